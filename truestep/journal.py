"""The checkpoints of an interrupted ``truestep run``, for ``truestep run --resume``.

Kept in ``.<name>.partial/`` beside the run's ``--out``: ``fingerprint.json`` (what the
run was: truestep version, ``--quick``, engines, and each case's name and the SHA-256 of
its file), one pickle per finished (case, engine, method) sweep with its rows and energy
traces, and ``analyses.pkl`` with the analyses' tables once they are done. Every file is
written to a temporary name and renamed into place, so a kill leaves whole checkpoints
or none. Pickles keep the rows exactly as the sweep made them (floats, NaN, strings,
numpy arrays), so a resumed run's tables equal an uninterrupted run's. The journal is
this process's own output (as trusted as the report beside it); it is removed once the
report is published.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import shutil
from pathlib import Path
from typing import Any

from truestep import __version__
from truestep.cases.case import Case

SweepKey = tuple[str, str, str]
"""(case, engine, method)."""


class JournalError(Exception):
    """The journal cannot be resumed: missing, or written by a different run."""


def journal_dir(out: Path) -> Path:
    """``.<name>.partial`` beside ``out`` (symbolic links resolved)."""
    out = Path(os.path.realpath(out))
    return out.parent / f".{out.name}.partial"


def _case_digest(case: Case) -> str:
    path = Path(case.file)
    data = path.read_bytes() if path.is_file() else case.file.encode()
    return hashlib.sha256(data).hexdigest()


def fingerprint(cases: list[Case], engines: list[str], quick: bool) -> dict[str, Any]:
    """What a resumed run must share with the interrupted one."""
    return {"truestep": __version__, "quick": bool(quick), "engines": list(engines),
            "cases": [[c.name, _case_digest(c)] for c in cases]}


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.parent / f".tmp-{os.getpid()}-{path.name}"
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


class Journal:
    """The checkpoints of one run, in ``.<name>.partial`` beside ``out``."""

    def __init__(self, out: Path) -> None:
        self.dir = journal_dir(out)

    def start(self, fp: dict[str, Any]) -> None:
        """Start afresh: drop any earlier journal, record ``fp``."""
        self.remove()
        self.dir.mkdir(parents=True)
        _write_atomic(self.dir / "fingerprint.json", json.dumps(fp, indent=1).encode())

    def resume(self, fp: dict[str, Any]) -> int:
        """Continue the journal: it must exist and record ``fp``; returns the number of
        finished sweeps. Raises :class:`JournalError` (one line) otherwise."""
        try:
            kept = json.loads((self.dir / "fingerprint.json").read_text())
        except (OSError, ValueError):
            raise JournalError(f"no interrupted run to resume: {self.dir} holds no "
                               "fingerprint.json") from None
        for field, what in (("truestep", "truestep version"), ("quick", "--quick"),
                            ("engines", "engines"), ("cases", "cases")):
            if kept.get(field) != fp[field]:
                was, now = kept.get(field), fp[field]
                if field == "cases":
                    was, now = _case_change(was, now)
                raise JournalError(f"the interrupted run in {self.dir} had other {what} "
                                   f"({_short(was)}, now {_short(now)}); "
                                   "run without --resume to start afresh")
        for tmp in self.dir.glob(".tmp-*"):
            tmp.unlink(missing_ok=True)
        return len(list(self.dir.glob("sweep-*.pkl")))

    def _sweep_path(self, key: SweepKey) -> Path:
        digest = hashlib.sha1("\0".join(key).encode()).hexdigest()[:16]
        return self.dir / f"sweep-{digest}.pkl"

    def sweep(self, key: SweepKey, dts: list[float]) -> tuple[list[dict], dict] | None:
        """The rows and traces of a finished sweep over ``dts``, or ``None``."""
        try:
            kept = pickle.loads(self._sweep_path(key).read_bytes())
        except (OSError, pickle.UnpicklingError, EOFError):
            return None
        if kept.get("key") != key or kept.get("dts") != list(dts):
            return None
        return kept["rows"], kept["traces"]

    def put_sweep(self, key: SweepKey, dts: list[float], rows: list[dict], traces: dict) -> None:
        """Checkpoint a finished sweep."""
        _write_atomic(self._sweep_path(key), pickle.dumps(
            {"key": key, "dts": list(dts), "rows": rows, "traces": traces}, protocol=5))

    def analyses(self) -> dict | None:
        """The analyses' tables, if they were checkpointed."""
        try:
            return pickle.loads((self.dir / "analyses.pkl").read_bytes())
        except (OSError, pickle.UnpicklingError, EOFError):
            return None

    def put_analyses(self, tables: dict) -> None:
        """Checkpoint the analyses' tables."""
        _write_atomic(self.dir / "analyses.pkl", pickle.dumps(tables, protocol=5))

    def remove(self) -> None:
        """Delete the journal (once the report is published, or to start afresh)."""
        shutil.rmtree(self.dir, ignore_errors=True)


def _case_change(was: Any, now: list) -> tuple[Any, Any]:
    """What differs between two runs' cases: their names, or which files were edited."""
    try:
        names = [n for n, _ in was]
    except (TypeError, ValueError):
        return was, [n for n, _ in now]
    if names != [n for n, _ in now]:
        return names, [n for n, _ in now]
    edited = ", ".join(n for (n, a), (_, b) in zip(was, now, strict=True) if a != b)
    return f"{edited} as it was", f"{edited} edited"


def _short(value: Any) -> str:
    text = value if isinstance(value, str) else json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."
