"""Reading a run's tables (``results.csv``, ``stability.csv``, ``restitution.csv``) that CI
hands back: anything malformed is one short :class:`TableError`, never a traceback and
never a table that passes quietly."""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np
import pandas as pd

from truestep.tables.spec import TABLES

STATUSES = frozenset(
    {"ok", "unstable", "stalled", "solver-failed", "crashed", "timeout", "unsupported", "skipped"}
)
"""Values of a ``status`` column."""

READ = ("results", "stability", "restitution")
"""The tables a run writes and ``truestep gate`` reads (:data:`truestep.tables.spec.TABLES`)."""

NUMERIC = {name: TABLES[name].numeric for name in READ}
"""Columns that must hold numbers (or be empty), per table."""

REQUIRED = {name: frozenset(TABLES[name].where(required=True)) for name in READ}
"""Columns every reader of a table needs, per table."""

TEXT = tuple(dict.fromkeys(c for name in READ for c in TABLES[name].where(kind="name")))
"""Columns that must hold names, not numbers, where a table has them."""


class TableError(ValueError):
    """A table that cannot be used: its message is one line naming the file and the reason."""


MAX_TABLE_BYTES = 64 * 2**20
"""The largest table read (64 MiB; a full run's results table is about 0.3 MiB)."""
MAX_FIELD_CHARS = 20_000
"""The longest field of a table (messages are cut far shorter when a run writes them)."""
MAX_COLUMNS = 1000
"""The most columns a table may have (a results table has about 30)."""
KEYS = {name: TABLES[name].keys for name in READ}
"""What identifies a row, per table: no two rows may share it."""
NA_VALUES = [
    "",
    "#N/A",
    "#N/A N/A",
    "#NA",
    "-1.#IND",
    "-1.#QNAN",
    "-NaN",
    "-nan",
    "1.#IND",
    "1.#QNAN",
    "<NA>",
    "N/A",
    "NA",
    "NULL",
    "NaN",
    "None",
    "n/a",
    "nan",
    "null",
]
"""What reads as a missing value, in every column but the names of :data:`TEXT` (where
``nan`` is a method's name like any other)."""
RAN = ("ok", "unstable", "stalled", "crashed", "timeout")
"""Statuses of rows that were run, so have a step (or tolerance)."""


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _row(table: pd.DataFrame, mask: pd.Series | np.ndarray) -> int:
    """The file line of the first row where ``mask`` holds (the header is line 1)."""
    return int(np.flatnonzero(np.asarray(mask))[0]) + 2


