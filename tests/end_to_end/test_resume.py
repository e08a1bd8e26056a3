"""``truestep run`` killed in the sweep or in the analyses leaves the previous report as it
was, and ``truestep run --resume`` finishes the run with the tables an uninterrupted run
writes (every column but the timing ones). Real runs, in processes of their own."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from kill_helpers import assert_same_tables, pids_in, scratch_left, snapshot, still_running

from truestep.cases import load_cases
from truestep.cli import main
from truestep.execution.journal import Journal, fingerprint
from truestep.runtime.faults import CHILD_PIDS, KILL_AT

RUN = ["run", "--quick", "--engines", "reference", "--cases", "harmonic-oscillator,bouncing-ball"]
"""A stability search (the oscillator) and restitution drops (the ball)."""


def truestep(
    cwd: Path,
    *args: str,
    env: dict[str, str] | None = None,
) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "truestep", *RUN, *args],
        cwd=cwd,
        env={**os.environ, **(env or {})},
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> list[Path]:
    """Two uninterrupted runs, side by side."""
    base = tmp_path_factory.mktemp("uninterrupted")
    runs = [
        subprocess.Popen(
            [sys.executable, "-m", "truestep", *RUN, "--out", name],
            cwd=base,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for name in ("a", "b")
    ]
    for run in runs:
        assert run.wait(600) == 0, run.stderr.read()
        run.stderr.close()
    return [base / "a", base / "b"]


def test_two_uninterrupted_runs_agree(uninterrupted):
    a, b = uninterrupted
    assert len(snapshot(a)) == len(snapshot(b))
    assert len((a / "restitution.csv").read_text().splitlines()) > 1
    assert len((a / "stability.csv").read_text().splitlines()) > 1
    assert_same_tables(a, b)


def test_killed_in_the_sweep_then_in_the_analyses_then_resumed(tmp_path, uninterrupted):
    out = tmp_path / "rep"
    shutil.copytree(uninterrupted[0], out)
    before = snapshot(out)
    journal = tmp_path / ".rep.partial"
    pids = tmp_path / "pids"

    run = truestep(tmp_path, "--out", "rep", env={KILL_AT: "sweep:5", CHILD_PIDS: str(pids)})
    # the run's process killed (as the kernel's OOM killer would): the command's supervisor
    # says so and exits as a shell reports a killed command
    assert run.returncode == 128 + signal.SIGKILL, run.stderr
    assert "ended by SIGKILL before it finished" in run.stderr
    assert snapshot(out) == before and still_running(pids_in(pids)) == []
    kept = len(list(journal.glob("sweep-*.json")))  # whole sweeps before the fifth row's
    assert kept >= 1

    run = truestep(
        tmp_path, "--out", "rep", "--resume", env={KILL_AT: "analyses:1:TERM", CHILD_PIDS: str(pids)}
    )
    said = [line for line in run.stderr.splitlines() if line.startswith("truestep:")]
    assert run.returncode == 128 + signal.SIGTERM, run.stderr
    assert "Traceback" not in run.stderr and len(said) == 1 and "SIGTERM" in said[0]
    assert f"resuming: {kept} finished sweeps" in run.stderr
    assert snapshot(out) == before and still_running(pids_in(pids)) == []
    assert scratch_left(out) == [] and not (journal / "analyses.json").exists()

    run = truestep(tmp_path, "--resume", "rep")
    assert run.returncode == 0, run.stderr
    assert "rows from the interrupted run" in run.stderr
    assert_same_tables(out, uninterrupted[0])
    assert not journal.exists() and scratch_left(out) == []


def test_resume_refuses_another_run_or_none(tmp_path, capsys):
    cases = load_cases("free-fall")
    Journal(tmp_path / "rep").start(fingerprint(cases, ["reference"], quick=True))
    argv = [
        "run",
        "--cases",
        "free-fall",
        "--engines",
        "reference",
        "--out",
        str(tmp_path / "rep"),
        "--resume",
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--quick" in err[0] and "without --resume" in err[0]
    assert main([*argv[:-2], str(tmp_path / "other"), "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no interrupted run to resume" in err[0]
