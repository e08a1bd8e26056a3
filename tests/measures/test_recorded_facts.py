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
