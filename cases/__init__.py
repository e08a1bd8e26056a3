"""The scene library: case files, their loader and validation, and exact solutions."""

from truestep.cases.case import Case, Gate, OdeSpec, StabilitySpec
from truestep.cases.errors import CaseError, SelectionError
from truestep.cases.loader import CASE_DIR, case_files, library, load_case, load_cases

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
