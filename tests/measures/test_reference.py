"""Cases without a closed form are measured against a fine run of the reference: checked
against another integrator, and by the orders the errors it gives fall with."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from truestep.adapters import get_adapter
from truestep.cases.exact import reference_run
from truestep.measures.metrics import exact_for, fit_order, position_error


def test_the_fine_rk4_run_of_the_cloth_agrees_with_dormand_prince(case_named):
    """hanging-cloth's reference (RK4 at 0.25 ms) against dopri5 at rtol 1e-11 over the
    same 2.5 s: the final positions agree to 1e-8 m (RK4's own error at that step is
    about 1e-12 m of a 0.7 m cloth; the tolerance leaves room for dopri5's)."""
    case = case_named("hanging-cloth")
    fine = reference_run(case, np.array([case.duration]))
    other = dataclasses.replace(case, exact_params={"method": "dopri5", "rtol": 1e-11})
    tight = reference_run(other, np.array([case.duration]))
    np.testing.assert_allclose(fine.x, tight.x, rtol=0, atol=1e-8)


@pytest.mark.parametrize(
    ("name", "method", "order"), [("rope-pendulum", "rk4", 4.0), ("hanging-cloth", "symplectic-euler", 1.0)]
)
def test_errors_against_the_reference_run_fall_with_the_methods_order(case_named, name, method, order):
    case = case_named(name)
    dts = np.array([case.dts[-1] * 2, case.dts[-1]])
    errors = []
    for dt in dts:
        traj = get_adapter("reference").simulate(case, method, dt)
        errors.append(position_error(case, traj, exact_for(case, traj.t)))
    assert abs(fit_order(dts, np.array(errors), scale=case.error_scale) - order) < 0.3


def test_particles_not_alive_are_not_compared(case_named):
    """The fountain's reference run marks particles that are not alive at the end as NaN;
    the lecture's update (exact in flight) then differs from it only by bounces found
    within a step: below a step's fall at the bounce speed."""
    case = case_named("particle-fountain")
    ref = exact_for(case, np.array([case.duration]))
    assert np.isnan(ref.x).any() and np.isfinite(ref.x).any()
    traj = get_adapter("reference").simulate(case, "lecture", case.dts[-1])
    error = position_error(case, traj, exact_for(case, traj.t))
    assert 0 < error < 0.02
