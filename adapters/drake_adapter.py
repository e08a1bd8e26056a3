"""Drake's integrators behind the Adapter protocol (``pip install "truestep[drake]"``).

What runs
---------
Drake (``pydrake``) is a toolbox for model-based design; its ``systems.analysis``
module holds the widest set of fixed-step and error-controlled integrators of any
engine truestep runs. This adapter measures those integrators. The scene is a Drake
``LeafSystem`` whose continuous state is the case's flat state (a particle scene's
positions then velocities, (6 n,); an ODE's state, (dim,)) and whose time derivative
is the reference system's (:func:`truestep.adapters.reference.build_system`), as for
scipy: the comparison is of integrators alone, on the same forces. Where the system has
a compiled twin of its derivative (:meth:`~truestep.reference_impl.system.System.compiled_derivative`:
a particle scene without fields, the lecture's ODEs), Drake calls that: the same bits at
a fraction of the cost of the Python one, whose interpreted work dominated each evaluation
Drake calls back from C++. A second-order
scene declares its state as Drake's generalized positions ``q`` and velocities ``v``
(``q' = v``), which ``semi_explicit_euler`` needs; a first-order ODE is Drake's
"miscellaneous" state ``z``. Drake's ``MultibodyPlant`` is not used: its contact is
compliant (point or hydroelastic, Hunt-Crossley dissipation) with no coefficient of
restitution to set, and a derivative handed to an integrator has no collision events,
so scenes with planes, emitters or impulses are ``unsupported`` (the row says why).

Stepping
--------
A ``Simulator`` owns the context and the integrator, chosen by Drake's own scheme
names (``ResetIntegratorFromFlags``). Fixed-step methods run in fixed-step mode: one
``AdvanceTo((k + 1) h)`` per step from ``k h``, with the integrator's largest step a
hair over ``h`` (``h (1 + 1e-9)``) so that round-off in ``(k + 1) h - k h`` never
splits a step in two (Drake would take a second, tiny step); ``steps`` is Drake's own
count and a test checks it equals ``round(duration / dt)``. Error-controlled methods
take ``dt`` as Drake's target accuracy (``set_target_accuracy``) and run to the end
in one ``AdvanceTo``, choosing every step themselves; the monitor keeps each accepted
step, which are the run's records (thinned evenly to the case's ``max_records``, as for
scipy). ``nfev`` counts every call of the derivative, the finite
differences of an implicit method's Jacobian among them (Drake forms it by forward
differences of a Python system). A fixed-step implicit method's Newton iteration is
run to convergence (:data:`NEWTON_ACCURACY`, the reference's Newton tolerance), and
its step is never split (:data:`UNSPLIT`): the two defaults truestep changes. No
damping, clamp or step limit is added.

Blow-ups and failures
---------------------
A Simulator monitor sees the state after every step: a non-finite state or one beyond
:data:`~truestep.reference_impl.integrate.BLOWUP` ends the run ``unstable`` at that
time. A Drake exception (an implicit step whose Newton iteration fails, a step below
the smallest Drake allows) ends it ``solver-failed`` with Drake's words, unless the
state has already run away. An error-controlled run may make at most
:data:`MAX_EVALUATIONS` evaluations: a bound on work, never on wall time, so that a run that creeps is
``solver-failed`` on every machine at the same step.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator
from pydrake.systems.framework import BasicVector, EventStatus, LeafSystem

from truestep.adapters.base import (
    COPY_HIDDEN_STEP_S,
    EnergyExtremes,
    FactsSpec,
    Trajectory,
    finite_until,
    thin_records,
)
from truestep.adapters.reference import build_system, trajectory_of_states
from truestep.cases.case import Case
from truestep.reference_impl.features import Feature
from truestep.reference_impl.integrate import BLOWUP, record_indices
from truestep.reference_impl.precompile import DERIVATIVE, compile_all
from truestep.reference_impl.solvers.explicit_rk import tableau_stability
from truestep.reference_impl.solvers.facts import MethodFacts, Stability
from truestep.reference_impl.system import SecondOrderSystem, System

INF = float("inf")

FIXED: dict[str, str] = {
    "explicit_euler": "explicit_euler",
    "semi_explicit_euler": "semi_explicit_euler",
    "runge_kutta2": "runge_kutta2",
    "runge_kutta3": "runge_kutta3",
    "implicit_euler": "implicit_euler",
    "radau1": "radau1",
    "radau3": "radau3",
}
"""Fixed-step methods: the method's name in the tables -> Drake's scheme name."""

ERROR_CONTROLLED: dict[str, str] = {
    "runge_kutta5": "runge_kutta5",
    "bogacki_shampine3": "bogacki_shampine3",
    "radau3-ec": "radau3",
}
"""Error-controlled methods (``dt`` is the target accuracy) -> Drake's scheme name.
``radau3-ec`` is Drake's ``radau3`` with its error control on (``radau3`` is the same
integrator at fixed steps)."""

SCHEMES: dict[str, str] = {**FIXED, **ERROR_CONTROLLED}

IMPLICIT = frozenset({"implicit_euler", "radau1", "radau3"})
"""The fixed-step methods that solve an equation each step (Newton's method)."""

UNSPLIT = 1e-6
"""A fixed-step implicit method's smallest step is ``h (1 - UNSPLIT)``: Drake halves a
step whose Newton iteration fails, even in fixed-step mode (down to 1e-14 s by default),
which would make a row's ``dt`` a step it did not take; with this floor a failed Newton
iteration ends the run ``solver-failed``, as it ends the reference's implicit Euler."""

NEWTON_ACCURACY = 1e-10
"""The target accuracy truestep sets for a fixed-step implicit method. In fixed-step
mode it decides nothing but when Newton's iteration has converged; left at Drake's
default, ``implicit_euler`` stops its iteration early (on the harmonic oscillator, 50
steps of 10 ms end 2e-5 of the amplitude away from the converged steps), so the run
would measure an unconverged solve rather than the method."""

STRETCH = 1e-9
"""The integrator's largest step is ``h (1 + STRETCH)``: round-off in the distance to the
next step's end must not make Drake split a step."""

MAX_EVALUATIONS = 300_000
"""The most derivative evaluations an error-controlled run may make (a bound on work, the
same on every machine, not on wall time): a run that needs more ends ``solver-failed`` at
the step that passed it, saying so. scipy's costliest run
of the library makes 2e5; an error-controlled Drake method that cannot reach its target
accuracy would otherwise creep for minutes."""

_RK3 = tableau_stability(
    np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [-1.0, 2.0, 0.0]]), np.array([1 / 6, 2 / 3, 1 / 6]), 3
)
"""Every three-stage explicit method of order 3 has the stability polynomial
``1 + z + z^2/2 + z^3/6``: Kutta's tableau stands for Drake's."""

