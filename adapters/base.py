"""The Adapter protocol, the Trajectory every adapter returns, and the fixed-step loop.

:class:`FixedStepAdapter` carries what every engine that advances a particle scene by
fixed steps needs around the engine's own calls: the method and feature checks, the
recorded steps, blow-up checks every few steps, the timed region, and the Trajectory
with its energy, status and evaluation count. An engine supplies ``build``, ``advance``
and ``read``.
"""

from __future__ import annotations

import abc
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from truestep.cases.case import Case
from truestep.reference_impl.integrate import BLOWUP, CHECK_EVERY, record_indices
from truestep.reference_impl.particles import total_energy
from truestep.reference_impl.solvers import MethodFacts, get_solver

STATUSES = ("ok", "unstable", "solver-failed", "crashed", "timeout", "unsupported", "skipped")


@dataclass(frozen=True)
class EnergyExtremes:
    """The lowest and highest total energy of a run over every step it took (not only the
    recorded ones), and when: ``t_min``, ``e_min``, ``t_max``, ``e_max`` (s, J)."""

    t_min: float
    e_min: float
    t_max: float
    e_max: float

    @classmethod
    def of(cls, t: np.ndarray, energy: np.ndarray) -> EnergyExtremes | None:
        """The extremes of energies (J) at times ``t`` (s), ``None`` if none is finite."""
        e = np.asarray(energy, float)
        if not len(e) or not np.isfinite(e).any():
            return None
        lo, hi = int(np.nanargmin(e)), int(np.nanargmax(e))
        return cls(float(t[lo]), float(e[lo]), float(t[hi]), float(e[hi]))


