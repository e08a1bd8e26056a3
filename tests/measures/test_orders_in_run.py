"""Orders of convergence read over the run, not at a moment where errors cancel."""

from __future__ import annotations

import dataclasses

import numpy as np

from truestep.execution.runner import run_matrix
from truestep.measures.metrics import exact_for, fit_order, position_error


def test_a_first_order_method_on_an_orbit_reads_first_order(case_named):
    """Symplectic Euler on earth-orbit: at the end of the whole period the run covers, its
    first-order phase error cancels and the final error falls as dt^2 (order 2.00, what
    the report published); over the run it is first order."""
    case = case_named("earth-orbit")
    assert case.error_norm == "max"
    rows = run_matrix([case], ["reference"], progress=lambda _: None)
    ok = rows[(rows["method"] == "symplectic-euler") & (rows["status"] == "ok")]
    assert abs(fit_order(ok["dt"], ok["error"], scale=case.error_scale) - 1.0) < 0.15
    at_end = dataclasses.replace(case, error_norm="final")
    from truestep.adapters import get_adapter

    finals = []
    for dt in case.dts:
        traj = get_adapter("reference").simulate(case, "symplectic-euler", dt)
        finals.append(position_error(at_end, traj, exact_for(at_end, traj.t)))
    assert abs(fit_order(np.array(case.dts), np.array(finals), scale=case.error_scale) - 2.0) < 0.1