A_STABLE = Stability(imaginary=INF, real=INF, a_stable=True)

METHOD_FACTS: dict[str, FactsSpec] = {
    "explicit_euler": "euler",
    "semi_explicit_euler": "symplectic-euler",
    "runge_kutta2": "heun",
    "runge_kutta3": MethodFacts(order=3, evaluations_per_step=3, symplectic=False, stability=_RK3),
    "implicit_euler": MethodFacts(order=1, evaluations_per_step=None, symplectic=False, stability=A_STABLE),
    "radau1": MethodFacts.like("implicit-euler", evaluations_per_step=None),
    "radau3": MethodFacts(order=3, evaluations_per_step=None, symplectic=False, stability=A_STABLE),
    "runge_kutta5": MethodFacts(order=5, evaluations_per_step=6, symplectic=False),
    "bogacki_shampine3": MethodFacts(order=3, evaluations_per_step=3, symplectic=False),
    "radau3-ec": MethodFacts(order=3, evaluations_per_step=None, symplectic=False, stability=A_STABLE),
}
"""From Drake's documentation (``systems/analysis/*_integrator.h``): explicit Euler;
semi-explicit Euler, velocity first (``v' = v + h a(q, v)``, ``q' = q + h v'``: the
reference's ``symplectic-euler``); RK2 is the explicit trapezoid (Heun's method, the
reference's ``heun``); RK3 is a three-stage third-order method; ``implicit_euler`` and
``radau1`` are first order and ``radau3`` (two-stage Radau IIA) third order, all three
A-stable (L-stable), their evaluations those of their Newton iterations and Jacobians
(counted, never declared); RK5 is Cash-Karp's 5(4), Bogacki-Shampine 3(2). The tests
compare ``semi_explicit_euler`` and ``runge_kutta2`` with the reference's methods of
those names step for step."""

