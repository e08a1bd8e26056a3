"""Run simulations in child processes, so a crash or a hang becomes a row.

Each call forks a fresh process (engine parameters cannot leak from one run into the
next, as pybullet's would between clients of one process), waits at most its timeout and
reports what happened. :func:`run_isolated` runs one child at a time: timed runs never
share the CPU with other runs of the harness. :func:`run_isolated_all` keeps up to
``workers`` children busy at once, for work whose wall time is not measured (stability
searches, bounce tests).

No child outlives its parent: each one asks the kernel for SIGKILL when its parent dies
(Linux, :func:`truestep.oscalls.die_with_parent`), ignores SIGINT (a Ctrl-C reaches the
whole process group; the parent decides) and takes SIGTERM by default; the parent kills
the live ones when it is interrupted (:func:`kill_children`, :mod:`truestep.interrupts`).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import wait
from typing import Any

from truestep import faults
from truestep.oscalls import die_with_parent


@dataclass
class Outcome:
    """What became of an isolated call: ``ok`` with its value, or why not."""

    status: str  # ok | crashed | timeout
    value: Any = None
    message: str = ""


Call = tuple[Callable[..., Any], tuple, float]
"""``(fn, args, timeout_s)``: one isolated call."""


_RUN_DEADLINE: list[float | None] = [None]
"""When the whole run's budget ends (``time.monotonic()``), if it has one."""
BUDGET_SPENT = "the run's budget (truestep run --budget) was spent before this finished"


def set_run_budget(seconds: float | None) -> None:
    """Give every isolated call from now on at most ``seconds`` (s) in all, counted from
    now (``None``: no run-wide budget). A call that would outlast it is cut at the end
    of the budget, and calls after it are not started: both are ``timeout`` outcomes that
    say so."""
    _RUN_DEADLINE[0] = None if seconds is None else time.monotonic() + seconds


def _budget_left() -> float:
    end = _RUN_DEADLINE[0]
    return float("inf") if end is None else end - time.monotonic()


_LIVE: dict[int, Any] = {}
"""The children started by this process and not yet joined, by pid."""


def _child(conn, parent: int, fn: Callable[..., Any], args: tuple) -> None:
    die_with_parent(parent)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        conn.send(("ok", fn(*args)))
    except BaseException as err:  # everything: the parent turns it into a row
        tb = traceback.extract_tb(err.__traceback__)
        where = f" at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else ""
        conn.send(("crashed", f"{type(err).__name__}: {err}{where}"))
    finally:
        conn.close()


@dataclass
class Running:
    """A call started by :func:`start_isolated`, to be collected by :func:`finish_isolated`."""

    index: int
    proc: Any
    conn: Any
    deadline: float
    timeout: float
    by_budget: bool = False


def _start(index: int, call: Call) -> Running:
    fn, args, timeout = call
    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(child, os.getpid(), fn, args), daemon=True)
    proc.start()
    _LIVE[proc.pid] = proc
    faults.note_child(proc.pid)
    child.close()
    left = _budget_left()
    return Running(index, proc, parent, time.monotonic() + min(timeout, left), timeout,
                   by_budget=left < timeout)


def _finish(run: Running, *, timed_out: bool) -> Outcome:
    try:
        if timed_out:
            return Outcome("timeout", message=BUDGET_SPENT if run.by_budget
                           else f"no result within {run.timeout:g} s")
        try:
            status, value = run.conn.recv()
        except EOFError:
            run.proc.join()
            return Outcome("crashed",
                           message=f"engine process died (exit code {run.proc.exitcode})")
        return Outcome("ok", value) if status == "ok" else Outcome("crashed", message=value)
    finally:
        run.conn.close()
        if run.proc.is_alive() and timed_out:
            run.proc.kill()
        run.proc.join()
        _LIVE.pop(run.proc.pid, None)


def kill_children() -> None:
    """SIGKILL every child this process started and has not joined yet, and reap them."""
    for pid, proc in list(_LIVE.items()):
        proc.kill()
        proc.join()
        _LIVE.pop(pid, None)


def run_isolated_all(calls: Sequence[Call], workers: int = 1,
                     done: Callable[[int, Outcome], None] | None = None) -> list[Outcome]:
    """Run every ``fn(*args)`` in its own forked child, at most ``workers`` at a time.

    Returns the outcomes in the order of ``calls``; never raises for what happens inside a
    child. ``done(index, outcome)`` is called as each one finishes.
    """
    outcomes: list[Outcome | None] = [None] * len(calls)
    pending = list(enumerate(calls))[::-1]
    running: list[Running] = []
    try:
        while pending or running:
            while pending and len(running) < max(1, workers):
                if _budget_left() <= 0:  # not started: this call's row says why
                    index, _ = pending.pop()
                    outcomes[index] = Outcome("timeout", message=BUDGET_SPENT)
                    if done is not None:
                        done(index, outcomes[index])
                    continue
                running.append(_start(*pending.pop()))
            if not running:
                continue
            now = time.monotonic()
            ready = wait([r.conn for r in running],
                         timeout=max(0.0, min(r.deadline for r in running) - now))
            for r in list(running):
                timed_out = r.conn not in ready and time.monotonic() >= r.deadline
                if r.conn in ready or timed_out:
                    running.remove(r)
                    outcomes[r.index] = _finish(r, timed_out=timed_out)
                    if done is not None:
                        done(r.index, outcomes[r.index])
                    faults.child_finished()
    finally:
        for r in running:
            r.proc.kill()
            r.proc.join()
            r.conn.close()
            _LIVE.pop(r.proc.pid, None)
    return outcomes  # type: ignore[return-value]


_UNTIMED: list[Any] = [None]
"""The cluster untimed calls go to (:func:`set_untimed_runner`), if any."""


def set_untimed_runner(cluster: Any) -> None:
    """Send the calls of :func:`run_untimed` to ``cluster`` (a
    :class:`truestep.cluster.Cluster`), or back to this machine's cores (``None``)."""
    _UNTIMED[0] = cluster


def run_untimed(calls: Sequence[Call], workers: int,
                done: Callable[[int, Outcome], None] | None = None) -> list[Outcome]:
    """Work whose wall time is not measured (stability searches, bounce drops): on every
    worker of the cluster set by :func:`set_untimed_runner`, else as
    :func:`run_isolated_all` with ``workers`` children at once."""
    if _UNTIMED[0] is not None:
        return _UNTIMED[0].untimed(calls, done)
    return run_isolated_all(calls, workers, done)


def start_isolated(fn: Callable[..., Any], args: tuple, timeout: float) -> Running:
    """Start ``fn(*args)`` in a forked child and return at once (untimed work only)."""
    return _start(0, (fn, args, timeout))


def finish_isolated(run: Running) -> Outcome:
    """Wait for a started call until its result arrives or its time runs out."""
    ready = wait([run.conn], timeout=max(0.0, run.deadline - time.monotonic()))
    return _finish(run, timed_out=not ready)


def run_isolated(fn: Callable[..., Any], args: tuple, timeout: float) -> Outcome:
    """Call ``fn(*args)`` in a forked child, alone; never raises for what happens inside it."""
    return run_isolated_all([(fn, args, timeout)])[0]


def untimed_workers() -> int:
    """How many children may run at once for work that is not timed: the usable cores."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
