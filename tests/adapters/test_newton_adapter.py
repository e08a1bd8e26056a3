"""The Newton adapter (real Newton, on Warp's CPU device) against the reference's schemes
at float32's tolerance, and against motions whose answer is known."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("newton", reason='Newton is not installed: pip install "truestep[newton]"')

from truestep.adapters import get_adapter
from truestep.adapters.base import Adapter
from truestep.adapters.newton_adapter import (
    NARROW_PHASE_FACTORIES,
    NewtonAdapter,
    build,
    contact_constants,
    restitution_of,
    share_narrow_phase_kernels,
    warp_arrays,
    wp,
)
from truestep.execution.analyses import _bounce_rows
from truestep.execution.runner import plan, unsupported_message
from truestep.measures.metrics import ROUND_OFF_FLOAT32, round_off_floor

pytestmark = pytest.mark.engine

FLOAT32 = 1e-5
"""Largest gap between Newton's float32 positions and the reference's float64 ones under
the same scheme, as a fraction of the scene's size (measured: 2e-6 on the oscillator)."""


@pytest.fixture(scope="module")
def newton_adapter() -> NewtonAdapter:
    return NewtonAdapter()


def _short(case, duration: float):
    return dataclasses.replace(case, duration=duration)


def test_it_is_an_adapter_registered_by_its_entry_point(newton_adapter):
    assert isinstance(newton_adapter, Adapter)
    assert isinstance(get_adapter("newton"), NewtonAdapter)
    assert newton_adapter.methods == ("semi-implicit", "xpbd", "vbd")
    assert newton_adapter.precision == "float32" and round_off_floor("newton") == ROUND_OFF_FLOAT32


@pytest.mark.parametrize(
    ("name", "dt", "duration"),
    [
        ("harmonic-oscillator", 1e-3, 2.0),
        ("spring-chain", 2e-3, 1.0),
        ("projectile-drag", 0.05, 3.0),
        ("hanging-cloth", 2e-3, 0.5),
    ],
)
def test_semi_implicit_moves_as_the_reference_s_symplectic_euler(
    newton_adapter, case_named, name, dt, duration
):
    """Springs (with rest lengths from the case, not Newton's initial distances), anchors
    (kinematic particles), pinned particles and truestep's drag kernel: Newton's
    ``SolverSemiImplicit`` is the reference's symplectic Euler in float32."""
    case = _short(case_named(name), duration)
    mine = newton_adapter.simulate(case, "semi-implicit", dt)
    theirs = get_adapter("reference").simulate(case, "symplectic-euler", dt)
    assert mine.status == theirs.status == "ok" and mine.path == "graph"
    assert mine.steps == theirs.steps
    size = float(np.ptp(theirs.x, axis=(0, 1)).max())
    gap = np.abs(mine.x - theirs.x).max()
    assert 0 < gap <= FLOAT32 * size


def test_its_contact_constants_give_the_restitution_asked(case_named):
    """``restitution_of`` against the motion: a unit-mass penalty contact (spring ke,
    damper kd only while approaching) integrated finely from a given approach speed
    rebounds at ``restitution_of(zeta)``."""
    from truestep.adapters.newton_adapter import damping_ratio

    for e in (0.3, 0.8, 0.95):
        zeta = damping_ratio(e)
        assert restitution_of(zeta) == pytest.approx(e, abs=1e-12)
        omega, r, v, h = 10.0, 0.0, -1.0, 1e-6
        while r <= 0.0:
            a = -(omega**2) * r - 2 * zeta * omega * min(v, 0.0)
            v += h * a
            r += h * v
        assert v == pytest.approx(e, rel=2e-4)


def _penalty_bounces(case, h: float, ke: float, kd: float, count: int = 3) -> list[float]:
    """Rebound ratios of a float64 semi-implicit Euler run of Newton's penalty contact
    (spring ``ke`` N/m, damper ``kd`` N s/m while approaching), written out here."""
    m = case.particles
    plane = m.planes[0]
    n, p, mass, radius = plane.normal, plane.point, m.mass[0], m.radius[0]
    x, v, ratios, v_in, inside = m.x0[0].copy(), m.v0[0].copy(), [], 0.0, False
    for _ in range(round(case.duration / h)):
        c = n @ (x - p) - radius
        f = -n * (c * ke) - n * min(n @ v, 0.0) * kd if c <= 0 else np.zeros(3)
        v_before = n @ v
        v = v + (f / mass + m.gravity) * h
        x = x + v * h
        now_inside = n @ (x - p) - radius < 0
        if now_inside and not inside:
            v_in = v_before
        if inside and not now_inside:
            ratios.append(-(n @ v) / v_in)
        inside = now_inside
    return ratios[:count]


