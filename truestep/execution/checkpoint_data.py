"""Rows, energy traces and tables as strict JSON, exactly, for the run's checkpoints.

JSON carries what a sweep or the analyses make without loss: a float is written as the
shortest text that reads back to the same double, an integer as an integer, text as
text. What strict JSON cannot say is tagged: NaN and the infinities as ``{"f": "nan"}``,
``{"f": "inf"}``, ``{"f": "-inf"}``, pandas' missing value as ``{"na": true}``. Reading is
as strict: no NaN or Infinity literals, no number that overflows a float, only the
shapes written here (:class:`DataError` otherwise). A decoded checkpoint is plain
numbers, text and numpy arrays of floats: nothing in it can run.
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

import numpy as np
import pandas as pd

MAX_TEXT = 100_000
"""The longest text value a checkpoint may hold (a row's message is far shorter)."""
MAX_COLUMNS = 500
"""The most columns of a row or a table."""
MAX_POINTS = 1_000_000
"""The most points of an energy trace (runs keep 400)."""
COLUMN = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")
"""What a column name is."""
DTYPES = frozenset({"float64", "int64", "bool", "object", "str", "string", "Int64", "Float64", "boolean"})
"""Column types a checkpointed table may have."""
DT_KINDS = frozenset({"step", "tolerance"})
_TAGS = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}


class DataError(ValueError):
    """A checkpoint that is not what a run writes; ``str()`` says why, briefly."""


def _refuse_constant(name: str) -> float:
    raise DataError(f"holds the non-standard constant {name}")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise DataError(f"holds a number beyond a float's range ({text[:20]})")
    return value


def dump_json(value: Any) -> str:
    """``value`` (already encoded: dicts, lists, finite floats, ints, text) as compact
    strict JSON."""
    return json.dumps(value, allow_nan=False, ensure_ascii=True, separators=(",", ":"), sort_keys=True)


def load_json(data: bytes) -> Any:
    """Strict JSON (UTF-8) as Python values; :class:`DataError` if it is anything else."""
    try:
        return json.loads(data.decode("utf-8"), parse_constant=_refuse_constant, parse_float=_finite_float)
    except DataError:
        raise
    except (ValueError, RecursionError) as err:
        raise DataError(f"not strict JSON ({type(err).__name__})") from None


def encode_scalar(value: Any) -> Any:
    """A row or table cell as JSON: ``None``, a bool, an int, a finite float, text, or a
    tagged non-finite float or missing value."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        value = float(value)
        if math.isfinite(value):
            return value
        return {"f": "nan" if math.isnan(value) else "inf" if value > 0 else "-inf"}
    if value is pd.NA:
        return {"na": True}
    if isinstance(value, np.ndarray) and value.ndim == 0:
        return encode_scalar(value.item())
    raise DataError(f"a value of type {type(value).__name__} has no checkpoint form")


def decode_scalar(value: Any) -> Any:
    """:func:`encode_scalar` undone; :class:`DataError` for anything it does not write."""
    if value is None or isinstance(value, bool | int | float):
        return value
    if isinstance(value, str):
        if len(value) > MAX_TEXT:
            raise DataError(f"holds a text of {len(value)} characters")
        return value
    if isinstance(value, dict) and len(value) == 1:
        if value.get("f") in _TAGS:
            return _TAGS[value["f"]]
        if value.get("na") is True:
            return pd.NA
    raise DataError("holds a value that is not a number, a text or a tagged float")


def _floats(values: Any, what: str) -> np.ndarray:
    if not isinstance(values, list) or len(values) > MAX_POINTS:
        raise DataError(f"{what} is not a list of at most {MAX_POINTS} numbers")
    out = [decode_scalar(v) for v in values]
    if not all(isinstance(v, float | int) and not isinstance(v, bool) for v in out):
        raise DataError(f"{what} holds something other than numbers")
    return np.asarray(out, dtype=float)


def rows_to(rows: list[dict]) -> list[dict]:
    """A sweep's rows, encoded."""
    return [{str(k): encode_scalar(v) for k, v in row.items()} for row in rows]


def rows_from(data: Any, key: tuple[str, str, str], dts: list[float]) -> list[dict]:
    """A sweep's rows decoded and checked: one per step of ``dts`` in order, each naming
    the sweep's case, engine and method, with a known status and named columns."""
    from truestep.tables.io import STATUSES

    if not isinstance(data, list) or len(data) != len(dts):
        raise DataError("the rows are not one per step of the sweep")
    rows = []
    for raw, dt in zip(data, dts, strict=True):
        if not isinstance(raw, dict) or len(raw) > MAX_COLUMNS:
            raise DataError("a row is not a table of columns")
        if not all(isinstance(k, str) and COLUMN.fullmatch(k) for k in raw):
            raise DataError("a row has a column without a column's name")
        row = {k: decode_scalar(v) for k, v in raw.items()}
        if (row.get("case"), row.get("engine"), row.get("method")) != key:
            raise DataError("a row belongs to another sweep")
        if row.get("dt") != float(dt) or row.get("status") not in STATUSES:
            raise DataError("a row has another step or an unknown status")
        rows.append(row)
    return rows


