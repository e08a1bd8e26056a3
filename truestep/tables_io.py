"""Reading a run's tables (``results.csv``, ``stability.csv``, ``restitution.csv``) that CI
hands back: anything malformed is one short :class:`TableError`, never a traceback and
never a table that passes quietly."""

from __future__ import annotations

import csv
from pathlib import Path

import pandas as pd

STATUSES = frozenset({"ok", "unstable", "solver-failed", "crashed", "timeout", "unsupported",
                      "skipped"})
"""Values of a ``status`` column."""

NUMERIC = {
    "results": ("dt", "error", "error_final", "error_v", "energy_drift", "energy_drift_final",
                "nfev", "steps", "wall_s", "wall_s_spread", "repeats", "t_fail"),
    "stability": ("dt_limit", "dt_limit_exact", "dt_unstable", "runs"),
    "restitution": ("dt", "e_set", "bounce", "e_measured", "e_apex", "v_in", "v_out", "apex",
                    "penetration"),
}
"""Columns that must hold numbers (or be empty), per table."""

REQUIRED = {
    "results": frozenset({"case", "engine", "method", "dt", "dt_kind", "status", "error"}),
    "stability": frozenset({"case", "engine", "method", "dt_limit", "dt_limit_exact", "status"}),
    "restitution": frozenset({"engine", "method", "dt", "e_set", "bounce", "e_measured", "status"}),
}
"""Columns every reader of a table needs, per table."""

TEXT = ("case", "engine", "method", "dt_kind", "status")
"""Columns that must hold names, not numbers, where a table has them."""


class TableError(ValueError):
    """A table that cannot be used: its message is one line naming the file and the reason."""


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def read_table(path: Path, kind: str, needs: set[str], *, rows: bool = True) -> pd.DataFrame:
    """The table at ``path`` (``kind``: ``results``, ``stability`` or ``restitution``), with
    the columns ``needs`` at least, every row as wide as the header, at least one row,
    numbers where :data:`NUMERIC` says and names where :data:`TEXT` says, and known
    statuses. ``rows=False``: a header without rows is a table of no rows (a run without
    stability searches or bounces writes one). Raises :class:`TableError`."""
    path = Path(path)
    if path.is_dir():
        raise TableError(f"{path}: is a directory, not a CSV file")
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise TableError(f"{path}: cannot read: {err.strerror or err}") from None
    if b"\0" in raw:
        raise TableError(f"{path}: holds NUL bytes: not a CSV table")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise TableError(f"{path}: not UTF-8 text (byte {err.start})") from None
    if text.count('"') % 2:
        raise TableError(f"{path}: a quoted field is never closed (the file is cut short?)")
    lines = list(csv.reader(text.splitlines()))
    lines = [line for line in lines if line]
    if not lines:
        raise TableError(f"{path}: empty: no header and no rows")
    width = len(lines[0])
    for k, line in enumerate(lines[1:], start=2):
        if len(line) != width:
            raise TableError(f"{path}: line {k} has {len(line)} fields, the header {width}")
    if len(lines) == 1 and rows:
        raise TableError(f"{path}: a header and no rows: nothing to check")
    try:
        table = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, ValueError) as err:
        raise TableError(f"{path}: cannot read as CSV: {str(err).splitlines()[0][:120]}") from None
    missing = needs - set(table.columns)
    if missing:
        raise TableError(f"{path}: missing columns {', '.join(sorted(missing))}")
    for col in NUMERIC.get(kind, ()):
        if col in table and not pd.api.types.is_numeric_dtype(table[col]):
            values = pd.to_numeric(table[col], errors="coerce")
            bad = table[col][values.isna() & table[col].notna()]
            if len(bad):
                raise TableError(f"{path}: column {col}: not a number: {_short(bad.iloc[0])} "
                                 f"(row {int(bad.index[0]) + 2})")
            table[col] = values
    for col in TEXT:
        if col in table and pd.api.types.is_numeric_dtype(table[col]) and table[col].notna().any():
            raise TableError(f"{path}: column {col}: numbers where names belong "
                             f"({_short(table[col].dropna().iloc[0])})")
    if "status" in table and table["status"].isna().any():
        row = int(table.index[table["status"].isna()][0]) + 2
        raise TableError(f"{path}: column status: empty (row {row}): every row says what became of it")
    if "status" in table:
        unknown = set(table["status"].dropna().astype(str)) - STATUSES
        if unknown:
            raise TableError(f"{path}: column status: unknown value {_short(sorted(unknown)[0])} "
                             f"(known: {', '.join(sorted(STATUSES))})")
    return table


def read_run_tables(directory: Path) -> dict[str, pd.DataFrame | None]:
    """``results`` (required) and ``stability``, ``restitution`` (``None`` when absent) of a
    run's output directory, each read strictly (:func:`read_table`); raises
    :class:`TableError` for a directory that is not one, a missing results table or any
    malformed table."""
    directory = Path(directory)
    if not directory.is_dir():
        raise TableError(f"{directory}: not a directory of a run's tables")
    results = directory / "results.csv"
    if not results.exists():
        raise TableError(f"{results}: no such file (run `truestep run` first)")
    out: dict[str, pd.DataFrame | None] = {
        "results": read_table(results, "results", set(REQUIRED["results"]))}
    for name in ("stability", "restitution"):
        path = directory / f"{name}.csv"
        out[name] = read_table(path, name, set(REQUIRED[name]), rows=False) if path.exists() else None
    return out
