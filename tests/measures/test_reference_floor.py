"""The error floor a case measured against a run publishes (issue 36, item 9), checked by
another route: the reference run measured against a finer run of its own method (fixed
step), or of its solver at the tightest tolerance a case may ask (adaptive)."""

from __future__ import annotations

import dataclasses

import pytest

from truestep.adapters.reference import ReferenceAdapter
from truestep.measures import metrics
from truestep.measures.reference_floor import reference_floor


def _error_against(case, finer_params: dict, method: str, step: float) -> float:
    """The error of the case's own reference run (``method`` at ``step``) measured, as the
    ``error`` column is, against a reference run made with ``finer_params``."""
    finer = dataclasses.replace(case, exact_params={**case.exact_params, **finer_params})
    run = ReferenceAdapter().simulate(case, method, step)
    return metrics.position_error(finer, run, metrics.exact_for(finer, run.t))


def test_a_fixed_step_reference_run_s_floor_is_its_error_against_a_run_at_half_its_step(case_named):
    """rope-pendulum's reference run (RK4 at 1e-4 s): the floor, read from a run at twice
    the step, is the error of the reference run itself against one at half its step (less
    the half-step run's own 1/16 of it), to 10 %."""
    case = case_named("rope-pendulum")
    floor = reference_floor(case)
    assert floor is not None and floor.method == "rk4" and floor.order == 4 and floor.floor is not None
    h = float(case.exact_params["dt"])
    assert floor.step == h and floor.other == 2 * h
    own = _error_against(case, {"dt": h / 2}, "rk4", h) / (1 - 2.0**-4)
    assert own == pytest.approx(floor.floor, rel=0.1)
    assert 1e-12 < floor.floor < 1e-8  # far below every row's error: the sweep's finest is 1 ms
    assert "Error floor" in floor.words() and f"{floor.floor:.2g}" in floor.words()


def test_an_adaptive_reference_run_s_floor_bounds_its_error_from_above(case_named):
    """close-encounter's reference run (dopri5 at 1e-12): its error against the same solver
    at 1e-14 is below the bound published (the error of the solver at 1e-10)."""
    case = case_named("close-encounter")
    floor = reference_floor(case)
    assert floor is not None and floor.adaptive and floor.floor is None and floor.order is None
    tol = float(case.exact_params.get("rtol", 1e-12))
    own = _error_against(case, {"rtol": 1e-14}, "dopri5", tol)
    assert own < floor.difference
    assert "below" in floor.words()


def test_a_case_with_an_exact_solution_has_no_floor_here(case_named):
    assert reference_floor(case_named("harmonic-oscillator")) is None
