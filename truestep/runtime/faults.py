"""Fault injection for tests: make ``truestep run`` kill itself at a named point.

Set ``TRUESTEP_KILL_AT=NAME[:K][:SIGNAL]`` and the process sends itself ``SIGNAL``
(``KILL``, the default, ``TERM`` or ``INT``) the ``K``-th time (default: the first) it
passes the point ``NAME``:

- ``sweep``: a row of the sweep was measured in this process (rows resumed from the
  journal do not count); ``sweep:3`` is right after the third row.
- ``analyses``: a child process of the analyses (a stability search, a bounce drop)
  finished, while the others may still run; ``analyses:2`` after the second.
- ``report-csv``: the report's tables are written into the staging folder;
  ``report-figures``: its figures too (the Markdown is made, not yet written);
  ``report-index``: ``index.md`` is written; ``report-swap``: the staging folder is
  complete, just before the swap; ``report-half``: (only where the directories cannot
  be exchanged) the old report is moved aside, the new one not yet in place (handled
  signals are blocked there, so only ``KILL`` acts at once); ``report-swapped``: the new
  report is in place, the old one not yet removed.

With ``TRUESTEP_CHILD_PIDS=FILE``, the pid of every child process is appended to
``FILE``, one a line (for tests that check that no child outlives its parent).

Unset, each point costs one dictionary look-up.
"""

from __future__ import annotations

import os
import signal
from collections import Counter

KILL_AT = "TRUESTEP_KILL_AT"
CHILD_PIDS = "TRUESTEP_CHILD_PIDS"
SIGNALS = {"KILL": signal.SIGKILL, "TERM": signal.SIGTERM, "INT": signal.SIGINT}

_passed: Counter[str] = Counter()


def parse(spec: str) -> tuple[str, int, signal.Signals]:
    """``NAME[:K][:SIGNAL]`` as (name, k, signal)."""
    parts = spec.strip().split(":")
    sig = SIGNALS.get(parts[-1].upper()) if len(parts) > 1 else None
    if sig is not None:
        parts = parts[:-1]
    k = int(parts.pop()) if len(parts) > 1 and parts[-1].isdigit() else 1
    return ":".join(parts), k, sig or signal.SIGKILL


def point(name: str) -> None:
    """Pass the point ``name``: kill this process here if ``TRUESTEP_KILL_AT`` says so."""
    spec = os.environ.get(KILL_AT)
    if not spec:
        return
    _passed[name] += 1
    at, k, sig = parse(spec)
    if at == name and _passed[name] == k:
        os.kill(os.getpid(), sig)


def note_child(pid: int) -> None:
    """Record a child's pid in ``TRUESTEP_CHILD_PIDS`` when it is set."""
    path = os.environ.get(CHILD_PIDS)
    if path:
        with open(path, "a") as f:
            f.write(f"{pid}\n")
