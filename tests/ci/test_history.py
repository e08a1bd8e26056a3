"""``truestep history`` (issue 36, item 5): runs kept by commit, a quantity shown over
commits with the commit where it stepped named, and github-action-benchmark's JSON."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import pandas as pd
import pytest

from truestep.ci.history import steps
from truestep.cli import main


def _git(root: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=root, check=True, capture_output=True, text=True).stdout.strip()


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("run") / "reports"
    args = ["run", "--quick", "--cases", "harmonic-oscillator", "--engines", "reference", "--out", str(out)]
    assert main(args) == 0
    return out


def test_steps_are_named_where_a_series_moved():
    assert steps([1.0, 1.0, 1.0, 2.0, 2.0], 1e-3) == [3]
    assert steps([1.0, 1.0, 1.0, 1.0], 1e-3) == []
    noisy = [1.0, 1.2, 0.9, 1.1, 3.0, 3.2, 2.9, 3.1]  # a wall time: one step, not every wobble
    assert steps(noisy, 0.5) == [4]
    assert steps([1.0, 1.0, math.nan, math.nan], 1e-3) == [2]  # a row that vanished


def _history(run_dir: Path, tmp_path: Path, monkeypatch, edits: list) -> list[str]:
    """A project of one commit per item of ``edits``, each adding to its history a copy of
    the run in ``run_dir`` that ``edit(results, record)`` changed (its ``results.csv``
    rows and ``run.json`` record); returns the commits' revisions."""
    root = tmp_path / "project"
    root.mkdir()
    _git(root, "init", "-q")
    _git(root, "config", "user.email", "t@t")
    _git(root, "config", "user.name", "t")
    monkeypatch.chdir(root)
    revisions = []
    for k, edit in enumerate(edits):
        (root / "solver.py").write_text(f"VERSION = {k}\n")
        _git(root, "add", "solver.py")
        _git(root, "commit", "-q", "-m", f"commit {k}")
        revisions.append(_git(root, "rev-parse", "HEAD"))
        run = tmp_path / f"run{k}"
        shutil.copytree(run_dir, run, ignore=shutil.ignore_patterns("figures", "index.*"))
        results, record = pd.read_csv(run_dir / "results.csv"), json.loads((run / "run.json").read_text())
        record.pop("rows", None)  # the rows are changed on purpose
        edit(results, record)
        results.to_csv(run / "results.csv", index=False)
        (run / "run.json").write_text(json.dumps(record))
        assert main(["history", "add", "--results", str(run / "results.csv")]) == 0
    return revisions


def _largest_rk4(results: pd.DataFrame) -> pd.Series:
    return (results["method"] == "rk4") & (results["dt"] == results["dt"].max())


def test_a_history_of_three_commits_names_the_one_that_doubled_an_error(
    run_dir, tmp_path, monkeypatch, capsys
):
    def times(factor: float):
        def edit(results: pd.DataFrame, record: dict) -> None:
            results.loc[_largest_rk4(results), "error"] *= factor

        return edit

    revisions = _history(run_dir, tmp_path, monkeypatch, [times(1.0), times(1.0), times(2.0)])
    results = pd.read_csv(run_dir / "results.csv")
    dt = float(results.loc[_largest_rk4(results), "dt"].iloc[0])
    capsys.readouterr()
    args = ["history", "show", "error", "--case", "harmonic-oscillator", "--engine", "reference"]
    assert main([*args, "--method", "rk4", "--dt", f"{dt!r}"]) == 0
    out = capsys.readouterr().out.splitlines()
    stepped = [line for line in out if "<- stepped" in line]
    assert len(stepped) == 1 and stepped[0].startswith(revisions[2][:12]), out
    assert [line[:12] for line in out[:3]] == [r[:12] for r in revisions]
    assert not any("another machine" in line for line in out), out
    index = json.loads((tmp_path / "project" / ".truestep-history" / "index.json").read_text())
    assert [e["revision"] for e in index] == revisions
    # without a step every row is one value: the method's errors at each step are several rows
    assert main([*args, "--method", "rk4"]) == 2
    assert "name the step (--dt)" in capsys.readouterr().err


def test_a_timing_that_stepped_with_the_machine_says_so(run_dir, tmp_path, monkeypatch, capsys):
    """A wall time that doubles where the history's runs move to another CPU: the step is
    named, and so is the machine it moved to, so that the commit is not blamed unseen;
    an error (no timing) over the same commits says nothing of machines."""

    def on(cpu: str, wall: float):
        def edit(results: pd.DataFrame, record: dict) -> None:
            results.loc[_largest_rk4(results), "wall_s"] = wall
            record["machine"] = {"cpu": cpu, "architecture": "x86_64", "cores": 2, "system": "Linux 6.1"}

        return edit

    intel, amd = "Intel(R) Xeon(R) Processor", "AMD EPYC"
    revisions = _history(run_dir, tmp_path, monkeypatch, [on(intel, 0.01), on(intel, 0.01), on(amd, 0.02)])
    results = pd.read_csv(run_dir / "results.csv")
    dt = float(results.loc[_largest_rk4(results), "dt"].iloc[0])
    capsys.readouterr()
    args = ["--case", "harmonic-oscillator", "--engine", "reference", "--method", "rk4", "--dt", f"{dt!r}"]
    assert main(["history", "show", "wall_s", *args]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[2].startswith(revisions[2][:12]) and "<- stepped: 0.01 -> 0.02" in out[2], out
    assert out[2].endswith("[timed on another machine from here: AMD EPYC (x86_64), 2 cores, Linux 6.1]")
    assert not any("another machine" in line for line in out[:2]), out
    assert main(["history", "show", "error", *args]) == 0
    assert "another machine" not in capsys.readouterr().out


def test_export_is_github_action_benchmark_json(run_dir, tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert main(["history", "export", "--results", str(run_dir / "results.csv"), "--out", str(out)]) == 0
    entries = json.loads(out.read_text())
    results = pd.read_csv(run_dir / "results.csv")
    ok = results[results["status"] == "ok"]
    errors = {e["name"]: e["value"] for e in entries if e["name"].endswith(" error")}
    assert len(errors) == ok["error"].notna().sum()
    r = ok.iloc[0]
    kind = "tol" if r["dt_kind"] == "tolerance" else "dt"
    assert errors[f"{r['case']}/{r['engine']}/{r['method']}@{kind}={r['dt']:g} error"] == r["error"]
    assert all(set(e) == {"name", "unit", "value"} for e in entries)


def test_a_history_needs_a_checkout(run_dir, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["history", "add", "--results", str(run_dir / "results.csv")]) == 2
    err = capsys.readouterr().err
    assert "not a git checkout" in err and "Traceback" not in err
