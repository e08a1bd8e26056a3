"""The typed form of a case file."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeAlias

import numpy as np

from truestep.reference_impl.features import Feature
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

    kind: ClassVar[str] = "ode"
    error_unit: ClassVar[str] = "state units"

    system: str
    y0: np.ndarray
    params: dict[str, float] = field(default_factory=dict)
    second_order: bool | None = None

    @property
    def dim(self) -> int:
        """The length of the state vector."""
        return len(self.y0)

    def features(self) -> set[str]:
        """Modelling features the ODE needs (``ode``, and ``second-order`` if it splits)."""
        return {Feature.ODE} | ({Feature.SECOND_ORDER} if self.is_second_order else set())

    @property
    def is_second_order(self) -> bool:
        if self.second_order is None:
            from truestep.cases.plugins import ode_system
            from truestep.reference_impl.system import SecondOrderSystem

            cls = ode_system(self.system)
            return cls is not None and issubclass(cls, SecondOrderSystem)
        return self.second_order


Scene: TypeAlias = ParticleModel | OdeSpec
"""What a case simulates: a particle scene or a plain ODE. Each kind carries its own
state shape (particles: positions and velocities (n, 3); an ODE: the state (dim,)), its
features (``features()``) and its ``kind`` name; consumers dispatch on the type once
(``match case.scene``) instead of testing a string."""


def ode_states(run: Any) -> np.ndarray:
    """The states (T, dim) of an ODE run or exact solution: its ``y``; from code written
    before ``y`` existed, ``x[:, 0, :]`` of its ``x`` (T, 1, dim), with a
    ``DeprecationWarning``."""
    y = getattr(run, "y", None)
    if y is not None:
        return np.asarray(y)
    warnings.warn(
        "an ODE's states belong in y (T, dim); x as (T, 1, dim) is deprecated "
        "(build runs with Trajectory.of_ode, exact solutions with Exact.of_ode)",
        DeprecationWarning,
        stacklevel=2,
    )
    return np.asarray(run.x)[:, 0, :]


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
    id : the gate's own id, if the file gives one (its verdicts' id is then ``case/id``)
    """

    kind: str
    engine: str
    method: str
    dt: float | None
    params: dict[str, Any]
    where: str
    file: str = ""
    id: str | None = None


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

    name : the file name without ``.toml``
    scene : the particle scene or the ODE (:data:`Scene`);  ``kind`` names which
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
    scene: Scene
    duration: float
    dts: list[float]
    quick_dts: list[float]
    tolerances: list[float]
    quick_tolerances: list[float]
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
    def kind(self) -> str:
        """``particles`` or ``ode``: the name of the scene's kind."""
        return self.scene.kind

    @property
    def model(self) -> ParticleModel | None:
        """The particle scene, or ``None`` for an ODE case (kept for plugins written
        before :attr:`scene`; new code matches on :attr:`scene`)."""
        return self.scene if isinstance(self.scene, ParticleModel) else None

    @property
    def ode(self) -> OdeSpec | None:
        """The ODE, or ``None`` for a particle case (kept for plugins written before
        :attr:`scene`; new code matches on :attr:`scene`)."""
        return self.scene if isinstance(self.scene, OdeSpec) else None

    @property
    def particles(self) -> ParticleModel:
        """The particle scene of a ``particles`` case (a ``TypeError`` for an ODE case):
        for code that runs only on particle scenes."""
        if not isinstance(self.scene, ParticleModel):
            raise TypeError(f"{self.name}: an ODE case has no particle scene")
        return self.scene

    @property
    def ode_spec(self) -> OdeSpec:
        """The ODE of an ``ode`` case (a ``TypeError`` for a particle case)."""
        if not isinstance(self.scene, OdeSpec):
            raise TypeError(f"{self.name}: a particle case has no ODE")
        return self.scene

    @property
    def features(self) -> set[str]:
        """Modelling features the scene needs (an ODE needs ``ode``)."""
        return self.scene.features()

    @property
    def bodies(self) -> int:
        """What a step moves, for per-body costs and speeds: the particles at the start
        (``n``), or 1 for an ODE (one state)."""
        return self.scene.n if isinstance(self.scene, ParticleModel) else 1

    def sweep(self, *, adaptive: bool, quick: bool) -> list[float]:
        """Steps (s) for fixed-step methods, or tolerances for adaptive ones."""
        if adaptive:
            return self.quick_tolerances if quick else self.tolerances
        return self.quick_dts if quick else self.dts

    def steps_for(self, dt: float) -> tuple[int, float]:
        """The number of steps for a nominal ``dt`` and the exact step that fills the run."""
        n = max(1, round(self.duration / dt))
        return n, self.duration / n
