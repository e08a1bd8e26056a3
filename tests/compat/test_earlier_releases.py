"""A user project written for an earlier release keeps working: its case files load, and a
gate at a step that only the full sweep runs is not evaluated in a ``--quick`` run (saying
so) instead of refusing the file (truestep 0.2's loader refused it on every command)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from truestep.cases import load_case
from truestep.ci.gates import check_gates, quick_only

RELEASE_0_2 = Path(__file__).parent / "release-0.2"


@pytest.mark.parametrize("path", sorted(RELEASE_0_2.glob("*.toml")), ids=lambda p: p.name)
def test_case_files_of_release_0_2_load(path):
    case = load_case(path)
    assert case.gates


def _rows(case, dts):
    """A run's rows of reference/rk4 and reference/verlet at ``dts``, errors falling as
    dt^2 (enough for the gates to read; the physics is checked where the sweep runs)."""
    return pd.DataFrame(
        [
            {
                "case": case.name,
                "engine": "reference",
                "method": m,
                "dt": dt,
                "dt_kind": "step",
                "status": "ok",
                "error": 1e-12 + dt**2,
                "nfev": 10,
                "wall_s": 0.01,
            }
            for m in ("rk4", "verlet")
            for dt in dts
        ]
    )


def test_a_gate_on_a_full_sweep_step_is_not_evaluated_in_a_quick_run():
    case = load_case(RELEASE_0_2 / "chain-of-three.toml")
    gate = next(g for g in case.gates if g.dt is not None)
    assert gate.dt not in case.quick_dts and gate.dt in case.dts
    quick = check_gates([case], _rows(case, case.quick_dts))
    verdicts = {v.gate.kind: v for v in quick}
    assert verdicts["error"].verdict == "skip"
    assert "full sweep only" in verdicts["error"].measured
    assert verdicts["order"].verdict == "pass"  # the rest of the case's gates are evaluated
    full = {v.gate.kind: v for v in check_gates([case], _rows(case, case.dts))}
    assert full["error"].verdict == "fail"  # a full run evaluates it (1e-6 > 1e-8)


def test_a_missing_row_in_a_full_run_still_fails():
    """Only a run whose every row lies in the quick sweep excuses the gate: a full run that
    lacks the gate's row fails it, as before."""
    case = load_case(RELEASE_0_2 / "chain-of-three.toml")
    rows = _rows(case, case.dts)
    gate = next(g for g in case.gates if g.dt is not None)
    assert quick_only(case, gate, rows) is None
    gapped = rows[~((rows["method"] == "rk4") & (rows["dt"] == gate.dt))]
    verdict = next(v for v in check_gates([case], gapped) if v.gate.kind == "error")
    assert verdict.verdict == "fail"
