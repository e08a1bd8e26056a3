"""Engine facts travel with the run (issue 38, item 2): ``run.json`` records each engine's
precision, and a verdict on a run's tables reads it, so a float32 engine's rows are judged
with its own round-off floor on a machine where that engine is not installed."""

from __future__ import annotations

import json
import shutil

import pandas as pd

from truestep.cli import main
from truestep.measures import metrics


def test_a_run_records_its_engines_precision(tmp_path):
    out = tmp_path / "out"
    args = ["run", "--quick", "--cases", "free-fall", "--engines", "reference,newton", "--out", str(out)]
    assert main(args) == 0
    assert json.loads((out / "run.json").read_text())["precision"] == {
        "reference": "float64",
        "newton": "float32",
    }


def test_a_verdict_reads_the_recorded_precision_of_an_engine_not_installed_here(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.setattr(metrics, "RECORDED_PRECISION", {})
    out = tmp_path / "out"
    assert main(["run", "--quick", "--cases", "free-fall", "--engines", "reference", "--out", str(out)]) == 0
    ghost = tmp_path / "ghost"
    shutil.copytree(out, ghost, ignore=shutil.ignore_patterns("figures", "index.*"))
    results = pd.read_csv(ghost / "results.csv")
    results.assign(engine="ghost32").to_csv(ghost / "results.csv", index=False)
    record = json.loads((ghost / "run.json").read_text())
    record["engines"], record["precision"] = ["ghost32"], {"ghost32": "float32"}
    (ghost / "run.json").write_text(json.dumps(record))
    assert metrics.round_off_floor("ghost32") == metrics.ROUND_OFF  # nothing here knows it
    main(["gate", "--results", str(ghost / "results.csv"), "-q"])
    capsys.readouterr()
    assert metrics.round_off_floor("ghost32") == metrics.ROUND_OFF_FLOAT32


ENGINE_MODULES = ("pymunk", "pybullet", "mujoco", "mujoco_warp", "warp", "newton", "pydrake")
"""The top-level modules of truestep's built-in engines' libraries."""
DRAWING_MODULES = ("matplotlib", "truestep.reporting.report")
"""What draws a report: a gate draws nothing."""


def test_gating_a_run_that_recorded_its_facts_imports_no_engine():
    """A run's verdicts come from what it recorded (``run.json``'s facts and its rows), so
    ``truestep gate`` on it, declared orders included, imports none of the engines it ran
    (seconds each: Newton's and MuJoCo Warp's about 1.5 s), and gives the same verdicts
    whether or not they are installed. The quick baseline recorded all eight engines. Nor
    does it import what draws a report (matplotlib: a third of a second)."""
    import subprocess
    import sys
    from pathlib import Path

    baseline = Path(__file__).resolve().parents[1] / "baselines" / "quick" / "results.csv"
    probe = (
        "import sys\n"
        "from truestep import api\n"
        f"report = api.gate({str(baseline)!r}, declared_orders=True)\n"
        "assert report.passed and report.held, report.console()\n"
        f"print(sorted(m for m in {ENGINE_MODULES + DRAWING_MODULES!r} if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def test_the_report_s_orders_table_reads_the_recorded_facts_of_an_engine_not_installed_here(monkeypatch):
    """The report's orders table declares the orders its run recorded, the very ones
    ``truestep gate --declared-orders`` checks, also where it is made without the engine
    installed: here the quick baseline's reference rows under the name of an engine
    nothing here knows, with the reference's recorded facts."""
    from pathlib import Path

    from truestep.cases import load_cases
    from truestep.measures import engine_facts
    from truestep.measures.declared import run_order_pairs
    from truestep.measures.findings import orders_table

    monkeypatch.setattr(engine_facts, "RECORDED_FACTS", {})
    monkeypatch.setattr(engine_facts, "RECORDED_LIMITS", {})
    monkeypatch.setattr(metrics, "RECORDED_PRECISION", {})
    quick = Path(__file__).resolve().parents[1] / "baselines" / "quick"
    record = json.loads((quick / "run.json").read_text())
    results = pd.read_csv(quick / "results.csv")
    results = results[results["engine"] == "reference"].assign(engine="ghost")
    cases = [c for c in load_cases("*") if c.name in set(results["case"])]
    assert run_order_pairs(cases, results) == []  # nothing here can read ghost's facts
    record["method_facts"] = {"ghost": record["method_facts"]["reference"]}
    record["precision"] = {"ghost": "float64"}
    engine_facts.take(record)
    gates = {(names[0], g.method): g.params["expect"] for names, g in run_order_pairs(cases, results)}
    table = orders_table(results, cases)
    declared = table[table["declared"].notna()]
    assert len(gates) >= 10 and set(declared["engine"]) == {"ghost"}
    assert {(r.case, r.method): r.declared for r in declared.itertuples()} == gates
    agrees = declared["agrees"]  # "" where the fit has no order: free-fall's runs are exact
    assert "no" not in set(agrees) and (agrees == "yes").sum() >= 5, declared


def test_one_judged_run_s_facts_do_not_reach_the_next():
    """Two verdicts in one process (two markers of a pytest session, two gates through the
    API): the facts the first run recorded are gone when the second, which recorded none
    for that engine, is judged, and ``take()`` leaves only the installed adapters' facts."""
    from truestep.measures import engine_facts

    first = {
        "precision": {"mine": "float32"},
        "method_facts": {"mine": {"m": {"like": "euler"}}},
        "stability_limits": {"mine": {"m": {"free-fall": 0.5}}},
    }
    try:
        engine_facts.take(first)
        assert engine_facts.recorded_facts("mine", "m")[0] and metrics.precision_of("mine") == "float32"
        assert engine_facts.recorded_limit("mine", "m", "free-fall") == 0.5
        engine_facts.take({"precision": {"other": "float64"}})
        assert engine_facts.recorded_facts("mine", "m") == (False, None)
        assert metrics.precision_of("mine") != "float32"
        assert engine_facts.recorded_limit("mine", "m", "free-fall") is None
        engine_facts.take(first, {"precision": {"mine": "float64"}})  # the later record wins
        assert metrics.precision_of("mine") == "float64" and engine_facts.recorded_facts("mine", "m")[0]
    finally:
        engine_facts.take()
    assert not engine_facts.RECORDED_FACTS and not metrics.RECORDED_PRECISION


def test_the_peers_and_notes_a_run_recorded_are_read_back_where_its_engine_is_not_installed():
    """A judged run's ``peers`` and ``method_notes`` (its ``run.json``) are what the peer
    table and the glossary read for its engines, also an engine not installed here; an
    installed engine's record wins over its adapter; ``take()`` leaves the adapters' own."""
    import pandas as pd

    from truestep.adapters import adapter_class
    from truestep.measures import engine_facts
    from truestep.measures.findings import method_notes
    from truestep.measures.peers import declared_peers

    rows = pd.DataFrame({"engine": ["mine", "mujoco"], "method": ["m", "RK4"]})
    record = {
        "peers": {"mine": {"m": "rk4"}, "mujoco": {"RK4": "euler"}},
        "method_notes": {"mine": {"m": "my own RK4"}},
    }
    assert declared_peers("mine") == {} and ("mine", "m") not in method_notes(rows)
    try:
        engine_facts.take(record)
        assert declared_peers("mine") == {"m": "rk4"}
        assert declared_peers("mujoco") == {"RK4": "euler"}  # the run's record, not the adapter's
        assert method_notes(rows)[("mine", "m")] == "my own RK4"
    finally:
        engine_facts.take()
    assert declared_peers("mine") == {}
    assert declared_peers("mujoco") == dict(adapter_class("mujoco").peers)
