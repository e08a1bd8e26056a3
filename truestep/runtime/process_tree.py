"""Finding and killing every process below one: what an isolated run leaves behind.

An adapter may start processes of its own (a solver server, a helper, a daemon that
double-forks and calls ``setsid`` to leave its process group). Each isolated run is a
subreaper (:func:`truestep.runtime.oscalls.become_subreaper`), so every such process stays below
it in the process tree even when its own parent exits; :func:`kill_tree` stops them all
(so none can fork meanwhile), then kills them, until none is left. The tree is read
from ``/proc`` (each process's parent), which works without ``/proc/PID/task/*/children``.
"""

from __future__ import annotations

import os
import signal

ROUNDS = 20
"""How many times :func:`kill_tree` looks again for processes that appeared meanwhile."""


def _parents() -> dict[int, int]:
    """Every visible process's parent, by pid (``/proc/PID/stat``)."""
    out: dict[int, int] = {}
    try:
        names = os.listdir("/proc")
    except OSError:
        return out
    for name in names:
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat", "rb") as fh:
                stat = fh.read()
        except OSError:
            continue
        fields = stat[stat.rfind(b")") + 2 :].split()
        if len(fields) > 1:
            out[int(name)] = int(fields[1])
    return out


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` in the tree (children first), ``pid`` excluded."""
    children: dict[int, list[int]] = {}
    for child, parent in _parents().items():
        children.setdefault(parent, []).append(child)
    found, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            if child not in found and child != pid:
                found.append(child)
                todo.append(child)
    return found


def _signal(pids: list[int], sig: int) -> None:
    for p in pids:
        try:
            os.kill(p, sig)
        except (ProcessLookupError, PermissionError):
            pass


def kill_group(pgid: int) -> None:
    """SIGKILL the process group ``pgid`` (nothing if it is gone)."""
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def kill_tree(pid: int) -> int:
    """SIGKILL every process below ``pid`` (not ``pid`` itself) and the process group
    ``pid`` leads, stopping each first so that none forks meanwhile; returns how many
    were found."""
    killed: set[int] = set()
    for _ in range(ROUNDS):
        found = [p for p in descendants(pid) if p not in killed]
        if not found:
            break
        _signal(found, signal.SIGSTOP)
        found = list(dict.fromkeys(found + descendants(pid)))
        _signal(found, signal.SIGKILL)
        killed.update(found)
    return len(killed)


def reap_children() -> None:
    """Collect the exit status of every child of this process that has ended."""
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return


def has_children() -> bool:
    """Whether this process has (or had, and has not collected) a child process: one
    ``waitpid`` that does not wait, so cheap enough for every isolated run."""
    try:
        os.waitpid(-1, os.WNOHANG)
    except ChildProcessError:
        return False
    return True