def traces_to(traces: dict) -> list[dict]:
    """Energy traces ``{(case, engine, method, dt_kind, dt): (t, energy)}``, encoded."""
    out = []
    for (case, engine, method, kind, dt), (t, energy) in traces.items():
        out.append(
            {
                "key": [case, engine, method, kind, encode_scalar(dt)],
                "t": [encode_scalar(v) for v in np.asarray(t, float)],
                "energy": [encode_scalar(v) for v in np.asarray(energy, float)],
            }
        )
    return out


def traces_from(data: Any, key: tuple[str, str, str]) -> dict:
    """Energy traces decoded and checked: each of the sweep's case, engine and method, a
    known step kind, times and energies of one length."""
    if not isinstance(data, list):
        raise DataError("the traces are not a list")
    out = {}
    for item in data:
        if not isinstance(item, dict) or set(item) != {"key", "t", "energy"}:
            raise DataError("a trace is not a key, times and energies")
        k = item["key"]
        if not isinstance(k, list) or len(k) != 5 or tuple(k[:3]) != key or k[3] not in DT_KINDS:
            raise DataError("a trace belongs to another sweep")
        dt = decode_scalar(k[4])
        if not isinstance(dt, float) or not dt > 0:
            raise DataError("a trace has no step")
        t, energy = _floats(item["t"], "a trace's times"), _floats(item["energy"], "a trace's energies")
        if len(t) != len(energy):
            raise DataError("a trace's times and energies differ in length")
        out[(*key, k[3], dt)] = (t, energy)
    return out


def tables_to(tables: dict[str, pd.DataFrame]) -> dict[str, dict]:
    """The analyses' tables (with their ``attrs``), encoded column by column."""
    out = {}
    for name, table in tables.items():
        out[str(name)] = {
            "columns": [str(c) for c in table.columns],
            "dtypes": [str(table[c].dtype) for c in table.columns],
            "data": [[encode_scalar(v) for v in table[c].tolist()] for c in table.columns],
            "rows": len(table),
            "attrs": {str(k): encode_scalar(v) for k, v in table.attrs.items()},
        }
    return out


def tables_from(data: Any) -> dict[str, pd.DataFrame]:
    """The analyses' tables decoded and checked: named columns of known types, all of
    one length, ``attrs`` of numbers and text."""
    if not isinstance(data, dict) or not all(isinstance(k, str) and COLUMN.fullmatch(k) for k in data):
        raise DataError("the analyses are not named tables")
    tables = {}
    for name, t in data.items():
        if not isinstance(t, dict) or set(t) != {"columns", "dtypes", "data", "rows", "attrs"}:
            raise DataError(f"table {name} is not columns, types, data, rows and attrs")
        columns, dtypes, columns_data, rows = t["columns"], t["dtypes"], t["data"], t["rows"]
        if not (
            isinstance(columns, list)
            and isinstance(dtypes, list)
            and isinstance(columns_data, list)
            and len(columns) == len(dtypes) == len(columns_data) <= MAX_COLUMNS
            and isinstance(rows, int)
            and not isinstance(rows, bool)
            and 0 <= rows <= MAX_POINTS
        ):
            raise DataError(f"table {name} has columns, types and data that do not match")
        named = all(isinstance(c, str) and COLUMN.fullmatch(c) for c in columns)
        if not named or len(set(columns)) != len(columns):
            raise DataError(f"table {name} has a column without a column's name")
        if not all(d in DTYPES for d in dtypes):
            raise DataError(f"table {name} has a column of an unknown type")
        series = {}
        for c, d, values in zip(columns, dtypes, columns_data, strict=True):
            if not isinstance(values, list) or len(values) != rows:
                raise DataError(f"table {name} column {c} is not {rows} values long")
            try:
                series[c] = pd.Series([decode_scalar(v) for v in values], dtype=d)
            except (TypeError, ValueError) as err:
                raise DataError(
                    f"table {name} column {c} does not hold {d} values ({type(err).__name__})"
                ) from None
        table = pd.DataFrame(series, columns=columns) if columns else pd.DataFrame(index=range(rows))
        attrs = t["attrs"]
        if not isinstance(attrs, dict) or len(attrs) > MAX_COLUMNS:
            raise DataError(f"table {name} has attrs that are not a table")
        table.attrs.update({str(k): decode_scalar(v) for k, v in attrs.items()})
        tables[name] = table
    return tables
