"""Run one simulation in a child process, so a crash or a hang becomes a row.

Each call forks a fresh process (engine parameters cannot leak from one run into the
next, as pybullet's would between clients of one process), waits at most ``timeout``
seconds and reports what happened. Only one child runs at a time: timings never share
the CPU with other runs of the harness.
"""

from __future__ import annotations

import multiprocessing as mp
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass
class Outcome:
    """What became of an isolated call: ``ok`` with its value, or why not."""

    status: str  # ok | crashed | timeout
    value: Any = None
    message: str = ""


def _child(conn, fn: Callable[..., Any], args: tuple) -> None:
    try:
        conn.send(("ok", fn(*args)))
    except BaseException as err:  # everything: the parent turns it into a row
        tb = traceback.extract_tb(err.__traceback__)
        where = f" at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else ""
        conn.send(("crashed", f"{type(err).__name__}: {err}{where}"))
    finally:
        conn.close()


def run_isolated(fn: Callable[..., Any], args: tuple, timeout: float) -> Outcome:
    """Call ``fn(*args)`` in a forked child; never raises for what happens inside it."""
    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(child, fn, args), daemon=True)
    proc.start()
    child.close()
    try:
        if not parent.poll(timeout):
            proc.kill()
            proc.join()
            return Outcome("timeout", message=f"no result within {timeout:g} s")
        try:
            status, value = parent.recv()
        except EOFError:
            proc.join()
            return Outcome("crashed", message=f"engine process died (exit code {proc.exitcode})")
        proc.join()
        if status == "ok":
            return Outcome("ok", value)
        return Outcome("crashed", message=value)
    finally:
        parent.close()
        if proc.is_alive():
            proc.kill()
            proc.join()
