"""Typed, checked access to one TOML table, naming the field in every error."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from truestep.cases.errors import CaseError

_MISSING = object()


class Fields:
    """A TOML table read field by field; every problem raises :class:`CaseError`.

    ``path`` is the dotted location of the table (``"scene.planes[0]"``); a field's
    name in errors is ``path.field``. Call :meth:`done` after reading to reject
    unknown (misspelt) fields.
    """

    def __init__(self, file: str, table: Any, path: str = "") -> None:
        if not isinstance(table, dict):
            raise CaseError(file, path or "<top>", f"expected a table, got {type(table).__name__}")
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

    def number(
        self,
        name: str,
        default: Any = _MISSING,
        *,
        positive: bool = False,
        nonnegative: bool = False,
        at_most: float | None = None,
    ) -> float:
        value = self.raw(name, default)
        if value is None:
            return value
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(name, f"expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise self.error(name, f"must be finite, got {value}")
        if positive and value <= 0:
            raise self.error(name, f"must be positive, got {value:g}")
        if nonnegative and value < 0:
            raise self.error(name, f"must not be negative, got {value:g}")
        if at_most is not None and value > at_most:
            raise self.error(name, f"must be at most {at_most:g}, got {value:g}")
        return value

    def integer(self, name: str, default: Any = _MISSING, *, minimum: int | None = None) -> int:
        value = self.raw(name, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(name, f"expected an integer, got {value!r}")
        if minimum is not None and value < minimum:
            raise self.error(name, f"must be at least {minimum}, got {value}")
        return value

    def boolean(self, name: str, default: Any = _MISSING) -> bool:
        value = self.raw(name, default)
        if not isinstance(value, bool):
            raise self.error(name, f"expected true or false, got {value!r}")
        return value

    def string(self, name: str, default: Any = _MISSING, *, choices: Any = None) -> str:
        value = self.raw(name, default)
        if value is None:
            return value
        if not isinstance(value, str):
            raise self.error(name, f"expected a string, got {value!r}")
        if choices is not None and value not in choices:
            raise self.error(name, f"{value!r} is not one of {', '.join(sorted(choices))}")
        return value

    def strings(self, name: str, default: Any = _MISSING) -> list[str]:
        value = self.raw(name, default)
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise self.error(name, f"expected a list of strings, got {value!r}")
        return list(value)

    def numbers(
        self, name: str, default: Any = _MISSING, *, positive: bool = False, nonempty: bool = True
    ) -> list[float]:
        value = self.raw(name, default)
        if not isinstance(value, list) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in value
        ):
            raise self.error(name, f"expected a list of numbers, got {value!r}")
        if nonempty and not value:
            raise self.error(name, "must not be empty")
        if positive and any(v <= 0 for v in value):
            raise self.error(name, f"every value must be positive, got {value!r}")
        return [float(v) for v in value]

    def array(self, name: str, default: Any = _MISSING, *, shape: tuple[int | None, ...]) -> np.ndarray:
        """An array of numbers with the given shape (``None`` for any length)."""
        value = self.raw(name, default)
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            reason = f"expected numbers of shape {_fmt(shape)}, got {value!r}"
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

    def sub(self, name: str, default: Any = _MISSING) -> Fields:
        return Fields(self.file, self.raw(name, default), self.where(name))

    def subs(self, name: str) -> list[Fields]:
        """An array of tables (``[[name]]``), possibly empty."""
        value = self.raw(name, [])
        if not isinstance(value, list):
            raise self.error(name, "expected an array of tables ([[...]])")
        return [Fields(self.file, v, f"{self.where(name)}[{i}]") for i, v in enumerate(value)]

    def done(self) -> None:
        """Reject fields that were never read: they are misspelt or unsupported."""
        unknown = sorted(set(self.table) - self._read)
        if unknown:
            raise self.error(unknown[0], "unknown field")


def _fmt(shape: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
