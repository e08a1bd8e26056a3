"""The Drake adapter (real Drake) against the reference's own schemes, closed forms of
the steps Drake documents, and the physics of runs whose answer is known."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("pydrake", reason='Drake is not installed: pip install "truestep[drake]"')

from truestep.adapters import get_adapter
from truestep.adapters.base import Adapter, resolve_facts
from truestep.adapters.drake_adapter import ERROR_CONTROLLED, FIXED, MAX_EVALUATIONS, DrakeAdapter
from truestep.execution.runner import plan
from truestep.measures.metrics import fit_order
from truestep.reference_impl.integrate import BLOWUP

pytestmark = pytest.mark.engine


@pytest.fixture(scope="module")
def drake() -> DrakeAdapter:
    return DrakeAdapter()


def _short(case, duration: float):
    return dataclasses.replace(case, duration=duration)


def _final(traj) -> np.ndarray:
    """The last recorded state, flat."""
    return np.ravel(traj.y[-1] if traj.y is not None else np.concatenate([traj.x[-1], traj.v[-1]]))


def test_it_is_an_adapter_registered_by_its_entry_point(drake):
    assert isinstance(drake, Adapter)
    assert isinstance(get_adapter("drake"), DrakeAdapter)
    assert set(drake.adaptive_methods) == set(ERROR_CONTROLLED) and set(drake.methods) == {
        *FIXED,
        *ERROR_CONTROLLED,
    }
    assert set(drake.method_notes) == set(drake.methods) == set(drake.method_facts)


@pytest.mark.parametrize("method", list(FIXED))
def test_a_fixed_step_run_takes_exactly_the_steps_asked(drake, case_named, method):
    """3 ms does not divide 1 s exactly in binary: without the stretch Drake would take
    tiny extra steps where ``(k + 1) h - k h`` rounds below ``h``."""
    case = _short(case_named("harmonic-oscillator"), 1.0)
    traj = drake.simulate(case, method, 3e-3)
    assert traj.status == "ok"
    assert traj.steps == case.steps_for(3e-3)[0] == 333
    np.testing.assert_allclose(np.diff(traj.t), 1.0 / 333, rtol=1e-12)


@pytest.mark.parametrize(
    ("mine", "theirs", "name"),
    [
        ("explicit_euler", "euler", "spring-damper-pair"),
        ("semi_explicit_euler", "symplectic-euler", "spring-damper-pair"),
        ("runge_kutta2", "heun", "spring-damper-pair"),
        ("explicit_euler", "euler", "circle-field"),
        ("runge_kutta2", "heun", "kepler-orbit"),
        ("semi_explicit_euler", "symplectic-euler", "kepler-orbit"),
    ],
)
def test_its_explicit_schemes_are_the_reference_methods_they_name(drake, case_named, mine, theirs, name):
    """The same scheme on the same forces: every record equal to round-off."""
    case = _short(case_named(name), min(case_named(name).duration, 2.0))
    dt = case.quick_dts[0]
    a = drake.simulate(case, mine, dt)
    b = get_adapter("reference").simulate(case, theirs, dt)
    assert a.steps == b.steps
    np.testing.assert_allclose(a.t, b.t, rtol=0, atol=1e-12)
    scale = np.abs(b.x).max()
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-11 * scale)
    assert a.nfev == b.nfev


def _oscillator_steps(method: str, h: float, omega: float) -> np.ndarray:
    """One step of an implicit method on ``q'' = -omega^2 q``, as a matrix on ``(q, v)``:
    backward Euler ``(I - h A)^-1``; Drake's implicit Euler, which keeps the two half
    steps of its error estimate, ``(I - h A / 2)^-2``."""
    a = np.array([[0.0, 1.0], [-(omega**2), 0.0]])
    eye = np.eye(2)
    if method == "radau1":
        return np.linalg.inv(eye - h * a)
    half = np.linalg.inv(eye - 0.5 * h * a)
    return half @ half


@pytest.mark.parametrize("method", ["radau1", "implicit_euler"])
def test_implicit_euler_keeps_two_half_steps_and_radau1_is_backward_euler(drake, case_named, method):
    """On the harmonic oscillator (linear, so Newton's iteration converges in one step up
    to its tolerance) each run's final state is the closed-form product of its step
    matrices: Drake's ``implicit_euler`` is two backward-Euler half steps per step, not
    the backward Euler its name says; ``radau1`` is backward Euler."""
    case = _short(case_named("harmonic-oscillator"), 0.5)
    h = 1e-2
    traj = drake.simulate(case, method, h)
    n, h = case.steps_for(h)
    omega = np.sqrt(case.model.anchors.stiffness[0] / case.model.mass[0])
    y0 = np.array([case.model.x0[0, 0], case.model.v0[0, 0]])
    expected = np.linalg.matrix_power(_oscillator_steps(method, h, omega), n) @ y0
    got = np.array([traj.x[-1, 0, 0], traj.v[-1, 0, 0]])
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6 * np.abs(y0).max())
    other = _oscillator_steps("radau1" if method == "implicit_euler" else "implicit_euler", h, omega)
    assert np.abs(np.linalg.matrix_power(other, n) @ y0 - got).max() > 1e-4


def test_the_orders_are_the_declared_ones_on_the_oscillator(drake, case_named):
    """Fitted from the error against the exact cosine at two steps, per method."""
    case = _short(case_named("harmonic-oscillator"), 1.0)
    exact = 0.1 * np.cos(10.0)
    for method in (
        "explicit_euler",
        "semi_explicit_euler",
        "runge_kutta2",
        "runge_kutta3",
        "radau3",
        "radau1",
    ):
        errors = [abs(drake.simulate(case, method, h).x[-1, 0, 0] - exact) for h in (2e-3, 1e-3)]
        order = fit_order(np.array([2e-3, 1e-3]), np.array(errors))
        assert abs(order - resolve_facts(drake.method_facts[method]).order) < 0.15, (method, order)


def test_error_control_meets_its_target_on_kepler(drake, case_named):
    """Cash-Karp 5(4) at target accuracy 1e-9 on the Kepler orbit ends within 1e-6 of
    scipy's DOP853 at rtol = atol = 1e-12 (another integrator, run here), and every
    accepted step is a record."""
    from scipy.integrate import solve_ivp

    from truestep.adapters.reference import build_system

    case = case_named("kepler-orbit")
    traj = drake.simulate(case, "runge_kutta5", 1e-9)
    assert traj.status == "ok" and traj.t[-1] == pytest.approx(case.duration)
    assert np.all(np.diff(traj.t) > 0)
    system = build_system(case)
    tight = solve_ivp(
        lambda t, y: system.derivative(y, t),
        (0, case.duration),
        system.get_state(),
        "DOP853",
        rtol=1e-12,
        atol=1e-12,
    )
    assert np.abs(traj.y[-1] - tight.y[:, -1]).max() < 1e-6
    assert len(traj.t) == min(traj.steps, case.max_records) + 1


def test_a_blow_up_is_unstable_at_its_time(drake, case_named):
    """Explicit Euler is unstable at every step on an undamped spring: its amplitude
    grows by ``sqrt(1 + (omega h)^2)`` a step, and the run stops where it passes
    ``BLOWUP``."""
    case = _short(case_named("stiff-spring"), 2.0)
    traj = drake.simulate(case, "explicit_euler", 1e-3)
    assert traj.status == "unstable"
    assert 0 < traj.t_fail < case.duration
    last = np.concatenate([traj.x[-1], traj.v[-1]])
    assert not np.isfinite(last).all() or np.abs(last).max() >= BLOWUP
    before = np.concatenate([traj.x[-2], traj.v[-2]])
    assert np.abs(before).max() < BLOWUP


def test_contact_is_unsupported_with_the_reason(case_named):
    """No coefficient of restitution in Drake: every row of the bouncing ball says so."""
    rows = list(plan(case_named("bouncing-ball"), "drake", quick=True))
    assert rows and all(why.startswith("unsupported:") and "planes" in why for *_, why in rows)
    from truestep.execution.runner import unsupported_message

    assert "no coefficient of restitution" in unsupported_message("drake", "planes")


def test_a_watched_run_has_the_energy_extremes_of_every_step(drake, case_named):
    """The watched run (``monitor=True``) keeps the extremes over every step, and the same
    records as a plain run."""
    case = case_named("harmonic-oscillator")
    plain = drake.simulate(case, "explicit_euler", 2e-3)
    watched = drake.simulate(case, "explicit_euler", 2e-3, monitor=True)
    np.testing.assert_array_equal(plain.t, watched.t)
    np.testing.assert_array_equal(plain.x, watched.x)
    assert watched.extremes is not None
    # explicit Euler gains energy every step: the highest is the last, the lowest the first
    assert watched.extremes.t_min == 0.0 and watched.extremes.t_max == pytest.approx(case.duration)
    assert MAX_EVALUATIONS > 100 * watched.nfev


@pytest.mark.parametrize(
    ("name", "method", "dt"),
    [
        ("earth-orbit", "runge_kutta3", 0.05),
        ("spring-chain", "implicit_euler", 0.01),
        ("hanging-cloth", "runge_kutta2", 0.002),
        ("earth-orbit", "bogacki_shampine3", 1e-6),
        ("arenstorf-orbit", "radau3", 0.002),
        ("long-orbit", "runge_kutta3", 0.05),
    ],
)
def test_the_compiled_derivative_gives_drake_the_numpy_runs_bits(drake, case_named, name, method, dt):
    """Drake calls the reference's compiled derivative on particle scenes: the same run,
    bit for bit, as with the numpy system's (every evaluation, Jacobian columns and error
    control included), in a fraction of the time."""
    case = _short(case_named(name), case_named(name).duration / 20 if dt < 1e-4 else 500 * dt)
    from test_compiled_derivative_users import assert_same_run

    fast = drake.simulate(case, method, dt)
    assert_same_run(fast, DrakeAdapter(compiled=False).simulate(case, method, dt))
    assert fast.nfev > 100