@dataclass
class Trajectory:
    """A run, in the same shape and units whichever engine produced it.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Recorded times, s, starting with the initial state.
    x : ndarray, shape (T, n, 3)
        Positions read back from the engine, m. For an ODE scene, ``y[:, None, :]``: the
        layout ODE states had before :attr:`y` (deprecated there; build ODE runs with
        :meth:`of_ode`).
    v : ndarray, shape (T, n, 3), or None
        Velocities, m/s (``None`` for ODE scenes, whose state is in ``y``).
    energy : ndarray, shape (T,), or None
        Total energy, J, computed from the read-back state by the same function for every
        engine (:func:`truestep.reference_impl.particles.total_energy`), or ``None``.
    alive : ndarray of bool, shape (T, n), or None
        Which particles exist at each record (scenes with emitters).
    status : str
        ``ok``; ``unstable`` (non-finite or runaway state, at ``t_fail``);
        ``solver-failed`` (a step's equations had no solution the method found: an
        implicit method's Newton iteration, an adaptive step that underflows; never a
        blow-up, at ``t_fail``, the solver's words in ``message``); ``crashed``;
        ``timeout``.
    t_fail : float or None
        Time at which a run became unstable, s.
    nfev : int
        Derivative (force) evaluations: counted where the engine exposes them, else its
        evaluations per step times the steps taken.
    steps : int
        Steps taken.
    wall_s : float
        Seconds spent stepping (scene building excluded).
    message : str
        What went wrong, or notes the engine wants in the table.
    path : str
        Which code path of the engine ran, where it has several (the reference:
        ``compiled`` or ``numpy``), for the table's ``path`` column.
    extremes : EnergyExtremes or None
        The lowest and highest energy over every step, for a run watched at every step
        (``simulate(..., monitor=True)``); ``None`` when only the records were seen.
    step_t, step_energy : ndarray, shape (S,), or None
        Times (s) and total energies (J) at every step of a run watched at every step,
        where the records keep fewer (the stability verdicts read these).
    y : ndarray, shape (T, dim), or None
        The state of an ODE scene at each record (``None`` for particle scenes).
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray | None
    energy: np.ndarray | None
    status: str = "ok"
    t_fail: float | None = None
    nfev: int = 0
    steps: int = 0
    wall_s: float = float("nan")
    message: str = ""
    alive: np.ndarray | None = None
    path: str = ""
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    extremes: EnergyExtremes | None = None
    step_t: np.ndarray | None = None
    step_energy: np.ndarray | None = None
    y: np.ndarray | None = None

    @classmethod
    def of_ode(
        cls, t: np.ndarray, y: np.ndarray, energy: np.ndarray | None = None, **fields: Any
    ) -> Trajectory:
        """The run of an ODE scene: states ``y`` (T, dim) at times ``t`` (T,) s, energy
        (T,) or ``None``; ``fields`` are the other attributes (``status``, ``nfev`` ...)."""
        y = np.asarray(y)
        return cls(t=t, x=y[:, None, :], v=None, energy=energy, y=y, **fields)

    def watched(self) -> tuple[np.ndarray, np.ndarray | None]:
        """Times and energies at the finest the run was seen: every step where it was
        watched at every step, else its records."""
        if self.step_energy is not None and self.step_t is not None:
            return self.step_t, self.step_energy
        return self.t, self.energy


@runtime_checkable
class Adapter(Protocol):
    """One engine behind the harness.

    An adapter must:

    1. have a ``name`` (the engine's name in the tables: ``reference``, ``scipy``,
       ``pymunk``, ``pybullet``, ``mujoco``, or a user engine's own, registered in the
       entry-point group ``truestep.adapters``) and ``methods``, the names of the
       integrators it offers, with ``adaptive_methods`` the subset whose ``dt`` is a
       tolerance;
    2. declare ``capabilities``, the features of :meth:`ParticleModel.features` (and
       ``ode``, ``second-order``) it can model; :meth:`missing` names what a case needs
       beyond them, and may refine that per method;
    3. in :meth:`simulate`, build the scene outside the timed region, step it for
       ``case.duration`` seconds with step ``dt`` (or tolerance ``dt`` for an adaptive
       method), read the engine's own state back at every recorded step, and return a
       :class:`Trajectory` whose ``wall_s`` covers the stepping only;
    4. report a blow-up as status ``unstable`` with ``t_fail``, never raise for it;
    5. import its engine only inside its own module;
    6. be constructible with no arguments (the harness makes one per run);
    7. optionally, ``duplicate(case, method)``: the reason a method would compute bit for
       bit what another of its methods computes on ``case`` (the harness then skips it
       with that reason), or ``None``;
    8. optionally, declare the facts of its methods (order, evaluations per step,
       symplectic, stability data: :class:`~truestep.reference_impl.solvers.MethodFacts`),
       which the harness uses for declared-order gates, exact stability limits and
       ``nfev``: ``method_facts``, a mapping from a method to its ``MethodFacts`` or to
       the name of the reference method whose facts it shares, every one of them
       (``"verlet"``, ``"symplectic-euler"``, ``"rk4"`` ...;
       ``MethodFacts.like("verlet", velocity_order=2)`` where some differ). The older
       ``schemes`` mapping is still read, with a ``DeprecationWarning`` (:func:`facts_of`);
    9. optionally, accept ``simulate(case, method, dt, monitor=True)``: the run a row is
       measured from (untimed), watched at every step, its ``Trajectory.extremes`` the
       lowest and highest energy over every step; the harness then times plain runs and
       checks they end in the same state. An adapter whose watched run adds no more than
       a copy of the state a step to the same stepping, inside its timed region, may say
       so (``light_watch = True``, or the names of the methods it holds for): a long row
       whose steps take a millisecond or more (``watched_step_s``, s, one number or one
       for each method, where the adapter says less; 0 says the watched run is the plain
       run, and a long one is timed from it however it ended) is then timed from its
       watched run, not stepped again
       (:func:`truestep.execution.timing.timed_from_watched`);
    10. optionally, ``peers``: for a method, the reference method whose scheme it says it
        computes; the report sets their errors at the same steps side by side
        (:mod:`truestep.measures.peers`), and ``unsupported_notes``: for a feature it
        cannot model, why (the ``unsupported`` row's message);
    11. optionally, ``skip(case, method) -> str | None``: why it leaves a case it can
        model unrun (a bound on the work it takes on, stated), a ``skipped`` row with
        that message; and ``precision``: ``"float32"`` for an engine whose state is
        single precision, whose order fits then stop at float32's round-off
        (:func:`truestep.measures.metrics.round_off_floor`);
    12. optionally, ``same_steps(case, method) -> (other, why) | None``: another of its
        methods whose steps ``method`` repeats bit for bit on ``case``, and why. Both
        stay rows of the sweep; the stability search is made once, for ``other``, and
        ``method``'s row carries its result and says so;
    13. optionally, ``bounce_methods``: the methods the restitution sweep drops a ball
        with (default: every fixed-step method), and ``warm(cases, *, say) -> int``, a
        static method that ``truestep compile`` calls to build what the engine compiles
        on first use (kernels) into its own cache, returning how many scenes it built.

    :class:`FixedStepAdapter` does 2 to 4 and 9 for an engine that steps a particle scene.
    """

    name: str
    methods: tuple[str, ...]
    adaptive_methods: tuple[str, ...]
    capabilities: frozenset[str]

    def missing(self, case: Case, method: str) -> set[str]:
        """Features ``case`` needs that this adapter cannot model with ``method``."""
        ...

    def simulate(self, case: Case, method: str, dt: float) -> Trajectory:
        """Run ``case`` with ``method`` at step (or tolerance) ``dt``."""
        ...


FactsSpec = MethodFacts | str
"""A method's facts as an adapter declares them: a record, or the name of the reference
method whose facts it shares."""


def resolve_facts(spec: FactsSpec | None) -> MethodFacts | None:
    """A declared :data:`FactsSpec` as a record (a name is a reference method's)."""
    if spec is None or isinstance(spec, MethodFacts):
        return spec
    return get_solver(spec).facts


def duplicate_of(adapter, case: Case, method: str) -> str | None:
    """Why ``method`` would repeat another method of the adapter bit for bit, or ``None``."""
    duplicate = getattr(adapter, "duplicate", None)
    return duplicate(case, method) if duplicate is not None else None


def facts_of(adapter: Any, method: str) -> MethodFacts | None:
    """The declared facts of an adapter's method, or ``None`` if it declares none.

    Read from the adapter's ``method_facts`` (a record or a reference method's name: every
    fact of that method). An adapter written before it may still name the method in
    ``schemes``: read the same, with a ``DeprecationWarning`` that says so, since a name
    there copies every fact (the order with velocity-dependent forces too), not only the
    stability interval it was often written for. A name that is no reference method
    raises ``KeyError`` naming the adapter, the attribute and the method.
    """
    name = getattr(adapter, "name", type(adapter).__name__)
    for attribute in ("method_facts", "schemes"):
        declared = getattr(adapter, attribute, None) or {}
        if method in declared:
            if attribute == "schemes":
                warnings.warn(
                    f"{name}: schemes[{method!r}] = {declared[method]!r} is deprecated: it copies every "
                    "fact of that reference method (order, order with velocity-dependent forces, "
                    "evaluations, symplectic, stability); write method_facts = "
                    f"{{{method!r}: {declared[method]!r}}}, or MethodFacts.like({declared[method]!r}, ...) "
                    "with the facts where yours differ",
                    DeprecationWarning,
                    stacklevel=2,
                )
            try:
                return resolve_facts(declared[method])
            except KeyError as err:
                raise KeyError(f"{name}: {attribute}[{method!r}]: {err.args[0]}") from None
    return None


COPY_HIDDEN_STEP_S = 2e-4
"""The shortest step (s) in which a watch that keeps the state after each step costs 1% or
less: the copy takes 0.3 to 2.8 microseconds a step on the reference's numpy path (one
body to the stiff cloth's) and 0.8 to 1.9 in Drake's ``AdvanceTo`` loop
(``benchmarks/light_watch.py``, 2026-12-07). An adapter's ``watched_step_s`` (Adapter
protocol item 9) may say it."""

MONITOR_BYTES = 512 * 2**20
"""The most memory a run watched at every step may take for its states (positions and
velocities, float64)."""


def unwatched_note(size: int) -> str:
    """The note of a run too large to record at every step (``size`` bytes of states)."""
    return (
        f"watched at its records only: its every step would take {size / 2**20:.0f} MiB "
        f"(over {MONITOR_BYTES / 2**20:.0f} MiB)"
    )


def thin_records(traj: Trajectory, n_steps: int, max_records: int) -> Trajectory:
    """A run recorded at every step cut back to the records a run of ``max_records`` keeps
    (:func:`~truestep.reference_impl.integrate.record_indices`), and its last state where
    it stopped early; its energy at every step is kept (``step_t``, ``step_energy``), and
    its extremes."""
    if traj.energy is not None:
        traj.step_t, traj.step_energy = traj.t.copy(), traj.energy.copy()
        traj.extremes = EnergyExtremes.of(traj.t, traj.energy)
    keep = record_indices(n_steps, max_records)
    keep = keep[keep < len(traj.t)]
    if keep[-1] != len(traj.t) - 1:
        keep = np.append(keep, len(traj.t) - 1)
    for name in ("t", "x", "v", "y", "energy", "alive"):
        value = getattr(traj, name)
        if value is not None:
            setattr(traj, name, value[keep])
    return traj


def particle_trajectory(case: Case, t: np.ndarray, x: np.ndarray, v: np.ndarray, **fields: Any) -> Trajectory:
    """The Trajectory of a particle scene's records (``t`` (T,) s, ``x``, ``v`` (T, n, 3) m
    and m/s) with its energy (:func:`~truestep.reference_impl.particles.total_energy`, NaN
    where the state is not finite) and ``fields`` (status, counts, wall time, message...)."""
    with np.errstate(all="ignore"):
        energy = total_energy(case.particles, x, v)
    return Trajectory(t=t, x=x, v=v, energy=energy, **fields)


def finite_until(x: np.ndarray, t: np.ndarray, limit: float = BLOWUP) -> tuple[str, float | None]:
    """Status of recorded states ``x`` (T, ...): ``ok`` or ``unstable`` at the first bad time."""
    flat = np.abs(x.reshape(len(x), -1))
    bad = ~np.all(np.isfinite(flat), axis=1) | (
        np.nanmax(np.where(np.isfinite(flat), flat, np.inf), axis=1, initial=0.0) > limit
    )
    if not np.any(bad):
        return "ok", None
    return "unstable", float(t[int(np.argmax(bad))])


def sane(x: np.ndarray, v: np.ndarray) -> bool:
    """Whether positions and velocities (n, 3) are finite and below :data:`BLOWUP`.

    The largest magnitude is NaN if any number is, and NaN compares false.
    """
    with np.errstate(invalid="ignore"):
        return bool(np.abs(x).max(initial=0.0) < BLOWUP and np.abs(v).max(initial=0.0) < BLOWUP)


@dataclass
class Recording:
    """The recorded states of a fixed-step run, as :meth:`FixedStepAdapter.step_and_record`
    returns them.

    t : ndarray, shape (T,), s;  x, v : ndarray, shape (T, n, 3), m and m/s
    steps : steps taken;  wall_s : seconds spent stepping and reading back
    stopped : why stepping stopped early (a blow-up check, an engine's warning), or ""
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    steps: int
    wall_s: float
    stopped: str = ""
    extremes: EnergyExtremes | None = None


def _stepped_by_its_own_loop(self: Any, scene: Any, k: int, steps: int, h: float) -> None:
    """:meth:`FixedStepAdapter.advance` of an adapter that steps in its own
    :meth:`~FixedStepAdapter.step_and_record`."""
    raise NotImplementedError(f"{type(self).__name__} steps in its own step_and_record, not by advance()")


class FixedStepAdapter(abc.ABC):
    """Base class of an adapter whose engine advances a particle scene by fixed steps.

    A subclass declares ``name``, ``methods`` and ``capabilities`` (see :class:`Adapter`)
    and implements

    1. :meth:`build` ``(case, method, h) -> scene``: the engine's scene for
       ``case.model`` (a :class:`~truestep.reference_impl.model.ParticleModel`), ready to
       take steps of ``h`` seconds; not timed;
    2. :meth:`advance` ``(scene, k, steps, h)``: take ``steps`` steps of ``h`` seconds,
       the first one starting at time ``k h`` (timed); an adapter that steps in a loop of
       its own instead (it overrides :meth:`step_and_record`, as MuJoCo's rollout does)
       needs none, and nothing calls it;
    3. :meth:`read` ``(scene) -> (x, v)``: positions and velocities now, each shape
       ``(n, 3)``, m and m/s, in the model's particle order (may be views: they are
       copied when kept).

    and, if it needs to, :meth:`close` (free the scene), :meth:`notes` (a message for
    the table), :attr:`method_facts` (each method's facts, see :class:`Adapter`; its
    evaluations per step make ``nfev``), :attr:`evaluations_per_step` (force
    evaluations per step where the facts do not say) and :meth:`snapshot` /
    :meth:`unpack` (keep a cheap form of a state in the timed loop and turn the kept
    states into arrays after it).

    :meth:`simulate` then checks the method and the case's features, builds the scene
    outside the timed region, steps it to ``case.duration`` reading the state back at
    the steps :func:`~truestep.reference_impl.integrate.record_indices` picks and
    checking for a blow-up (non-finite or beyond ``BLOWUP``) at least every
    :attr:`check_every` steps, and returns the :class:`Trajectory`: energy by the same
    function for every engine, ``nfev`` = steps x evaluations per step, status
    ``unstable`` with ``t_fail`` at the first bad record.
    """

    name: ClassVar[str]
    methods: ClassVar[tuple[str, ...]]
    adaptive_methods: ClassVar[tuple[str, ...]] = ()
    capabilities: ClassVar[frozenset[str]]
    method_facts: ClassVar[Mapping[str, FactsSpec]] = MappingProxyType({})
    """Each method's :class:`MethodFacts`, or the reference method whose facts it shares."""
    evaluations_per_step: ClassVar[Mapping[str, int]] = MappingProxyType({})
    """Force evaluations one step of a method makes, for a method whose facts do not
    say (:meth:`evaluations`)."""
    check_every: ClassVar[int] = CHECK_EVERY
    """Steps between blow-up checks: a blown-up run stops within this many steps (the
    reference's :data:`~truestep.reference_impl.integrate.CHECK_EVERY`)."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """A subclass with a stepping loop of its own (its own :meth:`step_and_record`)
        and no :meth:`advance`: :meth:`advance` is not abstract for it (nothing calls it)."""
        super().__init_subclass__(**kwargs)
        own_loop = cls.step_and_record is not FixedStepAdapter.step_and_record
        if own_loop and getattr(cls.advance, "__isabstractmethod__", False):
            cls.advance = _stepped_by_its_own_loop  # type: ignore[method-assign]  # set before ABCMeta reads it

    def missing(self, case: Case, method: str) -> set[str]:
        """Features of ``case`` beyond :attr:`capabilities`."""
        return set(case.features) - self.capabilities

    def evaluations_for(self, case: Case, method: str) -> int:
        """Force evaluations per step of ``method`` on ``case``'s scene, for ``nfev``:
        :meth:`evaluations` unless the adapter overrides this (a method whose count depends
        on the scene: sub-steps per contact, an iteration count set per scene ...)."""
        return self.evaluations(method)

    def evaluations(self, method: str) -> int:
        """Force evaluations per step of ``method``: :attr:`evaluations_per_step` where it
        names the method, else the method's declared facts (:func:`facts_of`), else 1."""
        if method in self.evaluations_per_step:
            return int(self.evaluations_per_step[method])
        facts = facts_of(self, method)
        if facts is not None and facts.evaluations_per_step is not None:
            return facts.evaluations_per_step
        return 1

    def require(self, case: Case, method: str) -> None:
        """Raise ``ValueError`` for a method this adapter lacks or a case it cannot model."""
        if method not in self.methods:
            raise ValueError(f"{self.name}: unknown method {method!r}; known: {', '.join(self.methods)}")
        lacking = self.missing(case, method)
        if lacking:
            raise ValueError(f"{self.name} cannot model {case.name}: needs {', '.join(sorted(lacking))}")

    @abc.abstractmethod
    def build(self, case: Case, method: str, h: float) -> Any:
        """The engine's scene for ``case``, ready for steps of ``h`` s (not timed)."""

    @abc.abstractmethod
    def advance(self, scene: Any, k: int, steps: int, h: float) -> None:
        """Take ``steps`` steps of ``h`` s, the first from time ``k h`` s."""

    @abc.abstractmethod
    def read(self, scene: Any) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities now, (n, 3) each, m and m/s."""

    def close(self, scene: Any) -> None:  # noqa: B027 (optional hook: nothing to free by default)
        """Release what :meth:`build` made (runs after stepping, also after an error)."""

    def notes(self, case: Case, method: str, scene: Any) -> list[str]:
        """Notes for the row's ``message`` (before :meth:`close`)."""
        return []

    def snapshot(self, scene: Any) -> Any:
        """The state now, in any form :meth:`unpack` understands (default: copied arrays;
        a complex state is refused, not cut to its real part)."""
        x, v = self.read(scene)
        return _real(x, "positions"), _real(v, "velocities")

    def unpack(self, scene: Any, snaps: list[Any]) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities (T, n, 3) from ``T`` snapshots."""
        return np.stack([s[0] for s in snaps]), np.stack([s[1] for s in snaps])

    def is_sane(self, scene: Any) -> bool:
        """Whether the state now is finite and below ``BLOWUP`` (the blow-up check)."""
        return sane(*self.read(scene))

    def step_and_record(self, case: Case, scene: Any, n_steps: int, h: float) -> Recording:
        """Step ``n_steps`` steps of ``h`` s, recording and checking; time the stepping.

        The engine is advanced from one stop to the next, a stop being a recorded step or
        a blow-up check (every :attr:`check_every` steps): one :meth:`advance` call per
        stop, so an engine that can take many steps in one call pays no per-step Python.
        A failed check records the state there and ends the run.
        """
        marks = record_indices(n_steps, case.max_records)
        checks = np.arange(self.check_every, n_steps + 1, self.check_every)
        stops = np.union1d(marks, np.append(checks, n_steps))[1:].tolist()
        record_at = np.zeros(n_steps + 1, dtype=bool)
        record_at[marks] = True
        check_at = np.zeros(n_steps + 1, dtype=bool)
        check_at[checks] = True
        check_at[n_steps] = True
        record_list, check_list = record_at.tolist(), check_at.tolist()
        snaps = [self.snapshot(scene)]
        advance, snapshot, is_sane, keep = self.advance, self.snapshot, self.is_sane, snaps.append
        k, stopped, extra = 0, "", []
        start = time.perf_counter()
        for stop in stops:
            advance(scene, k, stop - k, h)
            k = stop
            if record_list[k]:
                keep(snapshot(scene))
            if check_list[k] and not is_sane(scene):
                if not record_list[k]:
                    keep(snapshot(scene))
                    extra.append(k)
                stopped = "non-finite or runaway state read back"
                break
        wall = time.perf_counter() - start
        recorded = np.concatenate([marks[: len(snaps) - len(extra)], extra]).astype(int)
        x, v = self.unpack(scene, snaps)
        return Recording(recorded * h, x, v, k, wall, stopped)

    def simulate(self, case: Case, method: str, dt: float, *, monitor: bool = False) -> Trajectory:
        """Run ``case`` with ``method`` at step ``dt`` (s); see the class docstring.

        ``monitor``: for the run a row is measured from (timed runs leave it off): record
        every step (the engine's own :meth:`step_and_record`), find the energy's lowest
        and highest over all of them (``extremes``) and the first bad state, then keep the
        records a plain run keeps. A run whose every state would exceed
        :data:`MONITOR_BYTES` is watched at its records only."""
        self.require(case, method)
        n_steps, h = case.steps_for(dt)
        every = monitor and n_steps > case.max_records and (n_steps * case.particles.n * 48 <= MONITOR_BYTES)
        if monitor and n_steps > case.max_records and not every:
            notes_first = [unwatched_note(n_steps * case.particles.n * 48)]
        else:
            notes_first = []
        run_case = replace(case, max_records=n_steps) if every else case
        scene = self.build(case, method, h)
        try:
            rec = self.step_and_record(run_case, scene, n_steps, h)
            notes = self.notes(case, method, scene)
        finally:
            self.close(scene)
        traj = self.trajectory(case, method, rec, notes_first + notes)
        if every:
            return thin_records(traj, n_steps, case.max_records)
        if monitor and traj.energy is not None:
            traj.extremes = EnergyExtremes.of(traj.t, traj.energy)
        return traj

    def trajectory(self, case: Case, method: str, rec: Recording, notes: list[str]) -> Trajectory:
        """The Trajectory of a recording: status, energy, evaluations."""
        status, t_fail = finite_until(np.concatenate([rec.x, rec.v], axis=1), rec.t)
        if rec.stopped and status == "ok":
            status, t_fail = "unstable", float(rec.t[-1])
        if status != "ok" and rec.stopped:
            notes = [rec.stopped, *notes]
        return particle_trajectory(
            case,
            rec.t,
            rec.x,
            rec.v,
            status=status,
            t_fail=t_fail,
            nfev=rec.steps * self.evaluations_for(case, method),
            steps=rec.steps,
            wall_s=rec.wall_s,
            message="; ".join(notes),
            extremes=rec.extremes,
        )


def _real(values: Any, what: str) -> np.ndarray:
    """``values`` as a float64 copy; ``TypeError`` for complex numbers, whose imaginary
    part a cast would drop without a word (the row is then ``crashed``, saying so)."""
    array = np.asarray(values)
    if array.dtype.kind == "c":
        raise TypeError(f"read() returned complex {what} ({array.dtype}): a state is real numbers")
    return np.array(array, dtype=float)