def test_semi_implicit_bounces_as_its_penalty_contact_does():
    """The restitution analysis's own rows against the same contact law integrated here
    in float64: Newton's ``SolverSemiImplicit`` with the constants truestep sets
    rebounds as the law says, within 0.015 (float32 moves the phase at which the ball
    arrives, and the analysis samples the speeds outside its 1 mm band, a step or two
    from the plane: g h / v is 0.003 of e a step). The law itself gives 0.83, 0.78, 0.76 for the
    0.8 asked: the contact spans ten steps, and where in a step the ball arrives decides
    how much of the approach the damper sees."""
    from truestep.execution.analyses import bounce_case

    e, h = 0.8, 1e-3
    rows = _bounce_rows("newton", "semi-implicit", e, h)
    case = bounce_case(e, h)
    expected = _penalty_bounces(case, h, *contact_constants(case.particles, e, h))
    assert [r["status"] for r in rows] == ["ok"] * 3
    measured = [r["e_measured"] for r in rows]
    np.testing.assert_allclose(measured, expected, atol=0.015)
    assert all(abs(x - e) < 0.05 for x in measured)


def test_a_restitution_below_the_contact_s_floor_gets_the_floor_not_a_launch(case_named):
    """e = 0 would need infinite damping; an explicit damper beyond ``kd h / m`` = 1
    reverses the approach speed instead of removing it. The cap keeps the ball down: it
    leaves at the contact law's floor (0.26 in the law, 0.30 measured at 1 ms), not
    faster than it came."""
    from truestep.adapters.newton_adapter import EXPLICIT_DAMPING

    h, mass = 1e-3, case_named("bouncing-ball").particles.mass[0]
    _, kd = contact_constants(case_named("bouncing-ball").particles, 0.0, h)
    assert kd * h / mass == pytest.approx(EXPLICIT_DAMPING)
    rows = _bounce_rows("newton", "semi-implicit", 0.0, h)
    assert rows[0]["status"] == "ok" and 0.2 < rows[0]["e_measured"] < 0.4


def test_xpbd_and_vbd_restitution_is_measured_not_assumed():
    """Both are asked for 0.8 (XPBD through ``soft_contact_restitution``, VBD through the
    same penalty constants as semi-implicit); what the ball does is what the analysis
    reports. Newton 1.8.0, h = 1 ms: XPBD's restitution acts only on a particle already
    inside the plane at the start of a step, so the first rebound keeps 0.03 of the
    approach speed; VBD's implicit contact keeps 0.50."""
    xpbd, vbd = _bounce_rows("newton", "xpbd", 0.8, 1e-3), _bounce_rows("newton", "vbd", 0.8, 1e-3)
    assert xpbd[0]["status"] == vbd[0]["status"] == "ok"
    assert xpbd[0]["e_measured"] < 0.1 and xpbd[0]["apex"] < 0.01
    assert 0.4 < vbd[0]["e_measured"] < 0.6
    assert vbd[0]["apex"] == pytest.approx(vbd[0]["e_measured"] ** 2 * 1.0, rel=0.05)


def test_the_contact_stiffness_is_scaled_to_the_mass(case_named):
    """10 g particles get 1/100 of a 1 kg particle's stiffness and damping (Newton's
    defaults are the same for any mass)."""
    light = case_named("particle-rain").particles
    heavy = case_named("bouncing-ball").particles
    kl, dl = contact_constants(light, 0.8, 1e-3)
    kh, dh = contact_constants(heavy, 0.8, 1e-3)
    assert light.mass[0] == pytest.approx(0.01) and heavy.mass[0] == pytest.approx(1.0)
    assert kl / kh == pytest.approx(0.01) and dl / dh == pytest.approx(0.01)


def test_the_captured_graph_steps_as_plain_calls_do_bit_for_bit(case_named):
    case = case_named("spring-damper-pair")
    graphed, plain = build(case, "xpbd", 0.01), build(case, "xpbd", 0.01)
    assert graphed.graph is not None
    for _ in range(25):
        wp.capture_launch(graphed.graph)
        plain.run_step()
    for name in ("particle_q", "particle_qd"):
        mine, theirs = getattr(graphed.states[0], name).numpy(), getattr(plain.states[0], name).numpy()
        assert np.array_equal(mine, theirs)