def _value(table: pd.DataFrame, col: str, mask: np.ndarray) -> str:
    """The cell of ``col`` in the first row where ``mask`` holds, as it reads."""
    value = table[col].iloc[_row(table, mask) - 2]
    if pd.isna(value):
        return "empty"
    text = str(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _text_of(path: Path) -> str:
    from truestep.runtime.files import FileRefused, read_regular

    try:
        raw = read_regular(path, MAX_TABLE_BYTES)
    except FileRefused as err:
        raise TableError(str(err)) from None
    if b"\0" in raw:
        raise TableError(f"{path}: holds NUL bytes: not a CSV table")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise TableError(f"{path}: not UTF-8 text (byte {err.start})") from None


def _lines(path: Path, text: str, *, rows: bool) -> list[list[str]]:
    """The table's records, checked for shape: a unique header, rows as wide as it,
    fields of at most :data:`MAX_FIELD_CHARS`."""
    if text.count('"') % 2:
        raise TableError(f"{path}: a quoted field is never closed (the file is cut short?)")
    try:
        lines = [line for line in csv.reader(io.StringIO(text, newline="")) if line]
    except csv.Error as err:
        raise TableError(f"{path}: not a CSV table: {str(err)[:100]}") from None
    if not lines:
        raise TableError(f"{path}: empty: no header and no rows")
    header = lines[0]
    width = len(header)
    if width > MAX_COLUMNS:
        raise TableError(f"{path}: {width} columns, over the {MAX_COLUMNS} a table may have")
    named = [c.strip() for c in header]
    if "" in named:
        raise TableError(f"{path}: column {named.index('') + 1} of the header has no name")
    twice = sorted({c for c in named if named.count(c) > 1})
    if twice:
        raise TableError(f"{path}: column {_short(twice[0])} appears twice in the header")
    for k, line in enumerate(lines, start=1):
        if len(line) != width:
            raise TableError(f"{path}: line {k} has {len(line)} fields, the header {width}")
        longest = max(len(field) for field in line)
        if longest > MAX_FIELD_CHARS:
            raise TableError(
                f"{path}: line {k} has a field of {longest} characters (at most {MAX_FIELD_CHARS})"
            )
    if len(lines) == 1 and rows:
        raise TableError(f"{path}: a header and no rows: nothing to check")
    return lines


def read_table(path: Path, kind: str, needs: set[str], *, rows: bool = True) -> pd.DataFrame:
    """The table at ``path`` (``kind``: ``results``, ``stability`` or ``restitution``), with
    the columns ``needs`` at least, every row as wide as the header, at least one row,
    numbers where :data:`NUMERIC` says and names where :data:`TEXT` says (read as text:
    a method named ``nan`` is that name), known statuses, no two rows with the same key
    (:data:`KEYS`), and numbers that a run can write (:func:`check_rows`). ``rows=False``:
    a header without rows is a table of no rows (a run without stability searches or
    bounces writes one). Only a regular file of at most :data:`MAX_TABLE_BYTES` is read, and
    only a whole one: a file whose last line has no end was cut short. Raises
    :class:`TableError`."""
    path = Path(path)
    text = _text_of(path)
    if text and not text.endswith(("\n", "\r")):
        raise TableError(
            f"{path}: truncated: its last line has no end (a table truestep writes ends with a newline)"
        )
    header = [c.strip() for c in _lines(path, text, rows=rows)[0]]
    names = [c for c in header if c in TEXT]
    try:
        table = pd.read_csv(
            io.StringIO(text),
            dtype={c: str for c in names},
            keep_default_na=False,
            na_values={c: NA_VALUES for c in header if c not in TEXT},
            skipinitialspace=False,
        )
    except (pd.errors.ParserError, pd.errors.EmptyDataError, ValueError, OverflowError) as err:
        raise TableError(f"{path}: cannot read as CSV: {str(err).splitlines()[0][:120]}") from None
    table.columns = [str(c).strip() for c in table.columns]
    missing = needs - set(table.columns)
    if missing:
        raise TableError(f"{path}: missing columns {', '.join(sorted(missing))}")
    for col in NUMERIC.get(kind, ()):
        if col in table and not pd.api.types.is_numeric_dtype(table[col]):
            values = pd.to_numeric(table[col], errors="coerce")
            bad = table[col][values.isna() & table[col].notna()]
            if len(bad):
                raise TableError(
                    f"{path}: column {col}: not a number: {_short(bad.iloc[0])} (row {int(bad.index[0]) + 2})"
                )
            table[col] = values
    for col in names:
        values = table[col].astype(str)
        if not len(values):
            continue
        empty = values.str.strip() == ""
        if col in ("case", "engine", "method", "status") and empty.any():
            raise TableError(
                f"{path}: column {col}: empty (row {_row(table, empty)}): every row names what it is"
            )
        as_numbers = pd.to_numeric(values, errors="coerce").to_numpy(float)
        if np.isfinite(as_numbers).all():
            raise TableError(f"{path}: column {col}: numbers where names belong ({_short(values.iloc[0])})")
        table[col] = values
    if "status" in table:
        unknown = set(table["status"]) - STATUSES
        if unknown:
            raise TableError(
                f"{path}: column status: unknown value {_short(sorted(unknown)[0])} "
                f"(known: {', '.join(sorted(STATUSES))})"
            )
    check_rows(path, kind, table)
    return table


def _numbers(table: pd.DataFrame, col: str) -> np.ndarray:
    return pd.to_numeric(table[col], errors="coerce").to_numpy(float)


def check_rows(path: Path, kind: str, table: pd.DataFrame) -> None:
    """Refuse rows no run writes (:class:`TableError`): two rows with the same key; a run
    row without a positive, finite step (a ``crashed`` row may have none: the adapter's
    answer to what it runs failed before any step); counts and errors that are negative or
    infinite; an ``ok`` row without its evaluation count or with a wall time that is not
    positive; a results table whose ``ok`` rows hold no measurement at all."""
    keys = [k for k in KEYS.get(kind, ()) if k in table]
    if keys and len(table):
        twice = table.duplicated(subset=keys, keep=False).to_numpy()
        if twice.any():
            first = np.flatnonzero(twice)[:2] + 2
            raise TableError(
                f"{path}: rows {first[0]} and {first[1]} have the same "
                f"{', '.join(keys)}: a table holds each run once"
            )
    ran = table["status"].isin(RAN).to_numpy() if "status" in table else np.ones(len(table), bool)
    if "dt" in table:
        dt = _numbers(table, "dt")
        bad = ran & ~(np.isfinite(dt) & (dt > 0))
        if "status" in table:  # a question to the adapter failed before any step: no step
            bad &= ~((table["status"] == "crashed").to_numpy() & np.isnan(dt))
        if bad.any():
            raise TableError(
                f"{path}: column dt: {_value(table, 'dt', bad)} (row {_row(table, bad)}): "
                "a run's step must be positive and finite"
            )
    _check_counts(path, kind, table)
    if kind == "results" and "status" in table:
        _check_ok_rows(path, table)


def _check_counts(path: Path, kind: str, table: pd.DataFrame) -> None:
    """Values no run writes, as the table's spec bounds them (:class:`~truestep.tables.spec.Column`
    ``least``, ``most``, ``whole``): counts, errors and drifts are neither negative nor
    infinite, ``e_set`` is at most 1, ``bounce`` a whole number from 1."""
    for c in TABLES[kind].columns if kind in TABLES else ():
        if c.least is None or c.name not in table:
            continue
        values = _numbers(table, c.name)
        bad = np.isinf(values) | (values < c.least)
        if c.most is not None:
            bad |= values > c.most
        if c.whole:
            bad |= np.isfinite(values) & (values != np.round(values))
        if bad.any():
            raise TableError(
                f"{path}: column {c.name}: {_value(table, c.name, bad)} (row "
                f"{_row(table, bad)}) is not a value a run writes"
            )


def _check_ok_rows(path: Path, table: pd.DataFrame) -> None:
    """A results table's ``ok`` rows: each counts its evaluations and has a positive, finite
    wall time, and at least one of them holds a measurement."""
    ok = (table["status"] == "ok").to_numpy()
    if "nfev" in table:
        bad = ok & ~np.isfinite(_numbers(table, "nfev"))
        if bad.any():
            raise TableError(
                f"{path}: column nfev: empty in an ok row (row {_row(table, bad)}): "
                "every run counts its evaluations"
            )
    if "wall_s" in table:
        wall = _numbers(table, "wall_s")
        bad = ok & ~(np.isfinite(wall) & (wall > 0))
        if bad.any():
            raise TableError(
                f"{path}: column wall_s: {_value(table, 'wall_s', bad)} (row "
                f"{_row(table, bad)}): a run's wall time is positive and finite"
            )
    measured = [c for c in table.columns if c not in NOT_MEASURED and pd.api.types.is_numeric_dtype(table[c])]
    if ok.any() and not any(np.isfinite(_numbers(table[ok], c)).any() for c in measured):
        raise TableError(
            f"{path}: no ok row holds a measurement (error, energy drift or a "
            "property): nothing to check or compare"
        )


NOT_MEASURED = frozenset({"dt", "nfev", "steps", "wall_s", "wall_s_spread", "repeats", "t_fail"})
"""Numeric columns of a results table that describe a run rather than measure it."""


RUN_RECORD = "run.json"
"""The run's record beside its tables, whose ``rows`` (where it has them) are the row
count of each table the run wrote."""


def _run_record(directory: Path) -> dict:
    """The ``run.json`` of ``directory`` as a dictionary; empty where there is none or it
    cannot be read (its own readers say why)."""
    import json

    from truestep.runtime.files import read_regular

    try:
        record = json.loads(read_regular(Path(directory) / RUN_RECORD, 1 << 20).decode("utf-8"))
    except (OSError, ValueError):
        return {}
    return record if isinstance(record, dict) else {}


def recorded_rows(directory: Path) -> dict[str, int]:
    """The row count of each table, as the run that wrote ``directory`` recorded it (the
    ``rows`` of its ``run.json``); empty where it records none (no record, a record of an
    older truestep, or one that cannot be read: its own readers say why)."""
    rows = _run_record(directory).get("rows")
    if not isinstance(rows, dict):
        return {}
    return {str(k): v for k, v in rows.items() if isinstance(v, int) and not isinstance(v, bool)}


def recorded_engines(directory: Path) -> list[str] | None:
    """The engines whose rows the run that wrote ``directory`` published (the ``engines``
    of its ``run.json``, written from the results table itself), or ``None`` where it
    records none."""
    engines = _run_record(directory).get("engines")
    if not isinstance(engines, list) or not all(isinstance(e, str) for e in engines):
        return None
    return engines


def check_recorded_rows(directory: Path, tables: dict[str, pd.DataFrame | None]) -> None:
    """Refuse (:class:`TableError`) a table of ``directory`` that is not the one its run
    recorded: rows not as many as recorded (:func:`recorded_rows`), or a results table
    without a row of an engine the run published, or with rows of one it did not
    (:func:`recorded_engines`). One cut short at the end of a row, or changed after the
    run, reads as a table of fewer runs and nothing else would tell; a baseline whose
    table lacks an engine would compare none of that engine's rows."""
    counts = recorded_rows(directory)
    for name, table in tables.items():
        want = counts.get(name)
        if table is not None and want is not None and len(table) != want:
            raise TableError(
                f"{Path(directory) / f'{name}.csv'}: {len(table)} rows, but the run that wrote it "
                f"recorded {want} ({RUN_RECORD}): the table was cut short or changed since"
            )
    results, engines = tables.get("results"), recorded_engines(directory)
    if results is None or engines is None or "engine" not in results:
        return
    have = set(results["engine"].astype(str))
    lacking, extra = [e for e in engines if e not in have], sorted(have - set(engines))
    if lacking or extra:
        said = "; ".join(
            part
            for part in (
                f"no row of {', '.join(lacking)}, which the run published" if lacking else "",
                f"rows of {', '.join(extra)}, which the run did not publish" if extra else "",
            )
            if part
        )
        raise TableError(
            f"{Path(directory) / 'results.csv'}: {said} ({RUN_RECORD} names {', '.join(engines) or 'none'}): "
            "the table was changed since the run"
        )


def read_run_tables(directory: Path) -> dict[str, pd.DataFrame | None]:
    """``results`` (required) and ``stability``, ``restitution`` (``None`` when absent) of a
    run's output directory, each read strictly (:func:`read_table`) and as many rows as the
    run recorded (:func:`check_recorded_rows`); raises :class:`TableError` for a directory
    that is not one, a missing results table or any malformed table."""
    directory = Path(directory)
    if not directory.is_dir():
        raise TableError(f"{directory}: not a directory of a run's tables")
    results = directory / "results.csv"
    if not os.path.lexists(results):
        raise TableError(f"{results}: no such file (run `truestep run` first)")
    out: dict[str, pd.DataFrame | None] = {
        "results": read_table(results, "results", set(REQUIRED["results"]))
    }
    for name in ("stability", "restitution"):
        path = directory / f"{name}.csv"
        out[name] = read_table(path, name, set(REQUIRED[name]), rows=False) if os.path.lexists(path) else None
    check_recorded_rows(directory, out)
    return out