PEERS: dict[str, str] = {
    "explicit_euler": "euler",
    "semi_explicit_euler": "symplectic-euler",
    "runge_kutta2": "heun",
    "implicit_euler": "implicit-euler",
    "radau1": "implicit-euler",
}
"""Drake's methods whose names are schemes the reference implements: Drake's documentation
calls ``implicit_euler`` and ``radau1`` (one-stage Radau IIA) both implicit Euler."""

METHOD_NOTES: Mapping[str, str] = MappingProxyType(
    {
        "explicit_euler": "Drake's explicit Euler, fixed step",
        "semi_explicit_euler": "Drake's semi-explicit (symplectic) Euler, velocity first, fixed step",
        "runge_kutta2": "Drake's second-order Runge-Kutta (explicit trapezoid, Heun), fixed step",
        "runge_kutta3": "Drake's third-order Runge-Kutta, fixed step",
        "implicit_euler": "Drake's implicit Euler, fixed step (its error estimate's two half steps "
        "are what it keeps: see the comparison with the reference's implicit Euler)",
        "radau1": "Drake's one-stage Radau IIA, i.e. backward Euler, fixed step",
        "radau3": "Drake's two-stage Radau IIA (order 3, implicit), fixed step",
        "runge_kutta5": "Drake's Cash-Karp 5(4) with error control; dt is the target accuracy",
        "bogacki_shampine3": "Drake's Bogacki-Shampine 3(2) with error control; dt is the target accuracy",
        "radau3-ec": "Drake's two-stage Radau IIA with error control; dt is the target accuracy",
    }
)

UNSUPPORTED_NOTES: Mapping[str, str] = MappingProxyType(
    {
        Feature.PLANES: "Drake's contact is compliant (Hunt-Crossley) with no coefficient of restitution, "
        "and its integrators see no collision events",
        Feature.THIN_WALLS: "Drake's contact has no coefficient of restitution",
        Feature.FRICTION: "Drake's contact has no coefficient of restitution",
        Feature.EMITTERS: "particles that appear and expire act between steps, "
        "which Drake's integrators never see",
        Feature.IMPULSES: "impulses act between steps, which Drake's integrators never see",
    }
)
"""Why a feature is beyond this adapter, for the ``unsupported`` row's message."""


class _Derivative(LeafSystem):
    """A Drake system whose time derivative is a reference system's.

    ``calls`` counts the evaluations (every one Drake asks for, Jacobian columns
    included)."""

    def __init__(self, system: System, derivative: Callable[[np.ndarray, float], np.ndarray]) -> None:
        super().__init__()
        self.system = system
        self.derivative = derivative
        self.calls = 0
        start: Any = system.get_state()
        x0 = BasicVector(start)
        if isinstance(system, SecondOrderSystem):
            self.DeclareContinuousState(x0, system.half, system.half, 0)
        else:
            self.DeclareContinuousState(x0, 0, 0, system.dim)

    def DoCalcTimeDerivatives(self, context: Any, derivatives: Any) -> None:
        self.calls += 1
        y = context.get_continuous_state_vector().CopyToVector()
        # the ContinuousState's own SetFromVector: the same values, without a Python
        # wrapper of its vector made at every evaluation
        derivatives.SetFromVector(self.derivative(y, context.get_time()))


