"""A report is published whole or not at all: kills (SIGKILL, SIGTERM) at every point of
report writing leave ``--out`` either the previous report byte for byte or the new one
complete, no scratch folder (once the next run has cleaned up after a SIGKILL) and no
child process alive.

The runs of the report-writing kills are ``truestep run --resume`` from a journal whose
sweeps and analyses are done, each in a forked copy of this process (so it does not pay
Python's start-up again); the kill is a real signal to that process.
"""

from __future__ import annotations

import importlib
import os
import shutil
import signal
import subprocess
import sys
import traceback
from collections.abc import Callable
from pathlib import Path

import pytest
from kill_helpers import _running, pids_in, scratch_left, snapshot, still_running

from truestep.cli import main
from truestep.execution.runner import preload
from truestep.runtime import publish
from truestep.runtime.faults import CHILD_PIDS, KILL_AT, parse
from truestep.runtime.folder import MARKER, MARKER_TEXT
from truestep.runtime.oscalls import exchange

RUN = ["run", "--quick", "--engines", "reference", "--cases", "free-fall", "--out", "rep"]
POINTS = ("report-csv", "report-figures", "report-index", "report-swap", "report-swapped")


def fork_main(
    argv: list[str], cwd: Path, env: dict[str, str], before: Callable[[], None] | None = None
) -> int:
    """Start ``main(argv)`` in a forked copy of this process, in ``cwd`` with ``env``
    added, printing into ``cwd/log.txt``; return its pid."""
    pid = os.fork()
    if pid == 0:  # the child never returns into pytest
        code = 99
        try:
            os.chdir(cwd)
            os.environ.update(env)
            sys.stdout = sys.stderr = open(cwd / "log.txt", "w", buffering=1)
            if before is not None:
                before()
            code = main(argv)
        except BaseException:
            traceback.print_exc()
        finally:
            os._exit(code)
    return pid


def exit_code(pid: int) -> int:
    """Wait for a forked run: its exit code, or minus the signal that killed it."""
    return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])


def forked(
    argv: list[str], cwd: Path, env: dict[str, str], before: Callable[[], None] | None = None
) -> tuple[int, str]:
    """:func:`fork_main` and wait: the exit code and what the run printed."""
    code = exit_code(fork_main(argv, cwd, env, before))
    log = cwd / "log.txt"
    return code, log.read_text() if log.exists() else ""


def forked_all(
    jobs: dict[str, tuple[Path, dict[str, str], Callable[[], None] | None]], argv: list[str], at_once: int = 3
) -> dict[str, int]:
    """Several forked runs, ``at_once`` at a time: their exit codes by name."""
    pending, running, codes = list(jobs), {}, {}
    while pending or running:
        while pending and len(running) < at_once:
            name = pending.pop(0)
            running[fork_main(argv, *jobs[name])] = name
        pid, status = os.wait()
        if pid in running:
            codes[running.pop(pid)] = os.waitstatus_to_exitcode(status)
    return codes


def _old_report(where: Path) -> Path:
    """A previous report truestep wrote (its marker in it) that shares no bytes with the
    new one, with a scaling table and a figure that a quick run does not write (both
    gone once it is replaced)."""
    where.mkdir(parents=True)
    (where / "figures").mkdir()
    for name in (
        "results.csv",
        "stability.csv",
        "restitution.csv",
        "scaling.csv",
        "index.md",
        "index.html",
        "figures/free-fall-work-precision.png",
        "figures/old.png",
    ):
        (where / name).write_text(f"old {name}\n")
    (where / MARKER).write_text(MARKER_TEXT)
    return where


