"""The engines outside truestep that call the reference's derivative (scipy's solve_ivp,
Drake's integrators: Drake's own test is in ``test_drake_adapter.py``) get its compiled
twin on particle scenes without planes, and with it the numpy derivative's runs, bit for
bit: every step, evaluation and state, error control and Radau's Newton iterations
included."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from truestep.adapters.reference import build_system
from truestep.adapters.scipy_ivp import ScipyAdapter
from truestep.cases import load_cases
from truestep.reference_impl.odes import Arenstorf, CircleField, KeplerProblem

ODES = [c for c in load_cases("*") if c.kind == "ode" and c.name != "circle-field"]
"""The ODE cases with a compiled twin (the circle field's numpy derivative is the faster)."""


@pytest.mark.parametrize(
    ("name", "method", "tol"),
    [
        ("earth-orbit", "RK45", 1e-8),
        ("spring-chain", "DOP853", 1e-6),
        ("hanging-cloth", "Radau", 1e-4),
        ("bouncing-ball", "RK45", 1e-6),
        ("arenstorf-orbit", "DOP853", 1e-8),
        ("kepler-orbit", "Radau", 1e-6),
    ],
)
def test_scipy_s_runs_are_the_same_with_the_compiled_derivative(case_named, name, method, tol):
    case = case_named(name)
    case = dataclasses.replace(case, duration=case.duration / 10)
    fast = ScipyAdapter().simulate(case, method, tol)
    assert_same_run(fast, ScipyAdapter(compiled=False).simulate(case, method, tol))
    assert fast.nfev > 10


def assert_same_run(fast, slow) -> None:
    """Two runs of one engine, with the compiled and the Python derivative, alike in every
    count and every recorded state, bit for bit (an ODE's states are in ``x``)."""
    assert (fast.status, fast.nfev, fast.steps) == (slow.status, slow.nfev, slow.steps)
    for a, b in ((fast.t, slow.t), (fast.x, slow.x), (fast.v, slow.v)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("case", ODES, ids=[c.name for c in ODES])
def test_each_lecture_ode_has_a_compiled_twin_of_its_derivative_bit_for_bit(case):
    """On states spread over six decades about the origin and the bodies (Arenstorf's
    squares go through the C library's pow in both: ``x ** 2`` there is not always
    ``x * x``), and at the case's start."""
    system = build_system(case)
    fast = system.compiled_derivative()
    assert fast is not None, case.name
    rng = np.random.default_rng(3)
    for k in range(20000):
        y = rng.standard_normal(system.dim) * 10 ** rng.uniform(-3, 3)
        t = float(rng.uniform(0.0, case.duration))
        np.testing.assert_array_equal(fast(y, t), system.derivative(y, t), err_msg=f"{case.name} at {k}")
    y0 = system.get_state()
    np.testing.assert_array_equal(fast(y0, 0.0), system.derivative(y0, 0.0))


def test_the_twins_take_the_system_s_own_parameters():
    y = np.array([0.3, -0.2, 0.1, 0.7])
    for system in (KeplerProblem(y, mu=2.5), Arenstorf(y, mu=0.1)):
        np.testing.assert_array_equal(system.compiled_derivative()(y, 0.0), system.derivative(y, 0.0))
    assert CircleField(y[:2]).compiled_derivative() is None


@pytest.mark.parametrize(
    ("name", "method", "dt"),
    [
        ("stiff-cloth", "implicit-euler", 1e-3),
        ("rope-pendulum", "implicit-euler", 2e-3),
        ("kepler-orbit", "implicit-euler", 1e-3),
        ("hanging-cloth", "dopri5", 1e-6),
    ],
)
def test_the_reference_s_numpy_path_calls_the_twin_and_runs_the_same(
    monkeypatch, case_named, name, method, dt
):
    """A reference step with no compiled loop (implicit Euler's Newton iteration, an
    adaptive step on the numpy path) evaluates the compiled twin of the derivative: the
    run of ``ReferenceAdapter(compiled=False)`` (the numpy derivative), bit for bit, with
    next to none of the numpy derivative's calls."""
    from truestep.adapters.reference import ReferenceAdapter
    from truestep.reference_impl.odes import KeplerProblem
    from truestep.reference_impl.particles import ParticleSystem

    calls = []
    for system in (ParticleSystem, KeplerProblem):
        numpy_derivative = system.derivative

        def counted(self, x, t, _f=numpy_derivative):
            calls.append(1)
            return _f(self, x, t)

        monkeypatch.setattr(system, "derivative", counted)
    case = case_named(name)
    case = dataclasses.replace(case, duration=case.duration / 10)
    fast = ReferenceAdapter().simulate(case, method, dt)
    fast_calls = len(calls)
    slow = ReferenceAdapter(compiled=False).simulate(case, method, dt)
    assert fast.path == slow.path == "numpy"
    assert_same_run(fast, slow)
    assert fast.nfev > 50 and len(calls) - fast_calls >= fast.nfev and fast_calls <= 2