def _bad(y: np.ndarray) -> bool:
    """Whether a state (dim,) is non-finite or beyond :data:`BLOWUP` (NaN compares false,
    and warns of nothing)."""
    return not bool(np.abs(y).max(initial=0.0) < BLOWUP)


class DrakeAdapter:
    """Drake's fixed-step and error-controlled integrators on truestep's scenes (see the
    module docstring: Drake integrates the reference system's derivative)."""

    name = "drake"
    methods = tuple(SCHEMES)
    adaptive_methods = tuple(ERROR_CONTROLLED)
    method_notes = METHOD_NOTES
    """One line per method, for the report's glossary."""
    method_facts: ClassVar[Mapping[str, FactsSpec]] = MappingProxyType(METHOD_FACTS)
    unsupported_notes = UNSUPPORTED_NOTES
    peers: ClassVar[Mapping[str, str]] = MappingProxyType(PEERS)
    """The reference method each one names as its scheme (the report compares their
    errors at the same steps, :mod:`truestep.measures.peers`)."""
    light_watch: ClassVar[bool] = True
    """A watched run (``monitor=True``) makes the same ``AdvanceTo`` calls as a plain one
    and keeps the state after each (a copy, microseconds; the energy is computed after the
    timed region): a long row of long steps is timed from it (Adapter protocol, item 9)."""
    watched_step_s: ClassVar[Mapping[str, float]] = MappingProxyType(
        {method: 0.0 if method in ERROR_CONTROLLED else COPY_HIDDEN_STEP_S for method in SCHEMES}
    )
    """The shortest step (s) whose watch is hidden in it, per method: a fixed-step run's
    watch keeps the state after each ``AdvanceTo``, 0.8 to 1.9 microseconds, under 1% of a
    step of :data:`~truestep.adapters.base.COPY_HIDDEN_STEP_S`; an error-controlled run keeps every
    step its monitor sees, watched or not, so its watched run is its plain run
    (``benchmarks/light_watch.py``)."""
    capabilities = frozenset(
        {
            Feature.ODE,
            Feature.SECOND_ORDER,
            Feature.POINT_MASSES,
            Feature.PLANAR,
            Feature.SPATIAL,
            Feature.UNIFORM_GRAVITY,
            Feature.DRAG,
            Feature.SPRINGS,
            Feature.SPRING_DAMPING,
            Feature.ANCHORED_SPRINGS,
            Feature.UNIVERSAL_GRAVITATION,
            Feature.FORCE_FIELDS,
            Feature.PINNED_PARTICLES,
        }
    )

    def __init__(self, *, compiled: bool = True) -> None:
        self.compiled = compiled
        """Whether Drake calls the system's compiled twin of its derivative where it has
        one (:meth:`~truestep.reference_impl.system.System.compiled_derivative`; the Python
        one with ``compiled=False``: the same bits, slower)."""

    def prepare(self, case: Case, method: str) -> None:
        """Before a run's process is forked: the scene's compiled derivative made (or
        loaded from numba's cache) here, so that the process finds it ready."""
        if self.compiled:
            build_system(case).compiled_derivative()

    def prepare_all(self, pairs: list[tuple[Case, str]], *, workers: int = 1) -> None:
        """The compiled derivatives of every case of ``pairs`` (case, method), on
        ``workers`` cores at once (:func:`~truestep.reference_impl.precompile.compile_all`)."""
        if self.compiled:
            compile_all(pairs=[(case.model, DERIVATIVE) for case, _ in pairs], workers=workers)

    def missing(self, case: Case, method: str) -> set[str]:
        """Features of ``case`` beyond :attr:`capabilities`; ``semi_explicit_euler`` also
        needs a second-order scene (Drake's ``q`` and ``v``)."""
        lacking = set(case.features) - self.capabilities
        if (
            method == "semi_explicit_euler"
            and case.kind == "ode"
            and Feature.SECOND_ORDER not in case.features
        ):
            lacking.add(Feature.SECOND_ORDER)
        return lacking

    def simulate(self, case: Case, method: str, dt: float, *, monitor: bool = False) -> Trajectory:
        """Run ``case`` with Drake's ``method`` at step (or target accuracy) ``dt``;
        ``monitor``: the energy's extremes over every step (the records are then thinned
        to those of a plain run)."""
        if method not in SCHEMES:
            raise ValueError(f"drake: unknown method {method!r}; known: {', '.join(self.methods)}")
        lacking = self.missing(case, method)
        if lacking:
            raise ValueError(f"drake cannot model {case.name}: needs {', '.join(sorted(lacking))}")
        run = _Run(case, method, dt, compiled=self.compiled)
        n_steps = run.n_steps
        marks = record_indices(n_steps, n_steps if monitor else case.max_records) if run.fixed else None
        t, y, wall = run.advance(marks)
        status, t_fail = finite_until(y, t)
        message = run.message
        if status == "ok" and run.watch.stop:
            status, t_fail, message = run.watch.verdict()
        elif status == "ok" and message:
            status, t_fail = "solver-failed", float(t[-1])
        fields: dict[str, Any] = {
            "status": status,
            "t_fail": t_fail,
            "nfev": run.leaf.calls,
            "steps": int(run.integrator.get_num_steps_taken()),
            "wall_s": wall,
            "message": message,
        }
        if run.fixed and monitor:
            return thin_records(
                trajectory_of_states(case, run.system, t, y, **fields), n_steps, case.max_records
            )
        watched = trajectory_of_states(case, run.system, t, y).energy if monitor else None
        if len(t) > case.max_records + 1:
            keep = np.unique(np.linspace(0, len(t) - 1, case.max_records + 1).round().astype(int))
            traj = trajectory_of_states(case, run.system, t[keep], y[keep], **fields)
        else:
            traj = trajectory_of_states(case, run.system, t, y, **fields)
        if watched is not None:
            traj.step_t, traj.step_energy = t, np.asarray(watched, float)
            traj.extremes = EnergyExtremes.of(t, traj.step_energy)
        return traj


