"""The particle cases: their exact solutions agree with the scenes and with tight runs."""

from __future__ import annotations

import numpy as np
import pytest

from truestep.adapters.reference import ReferenceAdapter
from truestep.cases.exact import EXACT
from truestep.measures.properties import PROPERTIES

PARTICLE_CASES = [
    "free-fall",
    "projectile-drag",
    "earth-orbit",
    "spring-damper-pair",
    "triangle-impulse",
    "cube-inside-out",
    "cube-braced",
    "hanging-cloth",
    "rope-pendulum",
    "bouncing-ball",
    "sliding-contact",
    "particle-fountain",
    "hair-strands",
]
WITH_EXACT = [
    "free-fall",
    "projectile-drag",
    "earth-orbit",
    "spring-damper-pair",
    "bouncing-ball",
    "sliding-contact",
]


@pytest.mark.parametrize("name", PARTICLE_CASES)
def test_case_declares_gates_on_known_properties(case_named, name):
    case = case_named(name)
    assert case.gates and case.tags
    assert set(case.properties) <= set(PROPERTIES)
    for g in case.gates:
        if g.kind == "property":
            assert g.params["name"] in case.properties


@pytest.mark.parametrize("name", WITH_EXACT)
def test_exact_solution_starts_at_the_initial_state(case_named, name):
    case = case_named(name)
    ex = EXACT[case.exact](case, np.array([0.0]))
    m = case.model
    assert np.allclose(ex.x[0], m.x0, rtol=1e-15, atol=1e-12)
    assert np.allclose(ex.v[0], m.v0, rtol=1e-15, atol=1e-12)


@pytest.mark.parametrize(
    ("name", "method", "dt", "tol"),
    [
        # RK4 errors at these steps, measured: 3e-10 m, 0.076 m (on a 7e6 m orbit), 1e-9 m;
        # each tolerance is about ten times that, far below any modelling mistake.
        ("projectile-drag", "rk4", 0.0125, 3e-9),
        ("earth-orbit", "rk4", 15.0, 1.0),
        ("spring-damper-pair", "rk4", 0.0025, 1e-8),
    ],
)
def test_exact_solution_agrees_with_a_tight_run(case_named, name, method, dt, tol):
    case = case_named(name)
    traj = ReferenceAdapter().simulate(case, method, dt)
    ex = EXACT[case.exact](case, traj.t)
    assert np.max(np.linalg.norm(traj.x - ex.x, axis=2)) < tol
    if ex.energy is not None:
        scale = np.max(np.abs(ex.energy))
        assert np.max(np.abs(traj.energy - ex.energy)) < 1e-6 * scale


def test_earth_orbit_closes_after_one_period(case_named):
    case = case_named("earth-orbit")
    period = 2 * np.pi * np.sqrt(7e6**3 / (6.67384e-11 * (5.972e24 + 1000.0)))
    assert abs(case.duration - period) < 10.0  # 5820 s of whole steps, nearly one period
    ex = EXACT["two-body"](case, np.array([0.0, period / 2, period]))
    sat = ex.x[:, 1] - ex.x[:, 0]
    assert np.allclose(sat[2], sat[0], rtol=0, atol=1e-6)  # m, on a 7e6 m orbit
    assert np.allclose(sat[1], -sat[0], rtol=0, atol=1e-6)
    assert np.ptp(ex.energy) < 1e-12 * abs(ex.energy[0])


def test_linear_flow_stepped_record_to_record_equals_the_exponential_at_each_time():
    """truestep.cases.exact's linear solution steps expm from record to record (one exponential
    per distinct gap); it must agree with expm(A t) y0 at every time, here for a damped
    five-mass chain with forcing, 2001 records over 5000 steps of 1e-3 s."""
    from scipy.linalg import expm

    from truestep.cases.exact import _expm_flow

    n = 5
    K = np.diag(np.full(n, 800.0)) - 400 * np.eye(n, k=1) - 400 * np.eye(n, k=-1)
    K[-1, -1] = 400.0
    A = np.zeros((2 * n + 1, 2 * n + 1))
    A[:n, n : 2 * n] = np.eye(n)
    A[n : 2 * n, :n] = -K
    A[n : 2 * n, n : 2 * n] = -0.1 * np.eye(n)
    A[n : 2 * n, -1] = 1.0
    y0 = np.r_[np.random.default_rng(0).normal(size=2 * n), 1.0]
    t = np.unique(np.linspace(0, 5000, 2001).round()) * 1e-3
    direct = np.array([expm(A * ti) @ y0 for ti in t])
    assert np.max(np.abs(_expm_flow(expm, A, y0, t) - direct)) < 1e-10 * np.max(np.abs(direct))
