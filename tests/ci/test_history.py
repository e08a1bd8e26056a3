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


def test_a_history_of_three_commits_names_the_one_that_doubled_an_error(
    run_dir, tmp_path, monkeypatch, capsys
):
    root = tmp_path / "project"
    root.mkdir()
    _git(root, "init", "-q")
    _git(root, "config", "user.email", "t@t")
    _git(root, "config", "user.name", "t")
    monkeypatch.chdir(root)
    results = pd.read_csv(run_dir / "results.csv")
    rk4 = (results["method"] == "rk4") & (results["dt"] == results["dt"].max())
    dt = float(results.loc[rk4, "dt"].iloc[0])
    revisions = []
    for k, factor in enumerate((1.0, 1.0, 2.0)):
        (root / "solver.py").write_text(f"VERSION = {k}\n")
        _git(root, "add", "solver.py")
        _git(root, "commit", "-q", "-m", f"commit {k}")
        revisions.append(_git(root, "rev-parse", "HEAD"))
        run = tmp_path / f"run{k}"
        shutil.copytree(run_dir, run, ignore=shutil.ignore_patterns("figures", "index.*"))
        changed = results.copy()
        changed.loc[rk4, "error"] *= factor
        changed.to_csv(run / "results.csv", index=False)
        assert main(["history", "add", "--results", str(run / "results.csv")]) == 0
    capsys.readouterr()
    args = ["history", "show", "error", "--case", "harmonic-oscillator", "--engine", "reference"]
    assert main([*args, "--method", "rk4", "--dt", f"{dt!r}"]) == 0
    out = capsys.readouterr().out.splitlines()
    stepped = [line for line in out if "<- stepped" in line]
    assert len(stepped) == 1 and stepped[0].startswith(revisions[2][:12]), out
    assert [line[:12] for line in out[:3]] == [r[:12] for r in revisions]
    index = json.loads((root / ".truestep-history" / "index.json").read_text())
    assert [e["revision"] for e in index] == revisions
    # without a step every row is one value: the method's errors at each step are several rows
    assert main([*args, "--method", "rk4"]) == 2
    assert "name the step (--dt)" in capsys.readouterr().err


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