class _Run:
    """One run's Drake objects, built outside the timed region: the system, its
    Simulator and integrator set up for ``method`` at ``dt``, and the monitor."""

    def __init__(self, case: Case, method: str, dt: float, *, compiled: bool = True) -> None:
        self.case, self.method = case, method
        self.system = build_system(case)
        fast = self.system.compiled_derivative() if compiled else None
        self.leaf = _Derivative(self.system, fast or self.system.derivative)
        self.simulator = Simulator(self.leaf)
        self.context = self.simulator.get_mutable_context()
        self.fixed = method in FIXED
        self.n_steps, self.h = case.steps_for(dt) if self.fixed else (0, case.duration)
        integrator = ResetIntegratorFromFlags(self.simulator, SCHEMES[method], self.h * (1.0 + STRETCH))
        if self.fixed:
            integrator.set_fixed_step_mode(True)
            if method in IMPLICIT:
                integrator.set_target_accuracy(NEWTON_ACCURACY)
                integrator.set_requested_minimum_step_size(self.h * (1.0 - UNSPLIT))
                integrator.set_throw_on_minimum_step_size_violation(True)
        else:
            integrator.set_target_accuracy(dt)
        self.integrator = integrator
        self.state = self.context.get_continuous_state_vector()
        self.watch = _Watch(self.state, self.leaf, keep=not self.fixed)
        self.simulator.set_monitor(self.watch)
        self.simulator.Initialize()
        self.leaf.calls = 0  # count the stepping's evaluations only (Initialize evaluates once,
        self.watch.reset()  # and shows the monitor the initial state)
        self.message = ""

    def advance(self, marks: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, float]:
        """Step to the end (timed): a fixed-step run one ``AdvanceTo`` per step, keeping
        the state at the step indices ``marks``; an error-controlled run in one call,
        keeping every step the monitor saw. Times (T,) s, states (T, dim), seconds."""
        times: list[float] = [0.0]
        states: list[Any] = [self.state.CopyToVector()]
        start = time.perf_counter()
        try:
            if marks is None:
                self.simulator.AdvanceTo(self.case.duration)
            else:
                self._fixed_steps(marks, times, states)
        except RuntimeError as err:
            now = self.context.get_time()
            self.message = _failure(self.method, self.fixed, now, self.h, str(err))
            if self.fixed and now > times[-1]:  # the state the failed step began from
                times.append(now)
                states.append(self.state.CopyToVector())
        wall = time.perf_counter() - start
        if not self.fixed:
            times += self.watch.kept_t
            states += self.watch.kept_y
        return np.array(times), np.array(states), wall

    def _fixed_steps(self, marks: np.ndarray, times: list[float], states: list[Any]) -> None:
        k, h, advance = 0, self.h, self.simulator.AdvanceTo
        for mark in marks[1:].tolist():
            while k < mark and not self.watch.stop:
                k += 1
                advance(k * h)
            times.append(self.context.get_time())
            states.append(self.state.CopyToVector())
            if self.watch.stop:
                return


