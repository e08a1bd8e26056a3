"""Which folders truestep may replace: only a report it wrote itself.

Every report truestep publishes (and every folder ``truestep figures`` and ``truestep
bench`` write into) carries a marker file, ``.truestep-report``, with a short JSON body
(:data:`MARKER_TEXT`). ``--out`` may name a folder that does not exist, an empty folder,
or a folder with the marker that holds nothing but what truestep writes there
(:data:`REPORT_ENTRIES`, as regular files and a real ``figures/`` directory of PNG
files). Anything else is refused before anything runs (:class:`OutRefused`, one line,
nothing touched): a folder of other files (a home directory, the current directory), a
report folder someone added a file or a link to, a symbolic link that leads anywhere but
to such a report, a file. The new report is a new folder made by this process, so its
owner and modes never come from the one it replaces.
"""

from __future__ import annotations

import json
import os
import shutil
import stat
import tempfile
from pathlib import Path

from truestep.runtime.files import FileRefused, read_regular
from truestep.runtime.visible import visible

MARKER = ".truestep-report"
"""The marker file's name."""
MARKER_TEXT = (
    '{"written_by": "truestep", "kind": "report", "schema": 1, "note": "truestep '
    'replaces this folder as a whole when a run names it as --out"}\n'
)
"""What truestep writes into the marker (the same for every report)."""
MAX_MARKER_BYTES = 4096
REPORT_FILES = (
    "results.csv",
    "stability.csv",
    "restitution.csv",
    "scaling.csv",
    "scorecard.csv",
    "index.md",
    "index.html",
    "run.json",
)
"""Regular files truestep writes into a report folder."""
REPORT_DIRS = ("figures",)
"""Directories truestep writes into a report folder (of ``*.png`` files only)."""
REPORT_ENTRIES = (*REPORT_FILES, *REPORT_DIRS, MARKER)


class OutRefused(Exception):
    """A folder truestep will not write its report into; ``str()`` is one line."""


def _marked(folder: Path) -> bool:
    """Whether ``folder`` holds truestep's marker: a regular file (not a link) whose JSON
    says truestep wrote it."""
    try:
        info = json.loads(read_regular(folder / MARKER, MAX_MARKER_BYTES, follow_links=False))
    except (FileRefused, ValueError):
        return False
    return isinstance(info, dict) and info.get("written_by") == "truestep"


def _stranger(folder: Path) -> str | None:
    """The first entry of a marked report folder that truestep does not write there, as
    it would write it, or ``None``."""
    for entry in sorted(os.scandir(folder), key=lambda e: e.name):
        st = entry.stat(follow_symlinks=False)
        if entry.name in REPORT_DIRS:
            if not stat.S_ISDIR(st.st_mode):
                return f"{entry.name} (not a directory truestep made)"
            for inner in sorted(os.scandir(entry.path), key=lambda e: e.name):
                if not (inner.name.endswith(".png") and inner.is_file(follow_symlinks=False)):
                    return f"{entry.name}/{inner.name}"
        elif entry.name in (*REPORT_FILES, MARKER):
            if not stat.S_ISREG(st.st_mode):
                return f"{entry.name} (not a regular file)"
        else:
            return entry.name
    return None


def check_out(out: Path, *, flag: str = "--out") -> Path:
    """The folder ``out`` leads to, if truestep may replace it (absent, empty, or a report
    truestep wrote holding nothing else); raises :class:`OutRefused` (one line) if not."""
    shown = visible(out)
    real = Path(os.path.realpath(out))
    if os.path.islink(out):
        if not real.is_dir():
            raise OutRefused(
                f"{flag}: {shown} is a symbolic link to {visible(real)}, which is "
                "not a folder: nothing was touched"
            )
        if not _marked(real):
            raise OutRefused(
                f"{flag}: {shown} is a symbolic link to {visible(real)}, which is "
                "not a report truestep wrote: nothing was touched"
            )
    if not os.path.lexists(real):
        return real
    if not real.is_dir():
        raise OutRefused(f"{flag}: {shown} is a file, not a folder: nothing was touched")
    try:
        entries = os.listdir(real)
    except OSError as err:
        raise OutRefused(f"{flag}: cannot list {shown}: {err.strerror or err}") from None
    if not entries:
        return real
    if not _marked(real):
        first = visible(sorted(entries)[0])[:60]
        raise OutRefused(
            f"{flag}: {shown} holds {len(entries)} entries ({first!r} ...) and is "
            f"not a report truestep wrote (no {MARKER} in it): nothing was touched; "
            "name a new or empty folder"
        )
    try:
        stranger = _stranger(real)
    except OSError as err:
        raise OutRefused(f"{flag}: cannot look into {shown}: {err.strerror or err}") from None
    if stranger is not None:
        raise OutRefused(
            f"{flag}: {shown} is a truestep report, but {visible(stranger)[:80]!r} in "
            "it is not something truestep wrote, and a report is replaced as a "
            "whole: move it out, or name another folder; nothing was touched"
        )
    return real


def write_marker(folder: Path) -> None:
    """Mark ``folder`` as a report truestep wrote."""
    fd = os.open(folder / MARKER, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(MARKER_TEXT)


def prepare(out: Path, *, flag: str = "--out") -> Path:
    """For the commands that write into ``out`` in place (``truestep figures``,
    ``truestep bench``): check it (:func:`check_out`), create it, mark it; its real path."""
    real = check_out(out, flag=flag)
    real.mkdir(parents=True, exist_ok=True)
    if not _marked(real):
        write_marker(real)
    return real


REPORT_SPACE_MB = 64
"""Room a new report needs beside its folder besides twice the old one's size, MiB (the
published report is about 10 MiB with its figures)."""


def check_publishable(out: Path, *, flag: str = "--out", space_mb: float = REPORT_SPACE_MB) -> Path:
    """The folder ``out`` leads to, if a run can publish its report there; raises
    :class:`OutRefused` (one line) before any work if not: a folder that is not a report
    truestep wrote (:func:`check_out`), a mount point (the report is put in place by
    renaming a directory), a parent where this process cannot create the staging folder
    and the journal, or too little space beside it (twice the old report and
    ``space_mb`` MiB)."""
    real = check_out(out, flag=flag)
    if real.exists() and os.path.ismount(real):
        raise OutRefused(f"{flag}: {visible(out)} is a mount point; name a directory inside it")
    try:
        real.parent.mkdir(parents=True, exist_ok=True)
        for where in (real.parent, real) if real.exists() else (real.parent,):
            probe = tempfile.NamedTemporaryFile(dir=where, prefix=".truestep-probe-")
            probe.close()
    except OSError as err:
        raise OutRefused(f"{flag}: cannot write in {visible(out)}: {err.strerror or err}") from None
    old = sum(f.stat().st_size for f in real.rglob("*") if f.is_file()) if real.exists() else 0
    need = 2 * old + space_mb * 2**20  # the staged report beside the old one
    free = shutil.disk_usage(real.parent).free
    if free < need:
        raise OutRefused(
            f"{flag}: {free / 2**20:.0f} MiB free beside {out}; staging the report "
            f"there needs about {need / 2**20:.0f} MiB"
        )
    return real
