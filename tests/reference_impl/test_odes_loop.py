"""The plain ODE cases' compiled loop (reference_impl/odes_loop.py) gives the numpy path's
runs bit for bit: every ODE case of the library with every fixed-step method it runs, at
its sweep's steps and at a coarse one, a run that blows up, and RK4's BLAS-summed stages."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from truestep.adapters.reference import ReferenceAdapter, build_system
from truestep.cases import load_cases
from truestep.reference_impl.odes import CircleField
from truestep.reference_impl.odes_loop import ode_reason, weighted_sum
from truestep.reference_impl.solvers import RK4

ODES = [c for c in load_cases("*") if c.kind == "ode"]
FIXED = ["euler", "midpoint", "heun", "rk4", "symplectic-euler", "verlet", "lecture"]


def _same(a, b) -> None:
    assert (a.status, a.nfev, a.steps, a.t_fail) == (b.status, b.nfev, b.steps, b.t_fail)
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.energy, b.energy)


@pytest.mark.parametrize("case", ODES, ids=[c.name for c in ODES])
def test_every_ode_case_and_method_runs_as_the_numpy_path_does_bit_for_bit(case):
    """Over a tenth of each case (long-orbit's tenth is 12 566 steps at its finest step)."""
    case = dataclasses.replace(case, duration=case.duration / 10)
    compiled, numpy_path = ReferenceAdapter(), ReferenceAdapter(compiled=False)
    ran = 0
    for method in FIXED:
        if numpy_path.missing(case, method):
            continue
        steps = [*list(case.sweep(adaptive=False, quick=True))[:2], case.duration / 37]
        for dt in steps:
            fast = compiled.simulate(case, method, dt)
            assert fast.path == "compiled" and fast.wall_s > 0
            _same(fast, numpy_path.simulate(case, method, dt))
            ran += 1
    assert ran >= 9


def test_a_run_that_blows_up_stops_where_the_numpy_path_stops():
    """The circle field's explicit Euler grows the radius by sqrt(1 + h^2) a step: at h = 1
    past 1e12 near step 80, between two records and between two checks."""
    case = next(c for c in ODES if c.name == "circle-field")
    case = dataclasses.replace(case, duration=500.0, max_records=7)
    fast = ReferenceAdapter().simulate(case, "euler", 1.0)
    assert fast.status == "unstable" and 64 < fast.steps < 500
    _same(fast, ReferenceAdapter(compiled=False).simulate(case, "euler", 1.0))


@pytest.mark.parametrize("dim", [2, 4])
def test_rk4_s_stages_are_summed_as_numpy_s_blas_product_sums_them(dim):
    """The one sum numpy gives to OpenBLAS (its Haswell kernels, which truestep asks for):
    the loop must sum it alike for the runs to be the same."""
    rng = np.random.default_rng(7)
    b = np.ascontiguousarray(RK4.B, dtype=float)
    for _ in range(3000):
        k = rng.standard_normal((4, dim)) * 10 ** rng.uniform(-4, 4, (4, 1))
        expected = b @ k
        assert [weighted_sum(b, k, d) for d in range(dim)] == expected.tolist()


def test_what_the_loop_does_not_take_says_why():
    circle = CircleField(np.array([1.0, 0.0]))
    assert "position/velocity split" in str(ode_reason(circle, "verlet"))
    assert "not a fixed-step explicit method" in str(ode_reason(circle, "dopri5"))
    assert "not a fixed-step explicit method" in str(ode_reason(circle, "implicit-euler"))
    assert ode_reason(circle, "rk4") is None
    kepler = build_system(next(c for c in ODES if c.name == "kepler-orbit"))
    assert ode_reason(kepler, "lecture") is None
