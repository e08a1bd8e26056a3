"""The typed form of a case file."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from truestep.reference_impl.model import ParticleModel

FAMILIES: dict[str, str] = {
    "orbit": "orbits and plain ODEs",
    "oscillator": "oscillators",
    "chain": "chains and ropes",
    "cloth": "cloth and meshes",
    "contact": "contact",
    "particles": "particles",
}
"""The kinds of scene the report compares engines on: ``family`` -> what it covers."""


@dataclass
class OdeSpec:
    """A plain ODE scene: a named system of :mod:`truestep.reference_impl.odes` and its start.

    system : ``"circle-field"``, ``"kepler"``, ``"arenstorf"`` or an installed system's
    name (entry-point group ``truestep.systems``)
    y0 : ndarray, shape (dim,)  initial state
    params : keyword parameters of the system (``mu`` ...)
    second_order : whether the system splits its state into positions and velocities
    (``None``: as its class says)
    """

    system: str
    y0: np.ndarray
    params: dict[str, float] = field(default_factory=dict)
    second_order: bool | None = None

    @property
    def is_second_order(self) -> bool:
        if self.second_order is None:
            from truestep.cases.plugins import ode_system
            from truestep.reference_impl.system import SecondOrderSystem

            cls = ode_system(self.system)
            return cls is not None and issubclass(cls, SecondOrderSystem)
        return self.second_order


@dataclass
class Gate:
    """One accuracy gate of a case, in the units of the quantity it checks.

    kind : ``order`` (fitted convergence order within ``tol`` of ``expect``), ``error``,
    ``energy_drift`` (at most ``max``), ``status`` (equals ``expect``), ``property``
    (a named metric between ``min`` and ``max``), ``stability-limit`` (measured within
    ``rel_tol`` of the exact limit, or at least ``min``), ``restitution`` (within
    ``tol`` of the set value), ``no-worse-than`` (at most ``factor`` times another run's
    quantity) or ``speedup`` (see :func:`truestep.cases.loader.read_gate`).
    engine, method : the rows the gate reads (``*``: every engine that ran, every method);
    dt : the step (or tolerance) it reads, if one
    params : the kind's numbers (``expect``, ``tol``, ``max``, ``min``, ``name`` ...)
    where : ``gates[i]``, for messages;  file : the case file or gates file it is in
    """

    kind: str
    engine: str
    method: str
    dt: float | None
    params: dict[str, Any]
    where: str
    file: str = ""


@dataclass
class StabilitySpec:
    """A stability search: bisection on dt over a fixed horizon.

    horizon : s;  dt_lo, dt_hi : bracket, s;  max_runs : simulations per search;
    rel_tol : relative width at which bisection stops;
    quick : whether ``--quick`` runs search this case too (coarser, see truestep.execution.analyses);
    min_steps : every run of the search takes at least this many steps;
    budget_s : a safety valve, s: a search still running after this long is a ``timeout``
    row with no limit (searches are bounded by ``max_runs`` and ``rel_tol``, never by time,
    so that every machine finds the same limit).
    """

    horizon: float
    dt_lo: float
    dt_hi: float
    max_runs: int = 30
    rel_tol: float = 1e-3
    quick: bool = False
    min_steps: int = 5000  # truestep.measures.stability.MIN_STEPS
    budget_s: float = 300.0


@dataclass
class Case:
    """A scene, how to run it, what it is measured against and its gates.

    name : the file name without ``.toml``;  kind : ``ode`` or ``particles``
    duration : simulated time, s
    dts, quick_dts : fixed-step sweep (s) for full and ``--quick`` runs
    tolerances, quick_tolerances : rtol = atol sweep for adaptive methods
    exact : name of the exact solution in :mod:`truestep.cases.exact` (``None``: property checks only)
    error_norm : ``final`` (positions at the end) or ``max`` (worst over the run)
    properties : names of extra metrics (:mod:`truestep.measures.properties`) to compute per run
    skip : ``(engine, method, reason)`` pairs that are not run (rows say why)
    in_quick : whether ``--quick`` runs this case at all (long cases say no)
    escape_energy : J, an energy the motion the case describes never reaches (a bound
    orbit's: 0); a run that reaches it has escaped and is unstable (``[reference]``)
    family : the kind of scene the report groups it under (:data:`FAMILIES`, or ``other``)
    """

    name: str
    file: str
    title: str
    description: str
    kind: str
    duration: float
    dts: list[float]
    quick_dts: list[float]
    tolerances: list[float]
    quick_tolerances: list[float]
    model: ParticleModel | None = None
    ode: OdeSpec | None = None
    exact: str | None = None
    exact_params: dict[str, Any] = field(default_factory=dict)
    error_norm: str = "max"
    error_scale: float = 1.0
    conservative: bool = False
    max_records: int = 2000
    gates: list[Gate] = field(default_factory=list)
    stability: StabilitySpec | None = None
    properties: list[str] = field(default_factory=list)
    skip: list[tuple[str, str, str]] = field(default_factory=list)
    hard: str | None = None
    tags: list[str] = field(default_factory=list)
    family: str = "other"
    timeout_s: float = 120.0
    in_quick: bool = True
    escape_energy: float | None = None

    @property
    def particles(self) -> ParticleModel:
        """The particle scene of a ``particles`` case (a ``TypeError`` for an ODE case): the
        typed view of :attr:`model` for code that runs only on particle scenes."""
        if self.model is None:
            raise TypeError(f"{self.name}: an ODE case has no particle scene")
        return self.model

    @property
    def ode_spec(self) -> OdeSpec:
        """The ODE of an ``ode`` case (a ``TypeError`` for a particle case): the typed view
        of :attr:`ode`."""
        if self.ode is None:
            raise TypeError(f"{self.name}: a particle case has no ODE")
        return self.ode

    @property
    def features(self) -> set[str]:
        """Modelling features the scene needs (an ODE needs ``ode``)."""
        if self.model is not None:
            return self.model.features()
        return {"ode"} | ({"second-order"} if self.ode and self.ode.is_second_order else set())

    def sweep(self, *, adaptive: bool, quick: bool) -> list[float]:
        """Steps (s) for fixed-step methods, or tolerances for adaptive ones."""
        if adaptive:
            return self.quick_tolerances if quick else self.tolerances
        return self.quick_dts if quick else self.dts

    def steps_for(self, dt: float) -> tuple[int, float]:
        """The number of steps for a nominal ``dt`` and the exact step that fills the run."""
        n = max(1, round(self.duration / dt))
        return n, self.duration / n
