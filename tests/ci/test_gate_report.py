"""One gate pipeline: ``truestep gate`` is a parser over :func:`truestep.gate`, so the
command and the API give the same verdicts, the same console lines and the same bytes in
every CI output, and refuse the same input with the same line."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

import truestep
from truestep.adapters.reference import ReferenceAdapter
from truestep.cli import main

QUICK = Path(__file__).parents[1] / "baselines" / "quick"


@pytest.fixture(scope="module")
def changed(tmp_path_factory) -> Path:
    """The committed quick run with one error of the reference's rk4 doubled: a baseline
    comparison that finds a row worse, beside gates that hold."""
    import pandas as pd

    run = tmp_path_factory.mktemp("changed") / "run"
    shutil.copytree(QUICK, run)
    results = pd.read_csv(run / "results.csv", dtype=str, keep_default_na=False)
    row = results.index[
        (results["engine"] == "reference") & (results["method"] == "rk4") & (results["status"] == "ok")
    ][0]
    results.loc[row, "error"] = repr(2 * float(results.loc[row, "error"]))
    results.to_csv(run / "results.csv", index=False)
    return run


@pytest.mark.parametrize("against", ["itself", "changed"])
def test_the_command_prints_and_writes_what_the_api_reports(against, changed, tmp_path, capsys):
    run = QUICK if against == "itself" else changed
    options = ["--baseline", str(QUICK), "--identical", "--declared-orders", "-q"]
    paths = {kind: tmp_path / f"cli.{kind}" for kind in ("json", "xml", "md")}
    code = main(
        [
            "gate",
            "--results",
            str(run / "results.csv"),
            *options,
            "--json",
            str(paths["json"]),
            "--junit",
            str(paths["xml"]),
            "--markdown",
            str(paths["md"]),
        ]
    )
    printed = capsys.readouterr().out.splitlines()

    report = truestep.gate(run / "results.csv", baseline=QUICK, identical=True, declared_orders=True)
    api = {kind: tmp_path / f"api.{kind}" for kind in ("json", "xml", "md")}
    report.write(json=api["json"], junit=api["xml"], markdown=api["md"])

    assert code == (0 if report.passed else 1)
    assert printed == report.console(quiet=True)
    for kind in api:
        assert paths[kind].read_bytes() == api[kind].read_bytes(), kind
    worse = report.comparison.worse()
    if against == "itself":
        assert code == 0 and not worse and report.held
        assert printed[0].startswith("--identical: ") and printed[0].endswith(" 0 differ")
    else:  # the doubled error: one row worse, found by both
        assert code == 1
        assert any(f.quantity == "error" and f.change == "worse" for f in worse)
        assert any(line.startswith("WORSE") and "reference rk4" in line for line in printed)


def test_bad_input_is_the_same_line_from_the_command_and_the_api(tmp_path, capsys):
    missing = tmp_path / "nothing" / "results.csv"
    with pytest.raises(truestep.GateInputError) as err:
        truestep.gate(missing)
    assert main(["gate", "--results", str(missing)]) == 2
    assert capsys.readouterr().err.strip() == f"truestep: error: {err.value}"

    with pytest.raises(truestep.GateInputError, match="--baseline DIR"):
        truestep.gate(QUICK / "results.csv", identical=True)


def test_a_run_written_without_analyses_is_gated(tmp_path, capsys):
    """``truestep.run(..., analyses=False, out=DIR)`` writes its stability and restitution
    tables as a header without rows, which ``truestep gate`` reads: it refused the empty
    files it used to write ("stability.csv: empty: no header and no rows", exit 2)."""
    out = tmp_path / "run"
    truestep.run(
        "harmonic-oscillator",
        engines=["reference"],
        quick=True,
        analyses=False,
        out=out,
        progress=lambda _: None,
    )
    from truestep.tables.spec import TABLES

    for name in ("stability", "restitution"):
        lines = (out / f"{name}.csv").read_text().splitlines()
        assert lines == [",".join(TABLES[name].names)], (name, lines)
    assert main(["gate", "--results", str(out / "results.csv"), "--declared-orders", "-q"]) == 0
    assert capsys.readouterr().out.splitlines()[-1].endswith("failed, 0 not evaluated")


def test_a_timing_comparison_says_how_many_ratios_it_compared():
    report = truestep.gate(QUICK / "results.csv", baseline=QUICK, time_against="reference/rk4")
    assert report.comparison.timed > 0
    assert report.summary().endswith(
        f"; {report.comparison.timed} wall-time ratios to reference/rk4 compared"
    )


def test_an_order_gate_on_unstable_runs_says_they_were_unstable(tmp_path):
    """It said "measured order nan"."""
    import pandas as pd

    run = tmp_path / "run"
    shutil.copytree(QUICK, run)
    record = json.loads((run / "run.json").read_text())
    record.pop("rows", None)
    (run / "run.json").write_text(json.dumps(record))
    results = pd.read_csv(run / "results.csv")
    rows = (
        (results["case"] == "harmonic-oscillator")
        & (results["engine"] == "reference")
        & (results["method"] == "verlet")
    )
    results.loc[rows, ["status", "error"]] = ["unstable", float("nan")]
    results.to_csv(run / "results.csv", index=False)
    gates = tmp_path / "gates.toml"
    gates.write_text(
        '[[gates]]\ncases = "harmonic-oscillator"\nkind = "order"\nengine = "reference"\n'
        'method = "verlet"\nexpect = 2.0\ntol = 0.1\n'
    )
    report = truestep.gate(run / "results.csv", gates=[str(gates)], engines="reference")
    (verdict,) = [v for v in report.verdicts if v.gate.method == "verlet" and v.gate.file == str(gates)]
    assert (
        verdict.verdict == "fail"
        and verdict.measured == f"no order: {int(rows.sum())} of {int(rows.sum())} runs unstable"
    )


class Pinned(ReferenceAdapter):
    """A user's solver: the reference under another name, in another module than truestep."""

    name = "pinned-test"
    methods = ("rk4",)
    adaptive_methods = ()


def test_capabilities_no_case_of_the_run_exercises_are_named(tmp_path, capsys):
    """A new user's solver whose pinned particles did not stay pinned passed every channel:
    no quick case has a pinned particle. The gate now says which of a user engine's declared
    capabilities no case it ran has (truestep's own engines are left out)."""
    out = tmp_path / "run"
    engines = "reference,test_gate_report:Pinned"
    assert main(["run", "--quick", "--cases", "free-fall", "--engines", engines, "--out", str(out)]) == 0
    capsys.readouterr()
    report = truestep.gate(out / "results.csv", engines=engines)
    from truestep.cases import library, load_case

    have = set(map(str, load_case(library()["free-fall"]).features))
    idle = sorted(set(map(str, Pinned.capabilities)) - have)
    assert "pinned-particles" in idle
    assert report.notes == [
        f"note: engine pinned-test declares {', '.join(idle)}, which no case it ran here has: "
        "no verdict of this run checks those (add a case that needs them)"
    ]
    assert report.notes[0] in report.console() and report.notes[0] in report.markdown()
    assert json.loads(report.as_json())["notes"] == report.notes