@pytest.mark.parametrize("method", ["semi-implicit", "xpbd", "vbd"])
def test_scenes_sharing_narrow_phase_kernels_step_as_with_their_own_bit_for_bit(
    newton_adapter, case_named, monkeypatch, method
):
    """Every collision pipeline of a process shares the narrow-phase kernels made for its
    arguments (:func:`share_narrow_phase_kernels`): a scene with a plane, built after
    others have made and launched those kernels, moves as one whose pipeline made its own."""
    from newton._src.geometry import narrow_phase

    assert share_narrow_phase_kernels() == len(NARROW_PHASE_FACTORIES)
    case = _short(case_named("bouncing-ball"), 1.0)
    shared = [newton_adapter.simulate(case, method, dt) for dt in (4e-3, 2e-3, 4e-3)]
    for name in NARROW_PHASE_FACTORIES:
        monkeypatch.setattr(narrow_phase, name, getattr(narrow_phase, name).__wrapped__)
    own = newton_adapter.simulate(case, method, 4e-3)
    assert own.status == "ok" and np.ptp(own.x[:, 0], axis=0).max() > 0.1  # it fell and bounced
    for run in (shared[0], shared[2]):
        assert np.array_equal(run.x, own.x) and np.array_equal(run.v, own.v)


def test_a_snapshot_is_the_state_of_its_step_and_stays_so(newton_adapter, case_named):
    """On the CPU the state is read through views of the device's memory made once: a
    snapshot equals Warp's own ``numpy()`` copy at its step (the scene's particles only),
    and later steps leave it as it was."""
    case = case_named("spring-damper-pair")
    scene = newton_adapter.build(case, "semi-implicit", 0.01)
    assert all(v is not None for v in scene.views)
    wp.capture_launch(scene.graph)
    q, qd = newton_adapter.snapshot(scene)
    state = scene.states[0]
    assert np.array_equal(q, state.particle_q.numpy()[: scene.n])
    assert np.array_equal(qd, state.particle_qd.numpy()[: scene.n])
    before = q.copy()
    wp.capture_launch(scene.graph)
    assert np.array_equal(q, before) and not np.array_equal(newton_adapter.snapshot(scene)[0], before)


def test_a_2d_scene_stays_in_its_plane(newton_adapter, case_named):
    """A 2-D scene runs in 3-D: nothing pushes it out of z = 0, to the bit."""
    case = _short(case_named("rope-pendulum"), 1.0)
    for method in newton_adapter.methods:
        traj = newton_adapter.simulate(case, method, 2e-3)
        assert traj.status == "ok"
        assert np.all(traj.x[..., 2] == 0.0) and np.ptp(traj.x[..., 1]) > 0.1


def test_no_velocity_clamp_hides_a_blow_up(newton_adapter, case_named):
    """Symplectic Euler on the oscillator diverges for h omega > 2 (here 5): without
    Newton's default 1e5 m/s clamp the state overflows and the row is unstable."""
    case = dataclasses.replace(case_named("harmonic-oscillator"), duration=100.0)
    traj = newton_adapter.simulate(case, "semi-implicit", 0.5)
    assert traj.status == "unstable"
    assert traj.t_fail is not None and 0 < traj.t_fail <= 100.0
    assert build(case, "semi-implicit", 0.5).model.particle_max_velocity == float("inf")


def test_features_it_lacks_are_unsupported_with_the_reason(case_named):
    for name, feature in [("earth-orbit", "universal-gravitation"), ("high-speed-impact", "thin-walls")]:
        rows = list(plan(case_named(name), "newton", quick=True))
        assert rows and all(why == f"unsupported:{feature}" for *_, why in rows)
    assert "half-spaces" in unsupported_message("newton", "thin-walls")


def test_the_row_says_float32_and_how_it_stepped(newton_adapter, case_named):
    traj = newton_adapter.simulate(_short(case_named("harmonic-oscillator"), 0.1), "vbd", 1e-3)
    assert "float32" in traj.message and "captured Warp graph" in traj.message


@pytest.mark.skipif(
    wp.get_cuda_device_count() == 0, reason="no CUDA device: the GPU path runs only where one exists"
)
def test_on_a_gpu_it_moves_as_on_the_cpu(case_named):
    """The GPU path (docs: "On a GPU"): the same scene on ``cuda:0`` agrees with the CPU
    device to float32 rounding."""
    case = _short(case_named("harmonic-oscillator"), 1.0)
    cpu = NewtonAdapter().simulate(case, "semi-implicit", 1e-3)
    gpu = NewtonAdapter(device="cuda:0").simulate(case, "semi-implicit", 1e-3)
    assert gpu.status == "ok" and "cuda:0" in gpu.message
    assert np.abs(gpu.x - cpu.x).max() <= FLOAT32 * 0.2


def test_a_spring_that_underflows_float32_is_a_solver_failure_not_a_blow_up(newton_adapter, case_named):
    """The damped oscillator (rest length 0) decays onto its anchor: after some 45 s its
        length's square is below float32's smallest normal number (within 6000 steps at these
    steps), Newton's spring kernel
        divides by a length of 0 and the state turns NaN, at any step. The row says so and is
        ``solver-failed`` (no stability limit), where a blow-up would be ``unstable``."""
    case = case_named("damped-oscillator")
    steps = 6000
    for dt in (0.015, 0.05):
        long = dataclasses.replace(case, duration=steps * dt, max_records=steps)
        traj = newton_adapter.simulate(long, "semi-implicit", dt)
        assert traj.status == "solver-failed" and "float32" in traj.message
        finite = traj.x[np.isfinite(traj.x).all(axis=(1, 2))]
        assert np.abs(finite).max() <= 0.1 * (1 + 1e-7) and np.abs(finite[-1]).max() < 1e-18


