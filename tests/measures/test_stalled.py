"""Stalled particles (issue 35, finding 5): a run whose particle never moves where the
scene moves it is ``stalled``, not ``ok``; checked against the raw engine and the closed form."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from truestep.adapters import get_adapter
from truestep.execution.runner import run_one
from truestep.execution.timing import QUICK_TIMING
from truestep.measures import metrics
from truestep.measures.stalled import STALL_ULPS, stalled


def test_newton_vbd_leaves_the_heavy_end_of_the_chain_where_it_was(case_named):
    """mass-ratio-chain with Newton's VBD at 5 ms (float32): the raw run holds the 1e4 kg end
    particle at exactly x = 1 m (over the first 2 s of the case here), where the matrix
    exponential moves it by millimetres; the row says ``stalled``. Newton's semi-implicit
    Euler and the reference (float64) at the same step move it and stay ``ok``."""
    case = dataclasses.replace(case_named("mass-ratio-chain"), duration=2.0)
    raw = get_adapter("newton").simulate(case, "vbd", 5e-3)
    assert raw.status == "ok" and np.all(raw.x[:, 4, 0] == 1.0)
    exact = metrics.exact_for(case, raw.t)
    moved = float(np.max(np.abs(exact.x[:, 4, 0] - 1.0)))
    assert moved > STALL_ULPS * np.finfo(np.float32).eps
    assert "stalled" in (stalled(case, raw, exact, "float32") or "")
    row = run_one(case, "newton", "vbd", 5e-3, adaptive=False, timing=QUICK_TIMING)
    assert row["status"] == "stalled" and "never moved" in row["message"]
    assert np.isfinite(row["error"])  # measured all the same: the error of a frozen particle
    for engine, method in (("newton", "semi-implicit"), ("reference", "symplectic-euler")):
        assert run_one(case, engine, method, 5e-3, adaptive=False, timing=QUICK_TIMING)["status"] == "ok"


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_a_particle_at_rest_in_the_scene_is_not_stalled(case_named, precision):
    """A run that holds still what the exact motion holds still (within the threshold) is
    not stalled, nor is a run that moves."""
    case = case_named("mass-ratio-chain")
    exact = metrics.exact_for(case, np.linspace(0.0, case.duration, 11))
    frozen = type("Run", (), {})()
    frozen.x = np.repeat(exact.x[:1], 11, axis=0)
    frozen.v = None
    assert stalled(case, frozen, exact, precision) is not None
    frozen.x = exact.x.copy()
    assert stalled(case, frozen, exact, precision) is None
    at_rest = type("Exact", (), {"x": np.repeat(exact.x[:1], 11, axis=0)})()
    frozen.x = at_rest.x.copy()
    assert stalled(case, frozen, at_rest, precision) is None


def test_a_stalled_row_is_read_back_and_is_a_regression_against_ok(tmp_path):
    """``stalled`` is a status a results table holds (the reader refused it once), and a row
    that was ``ok`` in the baseline and is ``stalled`` now is worse."""
    import shutil

    import pandas as pd

    from truestep.ci.baseline import compare
    from truestep.tables.io import read_run_tables

    base = Path(__file__).parents[1] / "baselines" / "quick"
    now = tmp_path / "now"
    shutil.copytree(base, now)
    results = pd.read_csv(now / "results.csv")
    hit = results.index[results["status"] == "ok"][0]
    results.loc[hit, "status"] = "stalled"
    results.to_csv(now / "results.csv", index=False)
    found = compare(read_run_tables(base), read_run_tables(now))
    worse = [f for f in found.findings if f.change == "worse" and f.table == "results"]
    assert len(worse) == 1 and "ok -> stalled" in worse[0].line()
