"""Typed, checked access to one TOML table, naming the field in every error.

Every reader checks type, finiteness, sign and range, and an error quotes at most a few
dozen characters of the offending value (:func:`short`), so that a line stays short
whatever a file holds.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from truestep.cases.errors import CaseError

_MISSING = object()
QUOTE_CHARS = 40
"""The most characters of an offending value an error line quotes."""
MAX_INTEGER = 10**15
"""The largest integer any field takes (counts, seeds, indices): beyond it no run can
allocate or loop, and numpy's integers would overflow."""


def short(value: Any) -> str:
    """``repr(value)``, cut to :data:`QUOTE_CHARS` characters (with ``...``) for errors;
    an integer of more than 30 digits is described by its size."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 99:
        return f"an integer of about {int(value.bit_length() * math.log10(2))} digits"
    try:
        text = repr(value)
    except ValueError:  # it holds an integer beyond Python's digit limit for str()
        return f"a {type(value).__name__} holding an integer of over 4300 digits"
    return text if len(text) <= QUOTE_CHARS else text[: QUOTE_CHARS - 3] + "..."


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


class Fields:
    """A TOML table read field by field; every problem raises :class:`CaseError`.

    ``path`` is the dotted location of the table (``"scene.planes[0]"``); a field's
    name in errors is ``path.field``. Call :meth:`done` after reading to reject
    unknown (misspelt) fields.
    """

    def __init__(self, file: str, table: Any, path: str = "") -> None:
        if not isinstance(table, dict):
            raise CaseError(
                file, path or "<top>", f"expected a table, got {type(table).__name__} {short(table)}"
            )
        self.file, self.table, self.path = file, table, path
        self._read: set[str] = set()

    def where(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def error(self, name: str, reason: str) -> CaseError:
        return CaseError(self.file, self.where(name), reason)

    def has(self, name: str) -> bool:
        return name in self.table

    def raw(self, name: str, default: Any = _MISSING) -> Any:
        self._read.add(name)
        if name not in self.table:
            if default is _MISSING:
                raise self.error(name, "required field is missing")
            return default
        return self.table[name]

    def _float(self, name: str, value: Any, what: str = "a number") -> float:
        if not _is_number(value):
            raise self.error(name, f"expected {what}, got {short(value)}")
        try:
            out = float(value)
        except OverflowError:
            raise self.error(name, f"{short(value)} is beyond the range of a float") from None
        if not math.isfinite(out):
            raise self.error(name, f"must be finite, got {out}")
        return out

    def number(
        self,
        name: str,
        default: Any = _MISSING,
        *,
        positive: bool = False,
        nonnegative: bool = False,
        at_most: float | None = None,
        below: float | None = None,
        at_least: float | None = None,
    ) -> float:
        """A finite number (int or float in the file), as float; ``None`` if the default
        is ``None`` and the field is absent. ``positive``: > 0; ``nonnegative``: >= 0;
        ``at_most``, ``below``, ``at_least``: bounds."""
        value = self.raw(name, default)
        if value is None:
            return None  # type: ignore[return-value]  # only when the default is None
        value = self._float(name, value)
        if positive and value <= 0:
            raise self.error(name, f"must be positive, got {value:g}")
        if nonnegative and value < 0:
            raise self.error(name, f"must not be negative, got {value:g}")
        if at_most is not None and value > at_most:
            raise self.error(name, f"must be at most {at_most:g}, got {value:g}")
        if below is not None and value >= below:
            raise self.error(name, f"must be below {below:g}, got {value:g}")
        if at_least is not None and value < at_least:
            raise self.error(name, f"must be at least {at_least:g}, got {value:g}")
        return value

    def integer(
        self, name: str, default: Any = _MISSING, *, minimum: int | None = None, maximum: int = MAX_INTEGER
    ) -> int:
        """An integer of the file (not a float, not a bool) in ``minimum..maximum``."""
        value = self.raw(name, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(name, f"expected an integer, got {short(value)}")
        if minimum is not None and value < minimum:
            raise self.error(name, f"must be at least {minimum}, got {short(value)}")
        if value > maximum:
            raise self.error(name, f"must be at most {maximum:g}, got {short(value)}")
        return value

    def boolean(self, name: str, default: Any = _MISSING) -> bool:
        value = self.raw(name, default)
        if not isinstance(value, bool):
            raise self.error(name, f"expected true or false, got {short(value)}")
        return value

    def string(
        self, name: str, default: Any = _MISSING, *, choices: Any = None, max_length: int = 200
    ) -> str:
        """A string of at most ``max_length`` characters, one of ``choices`` if given."""
        value = self.raw(name, default)
        if value is None:
            return None  # type: ignore[return-value]  # only when the default is None
        if not isinstance(value, str):
            raise self.error(name, f"expected a string, got {short(value)}")
        if choices is not None and value not in choices:
            raise self.error(name, f"{short(value)} is not one of {', '.join(sorted(choices))}")
        if len(value) > max_length:
            raise self.error(name, f"at most {max_length} characters, got {len(value)}")
        if "\x00" in value:
            raise self.error(name, "must not hold a NUL character")
        return value

    def text(self, name: str, default: Any = _MISSING, *, max_length: int = 20_000) -> str:
        """Prose (a title, a description): a string, shown as text wherever it appears."""
        return self.string(name, default, max_length=max_length)

    def strings(self, name: str, default: Any = _MISSING, *, choices: Any = None) -> list[str]:
        value = self.raw(name, default)
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise self.error(name, f"expected a list of strings, got {short(value)}")
        if len(value) > 1000:
            raise self.error(name, f"at most 1000 entries, got {len(value)}")
        for v in value:
            if choices is not None and v not in choices:
                raise self.error(name, f"{short(v)} is not one of {', '.join(sorted(choices))}")
            if len(v) > 200 or "\x00" in v:
                raise self.error(name, f"{short(v)}: at most 200 characters, no NUL")
        return list(value)

    def numbers(
        self,
        name: str,
        default: Any = _MISSING,
        *,
        positive: bool = False,
        nonempty: bool = True,
        max_length: int = 10_000,
    ) -> list[float]:
        """A list of finite numbers (at most ``max_length``)."""
        value = self.raw(name, default)
        if not isinstance(value, list) or not all(_is_number(v) for v in value):
            raise self.error(name, f"expected a list of numbers, got {short(value)}")
        if nonempty and not value:
            raise self.error(name, "must not be empty")
        if len(value) > max_length:
            raise self.error(name, f"at most {max_length} values, got {len(value)}")
        out = [self._float(name, v) for v in value]
        if positive and any(v <= 0 for v in out):
            raise self.error(name, f"every value must be positive, got {short(value)}")
        return out

    def array(self, name: str, default: Any = _MISSING, *, shape: tuple[int | None, ...]) -> np.ndarray:
        """An array of finite numbers with the given shape (``None`` for any length)."""
        value = self.raw(name, default)
        if isinstance(value, np.ndarray):
            arr = value.astype(float)
        else:
            if not _nested_numbers(value, shape):
                reason = f"expected numbers of shape {_fmt(shape)}, got {short(value)}"
                raise self.error(name, reason)
            try:
                arr = np.asarray(value, dtype=float)
            except OverflowError:
                raise self.error(name, "holds a number beyond the range of a float") from None
            except (TypeError, ValueError):
                reason = f"expected numbers of shape {_fmt(shape)}, got {short(value)}"
                raise self.error(name, reason) from None
        wrong = arr.ndim != len(shape) or any(
            s is not None and s != a for s, a in zip(shape, arr.shape, strict=True)
        )
        if wrong:
            raise self.error(name, f"expected shape {_fmt(shape)}, got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise self.error(name, "every value must be finite")
        return arr

    def vec3(self, name: str, default: Any = _MISSING) -> np.ndarray:
        return self.array(name, default, shape=(3,))

    def indices(
        self, name: str, n: int, *, shape: tuple[int | None, ...], default: Any = _MISSING
    ) -> np.ndarray:
        """An integer array of the given shape whose entries number particles ``0..n-1``."""
        value = self.raw(name, default)
        if not _nested_integers(value, shape):
            raise self.error(name, f"expected integers of shape {_fmt(shape)}, got {short(value)}")
        try:
            arr = np.asarray(value, dtype=np.int64) if _fits_int64(value) else None
        except ValueError:  # ragged: rows of different lengths
            raise self.error(name, f"expected integers of shape {_fmt(shape)}, got {short(value)}") from None
        if arr is not None and (
            arr.ndim != len(shape)
            or any(s is not None and s != a for s, a in zip(shape, arr.shape, strict=True))
        ):
            raise self.error(name, f"expected shape {_fmt(shape)}, got {arr.shape}")
        if arr is None or np.any(arr < 0) or np.any(arr >= n):
            raise self.error(name, f"particle index out of range 0..{n - 1}")
        return arr

    def sub(self, name: str, default: Any = _MISSING) -> Fields:
        return Fields(self.file, self.raw(name, default), self.where(name))

    def subs(self, name: str) -> list[Fields]:
        """An array of tables (``[[name]]``), possibly empty."""
        value = self.raw(name, [])
        if not isinstance(value, list):
            raise self.error(name, f"expected an array of tables ([[...]]), got {short(value)}")
        return [Fields(self.file, v, f"{self.where(name)}[{i}]") for i, v in enumerate(value)]

    def done(self) -> None:
        """Reject fields that were never read: they are misspelt or unsupported."""
        unknown = sorted(set(self.table) - self._read)
        if unknown:
            raise self.error(short(unknown[0]).strip("'"), "unknown field")


def _nested_numbers(value: Any, shape: tuple[int | None, ...]) -> bool:
    """Whether ``value`` is lists nested as ``shape`` says (a fixed length where it gives
    one, checked before anything inside is looked at) of numbers (no bools, strings)."""
    if not shape:
        return _is_number(value)
    if not isinstance(value, list) or shape[0] not in (None, len(value)):
        return False
    return all(_nested_numbers(v, shape[1:]) for v in value)


def _nested_integers(value: Any, shape: tuple[int | None, ...]) -> bool:
    """As :func:`_nested_numbers`, of integers."""
    if not shape:
        return isinstance(value, int) and not isinstance(value, bool)
    if not isinstance(value, list) or shape[0] not in (None, len(value)):
        return False
    return all(_nested_integers(v, shape[1:]) for v in value)


def _fits_int64(value: Any) -> bool:
    if isinstance(value, list):
        return all(_fits_int64(v) for v in value)
    return -(2**63) <= value < 2**63


def _fmt(shape: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
