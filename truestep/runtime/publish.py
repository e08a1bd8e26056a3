"""Publish a report directory as a whole: ``out`` is at every instant either the whole
old report or the whole new one.

The new report is written into a staging folder beside ``out``
(``.<name>.staging-<pid>``, same parent, so the same file system). :func:`swap` then
exchanges the two directory entries in one system call (Linux ``renameat2`` with
``RENAME_EXCHANGE``): there is no instant at which ``out`` is missing or mixed. The old
report, now under the staging name, is removed. Where the exchange is not available (or
``out`` does not exist yet) it is two renames, ``out`` to ``.<name>.old-<pid>`` and the
staging folder to ``out``, with SIGTERM and SIGINT blocked between them; a SIGKILL there
leaves ``out`` missing and the old report beside it, and :func:`recover` (called at the
start of every run) puts it back. :func:`recover` also removes the staging and old
folders of processes that are gone.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import stat
from pathlib import Path

from truestep.runtime import faults
from truestep.runtime.interrupts import HANDLED, Interrupted
from truestep.runtime.oscalls import exchange

EXCHANGE = True
"""Swap with ``renameat2(RENAME_EXCHANGE)`` where available; ``False`` forces the two
renames (tests of the fallback)."""

KINDS = ("staging", "old")


def target(out: Path) -> Path:
    """The directory that is published: ``out`` with symbolic links resolved (a link to
    a report directory stays a link; its target is swapped)."""
    return Path(os.path.realpath(out))


def beside(out: Path, suffix: str) -> Path:
    """``.<name>.<suffix>`` beside ``out`` with symbolic links resolved: where every file
    truestep keeps across runs for an output folder lives (the journal, the lock)."""
    real = target(out)
    return real.parent / f".{real.name}.{suffix}"


def scratch(out: Path, kind: str, pid: int | None = None) -> Path:
    """``.<name>.<kind>-<pid>`` beside ``out``."""
    return out.parent / f".{out.name}.{kind}-{os.getpid() if pid is None else pid}"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _scratch_of(out: Path) -> list[tuple[str, int, Path]]:
    """(kind, pid, path) of every scratch folder of ``out`` in its parent."""
    found = []
    try:
        names = os.listdir(out.parent)
    except OSError:
        return []
    for name in names:
        for kind in KINDS:
            prefix = f".{out.name}.{kind}-"
            if name.startswith(prefix) and name[len(prefix) :].isdigit():
                found.append((kind, int(name[len(prefix) :]), out.parent / name))
    return found


def recover(out: Path) -> list[str]:
    """Undo what a killed run left beside ``out``: if ``out`` is missing and an old
    report was moved aside, move it back; remove the staging and old folders of dead
    processes. Returns a line per action."""
    out = target(out)
    done = []
    stale = [
        (kind, pid, path) for kind, pid, path in _scratch_of(out) if pid == os.getpid() or not _alive(pid)
    ]
    olds = sorted((p for kind, _, p in stale if kind == "old" and _ours(p)), key=lambda p: -p.stat().st_mtime)
    if not os.path.lexists(out) and olds:
        os.rename(olds[0], out)
        done.append(f"put the previous report back from {olds[0].name}")
    for _, _, path in stale:
        if not os.path.lexists(path):
            continue
        if _ours(path):
            shutil.rmtree(path, ignore_errors=True)
        elif os.path.isdir(path) and not os.path.islink(path):  # the user's folder: left alone
            done.append(f"left {path.name}: a folder truestep did not make")
            continue
        else:  # a link or a file under a scratch folder's name: removed, never followed
            with contextlib.suppress(OSError):
                path.unlink()
        done.append(f"removed {path.name}")
    return done


def _ours(path: Path) -> bool:
    """Whether ``path`` is a scratch folder a run made: a directory (not a link) of this
    process's user that holds a report's marker (a staging folder writes it first) or
    nothing at all. A user's own folder under a scratch name is never this, and never
    deleted."""
    from truestep.runtime.folder import MARKER

    try:
        st = os.lstat(path)
        if not (stat.S_ISDIR(st.st_mode) and st.st_uid == os.geteuid()):
            return False
        return os.path.isfile(path / MARKER) or not any(os.scandir(path))
    except OSError:
        return False


def new_stage(out: Path) -> Path:
    """A fresh, empty staging folder for ``out``, made by this process (its owner and
    mode are this process's and its umask's, never those of the folder it replaces)."""
    stage = scratch(out, "staging")
    if os.path.islink(stage) or (os.path.lexists(stage) and not stage.is_dir()):
        stage.unlink()
    elif stage.exists():
        shutil.rmtree(stage)
    out.parent.mkdir(parents=True, exist_ok=True)
    stage.mkdir()
    return stage


def swap(stage: Path, out: Path) -> None:
    """Put the complete ``stage`` in place of ``out`` as a whole, then remove the old
    report. If the swap fails, ``out`` is as it was and ``stage`` is left to the caller.
    SIGTERM and SIGINT wait until the swap is done; one that arrived meanwhile raises
    :class:`Interrupted` with ``published`` set."""
    faults.point("report-swap")
    old: Path | None = None
    swapped = False
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, HANDLED)
    try:
        try:
            if out.exists() and EXCHANGE and exchange(stage, out):
                old = stage
            elif out.exists():
                old = scratch(out, "old")
                os.rename(out, old)
                faults.point("report-half")
                try:
                    os.rename(stage, out)
                except BaseException:
                    os.rename(old, out)
                    raise
            else:
                os.rename(stage, out)
            swapped = True
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        faults.point("report-swapped")
    except Interrupted as err:
        err.published = swapped
        raise
    finally:
        if swapped and old is not None:
            shutil.rmtree(old, ignore_errors=True)