def _failure(method: str, fixed: bool, t: float, h: float, words: str) -> str:
    """The row's message for a Drake exception at time ``t`` (s): at a fixed step, the
    only one is a Newton iteration that failed (Drake asks for a smaller step, which
    :data:`UNSPLIT` refuses); its own first sentence follows."""
    first = words.strip().split(". ")[0].splitlines()[0]
    if fixed and method in IMPLICIT:
        return (
            f"drake/{method}: Newton's iteration failed in the step of h = {h:.6g} s from t = {t:.6g} s "
            f"(Drake would split the step; its words: {first})"
        )
    return f"drake/{method}: {first}"


class _Watch:
    """The Simulator's monitor: after every step, stop on a runaway state, or once the
    ``leaf``'s evaluations pass :data:`MAX_EVALUATIONS` in an error-controlled run
    (``keep``, which also keeps each step's time and state: such a run records every
    step it accepts)."""

    def __init__(self, state: Any, leaf: _Derivative, *, keep: bool) -> None:
        self.state, self.leaf, self.keep = state, leaf, keep
        self.steps, self.stop, self.bad = 0, False, False
        self.t_stop: float | None = None
        self.reason = ""
        self.kept_t: list[float] = []
        self.kept_y: list[Any] = []

    def verdict(self) -> tuple[str, float | None, str]:
        """Status, time (s) and message of a run the monitor stopped."""
        return ("unstable" if self.bad else "solver-failed"), self.t_stop, self.reason

    def reset(self) -> None:
        """Forget what was seen so far (the initial state, which the Simulator's
        ``Initialize`` shows the monitor)."""
        self.steps = 0
        self.kept_t.clear()
        self.kept_y.clear()

    def __call__(self, context: Any) -> Any:
        self.steps += 1
        y = self.state.CopyToVector()
        if self.keep:
            self.kept_t.append(context.get_time())
            self.kept_y.append(y)
        if _bad(y):
            self.stop, self.bad, self.t_stop = True, True, context.get_time()
            self.reason = "non-finite or runaway state read back"
        elif self.keep and self.leaf.calls > MAX_EVALUATIONS:
            self.stop, self.t_stop = True, context.get_time()
            self.reason = (
                f"stopped after {self.leaf.calls} evaluations in {self.steps} steps, at "
                f"t = {self.t_stop:.6g} s: over truestep's bound on one run's work ({MAX_EVALUATIONS})"
            )
        if self.stop:
            return EventStatus.ReachedTermination(None, self.reason)
        return EventStatus.Succeeded()


__all__ = ["ERROR_CONTROLLED", "FIXED", "METHOD_FACTS", "DrakeAdapter"]
