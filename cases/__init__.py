"""The scene library: case files, their loader and validation, and exact solutions.

The names below are imported when first used, so that a light module of the package
(``truestep.cases.limits``, ``truestep.cases.errors``) loads without the loader and the
exact solutions behind it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_EXPORTS: dict[str, str] = {
    "CASE_DIR": "truestep.cases.loader",
    "Case": "truestep.cases.case",
    "CaseError": "truestep.cases.errors",
    "Gate": "truestep.cases.case",
    "OdeSpec": "truestep.cases.case",
    "SelectionError": "truestep.cases.errors",
    "StabilitySpec": "truestep.cases.case",
    "case_files": "truestep.cases.loader",
    "library": "truestep.cases.loader",
    "load_case": "truestep.cases.loader",
    "load_cases": "truestep.cases.loader",
}

__all__ = [
    "CASE_DIR",
    "Case",
    "CaseError",
    "Gate",
    "OdeSpec",
    "SelectionError",
    "StabilitySpec",
    "case_files",
    "library",
    "load_case",
    "load_cases",
]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'truestep.cases' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)


if TYPE_CHECKING:
    from truestep.cases.case import Case, Gate, OdeSpec, StabilitySpec
    from truestep.cases.errors import CaseError, SelectionError
    from truestep.cases.loader import CASE_DIR, case_files, library, load_case, load_cases