def test_newton_is_installed_without_mujoco():
    """The Newton adapter takes its contact law from adapters/contact_law.py, not from the
    MuJoCo adapter: with MuJoCo not importable, ``truestep list`` says Newton is installed."""
    import subprocess
    import sys
    import textwrap

    code = """
        import sys
        class NoMujoco:
            def find_spec(self, name, path=None, target=None):
                if name == "mujoco" or name.startswith("mujoco."):
                    raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        sys.meta_path.insert(0, NoMujoco())
        from truestep.adapters import engine_status
        print(engine_status("newton"), "|", engine_status("mujoco"))
    """
    run = [sys.executable, "-c", textwrap.dedent(code)]
    out = subprocess.run(run, capture_output=True, text=True, check=True)
    newton, mujoco = (s.strip() for s in out.stdout.strip().split("|"))
    assert newton == "installed" and mujoco.startswith("not installed")


def _every_array(roots: tuple) -> list:
    """The Warp arrays reachable from ``roots`` through every Newton and Warp object (Warp's
    kernels, functions, modules and runtime among them), each once, in the order first met."""
    found, seen, stack = {}, set(), list(reversed(roots))
    while stack:
        obj = stack.pop()
        if obj is None or id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, wp.array):
            found.setdefault(id(obj), obj)
        elif isinstance(obj, list | tuple | dict):
            stack.extend(reversed(list(obj.values() if isinstance(obj, dict) else obj)))
        elif type(obj).__module__.split(".")[0] in ("newton", "warp") and hasattr(obj, "__dict__"):
            stack.extend(reversed(list(vars(obj).values())))
    return list(found.values())


@pytest.mark.parametrize("method", ["semi-implicit", "xpbd", "vbd"])
@pytest.mark.parametrize("name", ["bouncing-ball", "hanging-cloth"])
def test_the_arrays_a_reused_scene_puts_back_are_every_array_its_step_reaches(case_named, method, name):
    """:func:`warp_arrays` leaves Warp's code and runtime unwalked (20-50 ms a scene on
    contact and VBD scenes): it finds the arrays a walk through every object finds, in
    the same order (a struct of the model's among them)."""
    scene = build(case_named(name), method, 0.001, reuse=True)
    step = scene.run_step
    cells = {
        n: c.cell_contents for n, c in zip(step.__code__.co_freevars, step.__closure__ or (), strict=True)
    }
    roots = tuple(cells[n] for n in ("s0", "s1", "solver", "pipeline", "contacts"))
    found = warp_arrays(roots)
    assert [id(a) for a in found] == [id(a) for a in _every_array(roots)]
    assert any(wp.types.is_struct(v) for v in vars(roots[2].model).values())


@pytest.mark.parametrize("method", ["semi-implicit", "xpbd", "vbd"])
@pytest.mark.parametrize("name", ["bouncing-ball", "hanging-cloth", "projectile-drag"])
def test_a_run_of_the_reused_scene_is_the_run_of_a_scene_built_afresh(case_named, method, name):
    """The adapter builds a row's scene once (``build(..., reuse=True)``): its runs after the
    first (a shorter warm-up before them, a run of another scene and one at another step
    between them) step the bits of a scene built afresh for the run: contact, springs and
    pins, drag, under every solver."""
    case = _short(case_named(name), 0.5)
    if NewtonAdapter().missing(case, method):
        pytest.skip(f"newton does not run {name}")
    dt = case.dts[-1]
    fresh_adapter = NewtonAdapter()
    fresh_adapter.build = lambda c, m, h: build(c, m, h, reuse=False)  # type: ignore[method-assign]
    fresh = fresh_adapter.simulate(case, method, dt)
    adapter = NewtonAdapter()
    adapter.simulate(_short(case, 0.05), method, dt)
    runs = [adapter.simulate(case, method, dt), adapter.simulate(case, method, dt)]
    adapter.simulate(case, method, case.dts[0])
    other = _short(case_named("spring-chain"), 0.2)
    adapter.simulate(other, method, other.dts[0])
    runs.append(adapter.simulate(case, method, dt))
    assert build(case, method, dt, reuse=True) is build(case, method, dt, reuse=True)
    for run in runs:
        assert run.status == fresh.status and run.message == fresh.message
        assert np.array_equal(run.x, fresh.x) and np.array_equal(run.v, fresh.v)
