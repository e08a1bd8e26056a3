"""The reference solvers, registered under the method names of DESIGN.md; each carries
its :class:`MethodFacts` as ``facts``."""

from __future__ import annotations

from truestep.reference_impl.solvers import facts
from truestep.reference_impl.solvers.base import Solver
from truestep.reference_impl.solvers.explicit_rk import (
    RK4,
    DormandPrince54,
    Euler,
    ExplicitRungeKutta,
    Heun,
    Midpoint,
    rk_stages,
    stability_polynomial,
    tableau_stability,
)
from truestep.reference_impl.solvers.facts import MethodFacts, Stability, StepMatrix
from truestep.reference_impl.solvers.implicit import ImplicitEuler
from truestep.reference_impl.solvers.splitting import LectureUpdate, SymplecticEuler, VelocityVerlet

METHODS: dict[str, type[Solver]] = {
    cls.name: cls
    for cls in (
        Euler,
        Midpoint,
        Heun,
        RK4,
        DormandPrince54,
        SymplecticEuler,
        VelocityVerlet,
        ImplicitEuler,
        LectureUpdate,
    )
}


facts.NAMED.update({name: cls.facts for name, cls in METHODS.items()})


def get_solver(method: str | type[Solver]) -> type[Solver]:
    """Return the solver class for a method name (or the class itself)."""
    if isinstance(method, type) and issubclass(method, Solver):
        return method
    try:
        return METHODS[method]
    except KeyError:
        known = ", ".join(METHODS)
        raise KeyError(f"unknown method {method!r}; known: {known}") from None


__all__ = [
    "METHODS",
    "RK4",
    "DormandPrince54",
    "Euler",
    "ExplicitRungeKutta",
    "Heun",
    "ImplicitEuler",
    "LectureUpdate",
    "MethodFacts",
    "Midpoint",
    "Solver",
    "Stability",
    "StepMatrix",
    "SymplecticEuler",
    "VelocityVerlet",
    "get_solver",
    "rk_stages",
    "stability_polynomial",
    "tableau_stability",
]
