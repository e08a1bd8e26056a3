"""The checkpoints of an interrupted ``truestep run``, for ``truestep run --resume``.

Kept in ``.<name>.partial/`` beside the run's ``--out`` (created with mode 0700):

- ``journal.json``: what the run is (truestep version, ``--quick``, engines, and each
  case's name and the SHA-256 of its file), its fingerprint;
- ``sweep-<key>.json``: one per finished (case, engine, method) sweep, its rows and
  energy traces;
- ``analyses.json``: the analyses' tables, once they are done.

Checkpoints are data, never code: each file is a header line of JSON (``schema``, what
the file is, the run's identity, the SHA-256 and size of the body) followed by a body of
strict JSON (:mod:`truestep.execution.checkpoint_data` encodes rows, traces and tables exactly:
floats by their shortest round-trip text, NaN and infinities tagged). Nothing is
unpickled, imported or evaluated. A file that is not one of these names, not a regular
file, over its size cap, of another schema or run, whose checksum does not match or
whose body is not what this run writes, is ignored and listed in one line (its sweep
runs again); only a missing or unusable ``journal.json`` refuses ``--resume`` (exit 2).

Every file is written to a temporary name and renamed into place, so a kill leaves whole
checkpoints or none. The journal is removed once the report is published.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from truestep import __version__
from truestep.cases.case import Case
from truestep.execution.checkpoint_data import (
    DataError,
    dump_json,
    load_json,
    rows_from,
    rows_to,
    tables_from,
    tables_to,
    traces_from,
    traces_to,
)
from truestep.runtime.files import FileRefused, read_regular
from truestep.runtime.publish import beside

SweepKey = tuple[str, str, str]
"""(case, engine, method)."""

SCHEMA = 1
"""The layout of the checkpoint files; a journal of another schema is not resumed."""
JOURNAL_FILE = "journal.json"
ANALYSES_FILE = "analyses.json"
SWEEP_FILE = re.compile(r"sweep-[0-9a-f]{32}\.json")
TMP_PREFIX = ".tmp-"
MAX_CHECKPOINT_BYTES = 64 * 2**20
"""The largest checkpoint read (a sweep's rows and traces are well under 1 MiB)."""
MAX_HEADER_BYTES = 1024
"""The longest header line of a checkpoint file."""
HEADER_KEYS = {"schema", "kind", "run", "sha256", "size"}


class JournalError(Exception):
    """The journal cannot be resumed: missing, unusable or written by a different run."""


def journal_dir(out: Path) -> Path:
    """``.<name>.partial`` beside ``out`` (symbolic links resolved)."""
    return beside(out, "partial")


def _case_digest(case: Case) -> str:
    from truestep.cases.loader import MAX_FILE_BYTES

    try:
        data = read_regular(case.file, MAX_FILE_BYTES)
    except FileRefused:
        data = case.file.encode()
    return hashlib.sha256(data).hexdigest()


def own_sources() -> list[Path]:
    """Every ``.py`` file of the installed ``truestep`` package, sorted by its path inside it:
    the subpackages a source checkout links in (``adapters``, ``cases``,
    ``reference_impl``) are followed, so a fix there changes :func:`code_digest` too."""
    package = Path(__file__).resolve().parents[1]
    found = []
    for folder, dirs, files in os.walk(package, followlinks=True):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        found += [Path(folder, name) for name in files if name.endswith(".py")]
    return sorted(found, key=lambda path: path.relative_to(package).as_posix())


def code_digest(engines: list[str]) -> dict[str, str]:
    """Per engine, a digest of the code its rows come from: the source of its adapter's
    module, the version of the distribution that holds it, and, for truestep's own
    engines (an adapter module of the ``truestep`` package), every source file of truestep
    (:func:`own_sources`: the reference's kernels, the harness that measures). A fix to an
    adapter changes it, so ``--resume`` never reuses sweeps the buggy code made.
    truestep's own version is in the fingerprint already (:func:`fingerprint`): the
    distribution that holds another engine's adapter is looked up by its top-level name
    (:func:`truestep.runtime.distributions.holding`)."""
    import functools
    import inspect
    from importlib import metadata

    from truestep.adapters import adapter_class
    from truestep.runtime.distributions import holding

    package = Path(__file__).resolve().parents[1]

    @functools.cache
    def own() -> bytes:
        digest = hashlib.sha256()
        for path in own_sources():
            digest.update(path.relative_to(package).as_posix().encode())
            digest.update(path.read_bytes())
        return digest.digest()

    out = {}
    for engine in engines:
        h = hashlib.sha256()
        try:
            module = inspect.getmodule(adapter_class(engine))
            source = inspect.getsourcefile(module) if module is not None else None
        except Exception:  # an engine that cannot be imported here: its name alone
            module, source = None, None
        if source is not None:
            h.update(Path(source).read_bytes())
        top = module.__name__.split(".")[0] if module is not None else ""
        if top == "truestep":
            h.update(own())
        else:
            for dist in holding(top) if top else []:
                h.update(f"{dist} {metadata.version(dist)}".encode())
        out[engine] = h.hexdigest()[:16]
    return out


def fingerprint(
    cases: list[Case], engines: list[str], quick: bool, devices: dict[str, str] | None = None
) -> dict[str, Any]:
    """What a resumed run must share with the interrupted one: truestep's version,
    ``--quick``, the engines and the code they run (:func:`code_digest`), the cases'
    files, and the devices of the engines put off the CPU (``--device``; a run on the
    CPU alone has no such entry, as before ``--device`` was)."""
    return {
        "truestep": __version__,
        "quick": bool(quick),
        "engines": list(engines),
        "code": code_digest(list(engines)),
        "cases": [[c.name, _case_digest(c)] for c in cases],
        **({"devices": dict(sorted(devices.items()))} if devices else {}),
    }


def run_id(fp: dict[str, Any]) -> str:
    """The identity of a run: the SHA-256 of its fingerprint's canonical JSON."""
    return hashlib.sha256(dump_json(fp).encode()).hexdigest()


def _encode(kind: str, run: str, body: Any) -> bytes:
    """A checkpoint file: the header line, then the body."""
    data = dump_json(body).encode()
    header = {
        "schema": SCHEMA,
        "kind": kind,
        "run": run,
        "sha256": hashlib.sha256(data).hexdigest(),
        "size": len(data),
    }
    return json.dumps(header, sort_keys=True).encode() + b"\n" + data


def _decode(raw: bytes, kind: str, run: str | None) -> Any:
    """The body of a checkpoint file of ``kind`` written by the run ``run`` (any run if
    ``None``); raises :class:`DataError` saying why not."""
    head, sep, data = raw.partition(b"\n")
    if not sep or len(head) > MAX_HEADER_BYTES:
        raise DataError("no header line")
    try:
        header = json.loads(head)
    except ValueError:
        raise DataError("its header is not JSON") from None
    if not isinstance(header, dict) or set(header) != HEADER_KEYS:
        raise DataError("its header is not a checkpoint's")
    if header["schema"] != SCHEMA:
        raise DataError(f"schema {str(header['schema'])[:20]}, not {SCHEMA}")
    if header["kind"] != kind:
        raise DataError(f"a {str(header['kind'])[:20]} checkpoint, not a {kind}")
    if run is not None and header["run"] != run:
        raise DataError("written by another run")
    if header["size"] != len(data) or header["sha256"] != hashlib.sha256(data).hexdigest():
        raise DataError("its checksum does not match its contents")
    return load_json(data)


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.parent / f"{TMP_PREFIX}{os.getpid()}-{path.name}"
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


@dataclass
class Survey:
    """What :meth:`Journal.resume` found: the usable checkpoints and what it ignored."""

    sweeps: dict[str, Path] = field(default_factory=dict)
    analyses: Path | None = None
    ignored: list[str] = field(default_factory=list)

    def ignored_line(self, where: Path) -> str:
        """One line listing what was ignored (at most three by name), or ``""``."""
        if not self.ignored:
            return ""
        shown = "; ".join(self.ignored[:3])
        more = f"; and {len(self.ignored) - 3} more" if len(self.ignored) > 3 else ""
        return (
            f"{where}: ignored {len(self.ignored)} entries that are not this run's "
            f"checkpoints, never loaded ({shown}{more})"
        )[:400]


class Journal:
    """The checkpoints of one run, in ``.<name>.partial`` beside ``out``."""

    def __init__(self, out: Path) -> None:
        self.dir = journal_dir(out)
        self.run: str | None = None
        self._survey = Survey()

    def start(self, fp: dict[str, Any]) -> None:
        """Start afresh: drop any earlier journal (or whatever has its name), record ``fp``."""
        self.remove()
        self.dir.mkdir(mode=0o700, parents=True)
        self.run = run_id(fp)
        self._survey = Survey()
        _write_atomic(self.dir / JOURNAL_FILE, _encode("journal", self.run, fp))

    def resume(self, fp: dict[str, Any]) -> int:
        """Continue the journal: it must be a directory of this user's holding a
        ``journal.json`` that records ``fp``; returns the number of usable finished
        sweeps. Raises :class:`JournalError` (one line) otherwise. Every other entry is
        looked at without being loaded; those that are not checkpoints of this run are
        listed by :meth:`ignored_line`."""
        try:
            st = os.lstat(self.dir)
        except OSError:
            raise JournalError(f"no interrupted run to resume: {self.dir} does not exist") from None
        if not stat.S_ISDIR(st.st_mode):
            raise JournalError(
                f"{self.dir} is not a directory truestep wrote (a symbolic link "
                "or a file); run without --resume to start afresh"
            )
        if st.st_uid != os.geteuid():
            raise JournalError(
                f"{self.dir} belongs to another user (uid {st.st_uid}); run without --resume to start afresh"
            )
        try:
            kept = _decode(
                read_regular(self.dir / JOURNAL_FILE, MAX_CHECKPOINT_BYTES, follow_links=False),
                "journal",
                None,
            )
        except FileRefused as err:
            raise JournalError(f"no interrupted run to resume: {err}") from None
        except DataError as err:
            raise JournalError(
                f"{self.dir / JOURNAL_FILE}: not a journal of truestep's: {err}; "
                "run without --resume to start afresh"
            ) from None
        if not isinstance(kept, dict):
            raise JournalError(
                f"{self.dir / JOURNAL_FILE}: not a journal of truestep's; "
                "run without --resume to start afresh"
            )
        for key, what in (
            ("truestep", "truestep version"),
            ("quick", "--quick"),
            ("engines", "engines"),
            ("code", "engine code (an adapter, its package or truestep changed since)"),
            ("cases", "cases"),
            ("devices", "devices (--device)"),
        ):
            was, now = kept.get(key, {} if key == "devices" else None), fp.get(key, {})
            if was != now:
                if key == "cases":
                    was, now = _case_change(was, now)
                raise JournalError(
                    f"the interrupted run in {self.dir} had other {what} "
                    f"({_short(was)}, now {_short(now)}); "
                    "run without --resume to start afresh"
                )
        self.run = run_id(fp)
        self._survey = self._look()
        return len(self._survey.sweeps)

    def _look(self) -> Survey:
        """Sort the journal's entries into usable checkpoints and ignored ones (whose
        names are kept): verified now, so a resumed run says once what it ignores."""
        survey = Survey()
        for entry in sorted(os.scandir(self.dir), key=lambda e: e.name):
            name = entry.name
            if name == JOURNAL_FILE:
                continue
            if name.startswith(TMP_PREFIX) and entry.is_file(follow_symlinks=False):
                Path(entry.path).unlink(missing_ok=True)  # a write a kill cut short
                continue
            kind = "sweep" if SWEEP_FILE.fullmatch(name) else "analyses" if name == ANALYSES_FILE else None
            if kind is None:
                survey.ignored.append(f"{_short(name)}: not a checkpoint's name")
                continue
            try:
                _decode(read_regular(entry.path, MAX_CHECKPOINT_BYTES, follow_links=False), kind, self.run)
            except (FileRefused, DataError) as err:
                survey.ignored.append(f"{name}: {getattr(err, 'reason', err)}")
                continue
            if kind == "sweep":
                survey.sweeps[name] = Path(entry.path)
            else:
                survey.analyses = Path(entry.path)
        return survey

    def ignored_line(self) -> str:
        """One line naming what :meth:`resume` ignored, or ``""`` if nothing."""
        return self._survey.ignored_line(self.dir)

    def finished(self) -> int:
        """The sweeps checkpointed so far (files with a sweep checkpoint's name)."""
        try:
            return sum(1 for name in os.listdir(self.dir) if SWEEP_FILE.fullmatch(name))
        except OSError:
            return 0

    def holds_run(self) -> bool:
        """Whether the journal has its ``journal.json`` (so ``--resume`` can continue it)."""
        return os.path.isfile(self.dir / JOURNAL_FILE) and not os.path.islink(self.dir)

    def _sweep_name(self, key: SweepKey) -> str:
        digest = hashlib.sha256(json.dumps(list(key)).encode()).hexdigest()[:32]
        return f"sweep-{digest}.json"

    def _read(self, path: Path | None, kind: str) -> Any:
        if path is None or self.run is None:
            return None
        try:
            return _decode(read_regular(path, MAX_CHECKPOINT_BYTES, follow_links=False), kind, self.run)
        except (FileRefused, DataError):
            return None

    def sweep(self, key: SweepKey, dts: list[float]) -> tuple[list[dict], dict] | None:
        """The rows and traces of a finished sweep over ``dts``, or ``None`` (not
        checkpointed, or its checkpoint is not exactly what this sweep writes)."""
        body = self._read(self._survey.sweeps.get(self._sweep_name(key)), "sweep")
        if not isinstance(body, dict) or set(body) != {"key", "dts", "rows", "traces"}:
            return None
        if body["key"] != list(key) or body["dts"] != [float(d) for d in dts]:
            return None
        try:
            rows = rows_from(body["rows"], key, dts)
            traces = traces_from(body["traces"], key)
        except DataError:
            return None
        return rows, traces

    def put_sweep(self, key: SweepKey, dts: list[float], rows: list[dict], traces: dict) -> None:
        """Checkpoint a finished sweep (one holding a value JSON cannot carry exactly is
        not checkpointed: a resumed run runs it again)."""
        if self.run is None:
            return
        try:
            body = {
                "key": list(key),
                "dts": [float(d) for d in dts],
                "rows": rows_to(rows),
                "traces": traces_to(traces),
            }
        except DataError:
            return
        path = self.dir / self._sweep_name(key)
        _write_atomic(path, _encode("sweep", self.run, body))
        self._survey.sweeps[path.name] = path

    def analyses(self) -> dict | None:
        """The analyses' tables, if they were checkpointed (and their checkpoint is whole)."""
        body = self._read(self._survey.analyses, "analyses")
        if body is None:
            return None
        try:
            return tables_from(body)
        except DataError:
            return None

    def put_analyses(self, tables: dict) -> None:
        """Checkpoint the analyses' tables (unless a value has no exact JSON form)."""
        if self.run is None:
            return
        try:
            body = tables_to(tables)
        except DataError:
            return
        path = self.dir / ANALYSES_FILE
        _write_atomic(path, _encode("analyses", self.run, body))
        self._survey.analyses = path

    def remove(self) -> None:
        """Delete the journal (once the report is published, or to start afresh); a
        symbolic link or file in its place is removed, never followed. A folder of that
        name that truestep did not make (files in it, no journal among them) is the user's:
        :class:`JournalError`, and it is left as it is."""
        if os.path.islink(self.dir) or (os.path.lexists(self.dir) and not self.dir.is_dir()):
            self.dir.unlink(missing_ok=True)
        elif self.dir.is_dir():
            if not (self.dir / JOURNAL_FILE).exists() and any(self.dir.iterdir()):
                raise JournalError(
                    f"{self.dir} is a folder truestep did not make (no {JOURNAL_FILE} in it), where a "
                    "run keeps its checkpoints: rename or remove it; nothing was deleted"
                )
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
    from truestep.runtime.visible import visible

    text = value if isinstance(value, str) else json.dumps(value)
    text = visible(text)
    return text if len(text) <= 60 else text[:57] + "..."
