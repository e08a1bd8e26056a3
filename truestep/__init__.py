"""truestep: a verification and benchmark harness for physically based animation.

The public API (everything else is internal and may change)::

    import truestep

    truestep.__version__
    truestep.load_case(path), truestep.load_cases("names,globs,files,dirs")
    truestep.run(cases, engines, quick=...)        # -> truestep.Tables of pandas tables
    truestep.run_matrix(cases, engines)            # -> the results table only
    truestep.check(tables, gates="gates.toml")     # -> one row per gate verdict
    truestep.compare("baseline-dir", tables)       # -> what got worse or better
    truestep.gate("reports/results.csv", baseline="dir")  # -> truestep gate's report
    # what truestep list, baseline, history, figures, env, compile and bench do:
    truestep.engines(), truestep.save_baseline(results, dir), truestep.history_add(results),
    truestep.history(quantity, case, engine, method), truestep.benchmark_json(results),
    truestep.lecture_figures(out), truestep.environment(), truestep.compile_ahead(),
    truestep.bench(engines, sizes=..., out=...)

    class MyEngine(truestep.FixedStepAdapter): ...   # see README, "Writing an adapter"

Names are imported on first use, so ``import truestep`` (and importing
``truestep.reference_impl`` on its own) stays light, and it changes nothing in the process
that imports it: no environment variable, no thread count (:mod:`truestep.numerics`).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.2.0"

_EXPORTS: dict[str, str] = {
    "Adapter": "truestep.adapters.base",
    "FixedStepAdapter": "truestep.adapters.base",
    "Recording": "truestep.adapters.base",
    "Trajectory": "truestep.adapters.base",
    "get_adapter": "truestep.adapters",
    "build_system": "truestep.adapters.reference",
    "Case": "truestep.cases.case",
    "CaseError": "truestep.cases.errors",
    "SelectionError": "truestep.cases.errors",
    "Gate": "truestep.cases.case",
    "OdeSpec": "truestep.cases.case",
    "load_case": "truestep.cases.loader",
    "load_cases": "truestep.cases.loader",
    "Exact": "truestep.cases.exact",
    "exact_solution": "truestep.cases.exact",
    "Feature": "truestep.reference_impl.features",
    "ParticleModel": "truestep.reference_impl.model",
    "MethodFacts": "truestep.reference_impl.solvers.facts",
    "Stability": "truestep.reference_impl.solvers.facts",
    "System": "truestep.reference_impl.system",
    "SecondOrderSystem": "truestep.reference_impl.system",
    "Tables": "truestep.api",
    "run": "truestep.api",
    "check": "truestep.api",
    "compare": "truestep.api",
    "gate": "truestep.api",
    "GateReport": "truestep.ci.gate_report",
    "GateRequest": "truestep.ci.gate_report",
    "GateInputError": "truestep.ci.gate_report",
    "select_engines": "truestep.api",
    "engines": "truestep.api",
    "EngineInfo": "truestep.api",
    "save_baseline": "truestep.api",
    "history_add": "truestep.api",
    "history": "truestep.api",
    "History": "truestep.api",
    "benchmark_json": "truestep.api",
    "lecture_figures": "truestep.api",
    "environment": "truestep.api",
    "compile_ahead": "truestep.api",
    "bench": "truestep.api",
    "check_report_folder": "truestep.api",
    "engines_for_run": "truestep.api",
    "interruptible": "truestep.api",
    "resumable": "truestep.api",
    "run_matrix": "truestep.execution.runner",
}

__all__ = [
    "Adapter",
    "Case",
    "CaseError",
    "EngineInfo",
    "Exact",
    "Feature",
    "FixedStepAdapter",
    "Gate",
    "GateInputError",
    "GateReport",
    "GateRequest",
    "History",
    "MethodFacts",
    "OdeSpec",
    "ParticleModel",
    "Recording",
    "SecondOrderSystem",
    "SelectionError",
    "Stability",
    "System",
    "Tables",
    "Trajectory",
    "__version__",
    "bench",
    "benchmark_json",
    "build_system",
    "check",
    "check_report_folder",
    "compare",
    "compile_ahead",
    "engines",
    "engines_for_run",
    "environment",
    "exact_solution",
    "gate",
    "get_adapter",
    "history",
    "history_add",
    "interruptible",
    "lecture_figures",
    "load_case",
    "load_cases",
    "resumable",
    "run",
    "run_matrix",
    "save_baseline",
    "select_engines",
]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'truestep' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)


if TYPE_CHECKING:
    from truestep.adapters import get_adapter
    from truestep.adapters.base import Adapter, FixedStepAdapter, Recording, Trajectory
    from truestep.adapters.reference import build_system
    from truestep.api import (
        Tables,
        check,
        check_report_folder,
        compare,
        engines_for_run,
        gate,
        interruptible,
        resumable,
        run,
        select_engines,
    )
    from truestep.cases.case import Case, Gate, OdeSpec
    from truestep.cases.errors import CaseError, SelectionError
    from truestep.cases.exact import Exact, exact_solution
    from truestep.cases.loader import load_case, load_cases
    from truestep.ci.gate_report import GateInputError, GateReport, GateRequest
    from truestep.execution.runner import run_matrix
    from truestep.reference_impl.features import Feature
    from truestep.reference_impl.model import ParticleModel
    from truestep.reference_impl.solvers.facts import MethodFacts, Stability
    from truestep.reference_impl.system import SecondOrderSystem, System
