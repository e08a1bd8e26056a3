"""Same scheme, same steps: the ratio table on rows made here, and its one finding (Drake's
implicit Euler) recomputed from the raw runs against the closed form."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from truestep.cases.loader import load_cases
from truestep.measures.peers import FLOOR, PEER_COLUMNS, same_scheme, verdict


def _row(case: str, engine: str, method: str, dt: float, error: float, status: str = "ok") -> dict:
    return {
        "case": case,
        "engine": engine,
        "method": method,
        "dt": dt,
        "dt_kind": "step",
        "status": status,
        "error": error,
    }


CASES = load_cases("harmonic-oscillator,bouncing-ball,free-fall")


def test_the_ratio_is_of_equal_steps_on_contact_free_cases_above_round_off():
    rows = [
        _row("harmonic-oscillator", "reference", "euler", 1e-3, 2e-2),
        _row("harmonic-oscillator", "reference", "euler", 5e-4, 1e-2),
        _row("harmonic-oscillator", "mine", "fast", 1e-3, 1e-2),
        _row("harmonic-oscillator", "mine", "fast", 5e-4, 5e-3),
        _row("harmonic-oscillator", "mine", "fast", 2e-4, 1e-3),  # no reference row at this step
        _row("bouncing-ball", "reference", "euler", 1e-3, 1e-3),  # contact: not compared
        _row("bouncing-ball", "mine", "fast", 1e-3, 9e-3),
        _row("free-fall", "reference", "euler", 1e-3, FLOOR / 10),  # round-off: not compared
        _row("free-fall", "mine", "fast", 1e-3, 1e-14),
        _row("harmonic-oscillator", "mine", "fast", 1e-4, 1e-4, status="unstable"),
    ]
    table = same_scheme(pd.DataFrame(rows), CASES, {"mine": {"fast": "euler"}})
    assert list(table.columns) == list(PEER_COLUMNS)
    (r,) = table.itertuples(index=False)
    assert (r.rows, r.cases, r.ratio, r.ratio_min, r.ratio_max) == (2, 1, 0.5, 0.5, 0.5)
    assert r.verdict == verdict(0.5) and "not the named scheme" in r.verdict
    assert verdict(1.1) == "same scheme" and verdict(float("nan")) == "not compared"


@pytest.mark.engine
def test_drakes_implicit_euler_makes_half_the_error_of_backward_euler():
    """Recomputed from the runs themselves: each run's worst distance from the exact
    ``0.1 cos(10 t)`` over its records, Drake's over the reference's, at three steps; the
    harness's table gives the same ratios from the rows it makes of those runs."""
    pytest.importorskip("pydrake")
    from truestep.adapters import get_adapter
    from truestep.execution.runner import row_from

    case = dataclasses.replace(load_cases("harmonic-oscillator")[0], duration=1.0)
    ratios, rows = [], []
    for dt in (2e-3, 1e-3, 5e-4):
        errors = []
        for engine, method in (("drake", "implicit_euler"), ("reference", "implicit-euler")):
            run = get_adapter(engine).simulate(case, method, dt, monitor=True)
            errors.append(np.abs(run.x[:, 0, 0] - 0.1 * np.cos(10.0 * run.t)).max())
            rows.append(row_from(case, engine, method, dt, adaptive=False, outcome=run))
        ratios.append(errors[0] / errors[1])
    assert np.allclose(ratios, 0.5, atol=0.02), ratios
    table = same_scheme(pd.DataFrame(rows), [case], {"drake": {"implicit_euler": "implicit-euler"}})
    assert table.loc[0, "rows"] == 3
    assert table.loc[0, "ratio"] == pytest.approx(float(np.median(ratios)), rel=1e-6)
