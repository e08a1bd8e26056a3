"""One experiment driver: ``truestep run`` is :func:`truestep.run`, and both go through
:func:`truestep.execution.experiment.run_experiment` (journal, budget, cluster, report)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pandas as pd

import truestep
from truestep import api
from truestep.cli import main
from truestep.execution import experiment

ARGS = ["--quick", "--engines", "reference", "--cases", "free-fall"]


def test_the_cli_run_is_the_public_run(tmp_path, monkeypatch, capsys):
    calls = []
    real = api.run

    def recorded(*args, **kwargs):
        calls.append(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(api, "run", recorded)
    out = tmp_path / "rep"
    assert main(["run", *ARGS, "--out", str(out)]) == 0
    (kw,) = calls
    assert kw["out"] == out and kw["quick"] and not kw["lecture_figures"]
    assert kw["argv"][:2] == ["run", "--quick"]
    said = capsys.readouterr().out
    assert f"wrote {out}/ (" in said and "sweep" in said and "report" in said
    written = pd.read_csv(out / "results.csv")
    assert set(written["case"]) == {"free-fall"} and (written["engine"] == "reference").all()


def test_the_public_run_writes_the_same_tables_and_leaves_no_journal(tmp_path):
    """With ``out``, :func:`truestep.run` checkpoints in a journal beside it (gone once the
    report is in place) and returns the tables it wrote, with each phase's time."""
    out = tmp_path / "rep"
    seen = []
    tables = truestep.run("free-fall", ["reference"], quick=True, out=out, progress=seen.append)
    assert set(tables.seconds) == {"sweep", "analyses", "report"}
    assert all(s >= 0 for s in tables.seconds.values())
    assert not (tmp_path / ".rep.partial").exists()
    written = pd.read_csv(out / "results.csv")
    assert len(written) == len(tables.results) and seen  # each row's line went to progress
    assert written["error"].equals(tables.results["error"].astype(float))
    record = json.loads((out / "run.json").read_text())
    kinds = {"analyses stability", "analyses restitution", "analyses scaling"}
    assert set(record["seconds"]) == {"sweep", "analyses", "compile", "sweep reference", *kinds}
    spent = record["seconds"]
    assert 0 < spent["sweep reference"] <= spent["sweep"] and 0 <= spent["compile"] <= spent["sweep"]
    # the searches and drops run beside the sweep's timed runs, the scaling table after it
    assert sum(spent[k] for k in kinds) <= spent["sweep"] + spent["analyses"]


def test_each_engine_s_seconds_count_its_processes_from_fork_to_end(tmp_path):
    """``run.json`` gives each engine's seconds of sweep and of search processes, each
    counted from its fork to its end: not up to the moment its outcome was handed on (an
    untimed outcome waits for a gap between timed runs), so that together they cannot pass
    what the machine's cores had in the run's wall time."""
    out = tmp_path / "rep"
    truestep.run("harmonic-oscillator", ["reference", "pymunk"], quick=True, out=out, progress=lambda _: None)
    spent = json.loads((out / "run.json").read_text())["seconds"]
    engines = ("reference", "pymunk")
    for engine in engines:
        assert spent[f"sweep {engine}"] > 0 and spent[f"analyses stability {engine}"] > 0
    cores = len(os.sched_getaffinity(0))
    wall = spent["sweep"] + spent["analyses"]
    counted = sum(spent[f"{phase} {e}"] for e in engines for phase in ("sweep", "analyses stability"))
    assert counted <= cores * wall


def test_a_run_beside_its_analyses_gives_the_tables_of_one_after_them(tmp_path):
    """The searches and drops run as the backlog of the sweep's lanes (the default) give
    the tables they give when they run after the sweep (:func:`run_analyses` alone)."""
    from truestep.ci.baseline import identical
    from truestep.execution.analyses import run_analyses

    cases = truestep.load_cases("harmonic-oscillator,bouncing-ball")
    tables = truestep.run(cases, ["reference"], quick=True, progress=lambda _: None)
    after = run_analyses(cases, ["reference"], tables.results, quick=True, progress=lambda _: None)
    assert len(after["stability"]) and len(after["restitution"])
    differs, cells = identical(
        {"stability": after["stability"], "restitution": after["restitution"]},
        {"stability": tables.stability, "restitution": tables.restitution},
    )
    assert cells > 50 and differs == []


def test_without_an_output_there_is_no_journal_and_no_report(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    tables = truestep.run("free-fall", ["reference"], quick=True, analyses=False, progress=lambda _: None)
    assert set(tables.seconds) == {"sweep", "analyses"} and list(tmp_path.iterdir()) == []
    assert isinstance(tables, experiment.Tables) and tables.stability.empty


def test_the_report_renders_the_findings_and_computes_none(tmp_path, monkeypatch):
    """Given a run's findings, rendering the report fits no order and picks nothing again."""
    from truestep.measures import findings, picks
    from truestep.reporting import sections as report_sections
    from truestep.reporting.report import render_markdown

    cases = truestep.load_cases("free-fall,bouncing-ball")
    reports = Path(__file__).resolve().parents[2] / "reports"
    results = pd.read_csv(reports / "results.csv")
    results = results[results["case"].isin([c.name for c in cases])]
    tables = {n: pd.read_csv(reports / f"{n}.csv") for n in ("stability", "restitution")}
    found = findings.find(cases, results, tables)
    assert len(found.orders) and len(found.cheapest) and set(found.survival) <= {"bouncing-ball"}

    def refuse(*args, **kwargs):
        raise AssertionError("recomputed while rendering")

    for module, name in [
        (findings, "orders_table"),
        (findings, "find"),
        (findings, "speed_table"),
        (findings, "same_scheme"),
        (picks, "cheapest"),
        (picks, "scorecard"),
        (picks, "survival"),
        (picks, "restitution_fidelity"),
        (report_sections, "fit_order"),
    ]:
        monkeypatch.setattr(module, name, refuse, raising=False)
    md = render_markdown(tmp_path, cases, results, tables, quick=True, argv=["run"], findings=found)
    assert "## Which engine, which method" in md and "## Measured orders of convergence" in md