@pytest.fixture(scope="module")
def journal(tmp_path_factory) -> dict:
    """A journal with every sweep and the analyses done, the previous report and the new
    report an uninterrupted resume from that journal writes."""
    base = tmp_path_factory.mktemp("kills")
    preload()
    for name in (
        "truestep.execution.analyses",
        "truestep.api",
        "truestep.reporting.report",
        "truestep.figures.lecture",
    ):
        importlib.import_module(name)  # here, so that every forked run runs the same code
    first = base / "first"
    first.mkdir()
    code, log = forked(RUN, first, {KILL_AT: "report-csv"})
    assert code == -signal.SIGKILL, log
    assert (first / ".rep.partial" / "analyses.json").is_file()
    old = _old_report(base / "old")
    ref = base / "ref"
    shutil.copytree(old, ref / "rep")
    shutil.copytree(first / ".rep.partial", ref / ".rep.partial")
    code, log = forked([*RUN, "--resume"], ref, {})
    assert code == 0, log
    assert not (ref / ".rep.partial").exists() and scratch_left(ref / "rep") == []
    new = snapshot(ref / "rep")
    assert MARKER in new and "scaling.csv" not in new and "figures/old.png" not in new
    jobs = {}
    for name, env, before in [
        *((f"{p}:{s}", {KILL_AT: f"{p}:{s}"}, None) for p in POINTS for s in ("KILL", "TERM")),
        ("report-half:KILL", {KILL_AT: "report-half"}, _no_exchange),
        ("no-exchange", {}, _no_exchange),
    ]:
        work = base / name.replace(":", "-")
        shutil.copytree(old, work / "rep")
        shutil.copytree(first / ".rep.partial", work / ".rep.partial")
        jobs[name] = (work, {**env, CHILD_PIDS: str(work / "pids")}, before)
    codes = forked_all(jobs, [*RUN, "--resume"])
    return {
        "old": snapshot(old),
        "new": new,
        "runs": {
            name: (work / "rep", codes[name], (work / "log.txt").read_text())
            for name, (work, _, _) in jobs.items()
        },
    }


def _no_exchange() -> None:
    publish.EXCHANGE = False


@pytest.mark.parametrize("sig", ["KILL", "TERM"])
@pytest.mark.parametrize("point", POINTS)
def test_a_kill_while_writing_the_report_leaves_the_old_or_the_new_one(journal, point, sig):
    out, code, log = journal["runs"][f"{point}:{sig}"]
    published = point == "report-swapped"
    assert snapshot(out) == journal["new" if published else "old"]
    assert still_running(pids_in(out.parent / "pids")) == []
    if sig == "KILL":
        assert code == -signal.SIGKILL, log
        assert scratch_left(out), "a SIGKILL leaves its staging folder to the next run"
        publish.recover(out)  # what the next run does first
    else:
        lines = log.strip().splitlines()
        assert code == 128 + signal.SIGTERM, log
        assert "Traceback" not in log and lines[-1].startswith("truestep: interrupted by SIGTERM")
        assert ("the new report is in" in lines[-1]) == published
    assert scratch_left(out) == []
    assert snapshot(out) == journal["new" if published else "old"]
    assert (out.parent / ".rep.partial" / "analyses.json").is_file()  # kept for --resume


def test_without_exchange_a_kill_between_the_renames_is_undone_by_the_next_run(journal):
    out, code, log = journal["runs"]["report-half:KILL"]
    assert code == -signal.SIGKILL, log
    assert not out.exists() and [n for n in scratch_left(out) if ".old-" in n]
    assert publish.recover(out)
    assert snapshot(out) == journal["old"] and scratch_left(out) == []
    out, code, log = journal["runs"]["no-exchange"]
    assert code == 0, log
    assert snapshot(out) == journal["new"] and scratch_left(out) == []


def test_directories_are_exchanged_here(tmp_path):
    """The file system of the tests exchanges directories (else the tests above test the
    fallback twice)."""
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    (tmp_path / "a" / "x").write_text("a")
    assert exchange(tmp_path / "a", tmp_path / "b")
    assert (tmp_path / "b" / "x").read_text() == "a" and not (tmp_path / "a" / "x").exists()


CHILD_SCRIPT = """
import sys, time
from truestep.runtime.interrupts import Interrupted, handled
from truestep.runtime.isolation import start_isolated
with handled():
    try:
        run = start_isolated(time.sleep, (60,), 120.0)
        print(run.proc.pid, flush=True)
        time.sleep(60)
    except Interrupted:
        sys.exit(3)
"""


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM, signal.SIGINT])
def test_no_child_outlives_its_parent(sig):
    parent = subprocess.Popen([sys.executable, "-c", CHILD_SCRIPT], stdout=subprocess.PIPE, text=True)
    child = int(parent.stdout.readline())
    assert _running(child)
    parent.send_signal(sig)
    assert parent.wait(10) == (-sig if sig == signal.SIGKILL else 3)
    assert still_running([child]) == []


def test_kill_points_parse():
    assert parse("sweep:3") == ("sweep", 3, signal.SIGKILL)
    assert parse("report-swap:TERM") == ("report-swap", 1, signal.SIGTERM)
    assert parse("analyses:2:int") == ("analyses", 2, signal.SIGINT)
