"""scipy's ``solve_ivp`` as the peer users already know (plain ODE scenes and particles)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from truestep.adapters.base import EnergyExtremes, Trajectory, finite_until
from truestep.adapters.reference import build_system, trajectory_of_states
from truestep.cases.case import Case
from truestep.reference_impl.features import Feature
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.solvers import MethodFacts, Stability

INF = float("inf")


class ScipyAdapter:
    """``scipy.integrate.solve_ivp`` with RK45, DOP853 and Radau, all adaptive.

    The right-hand side is the reference system's derivative, so the comparison is of
    integrators alone: its compiled twin where it has one
    (:meth:`~truestep.reference_impl.system.System.compiled_derivative`: the same bits; the
    Python one with ``compiled=False``). ``dt`` is the tolerance (rtol = atol). Planes are
    met through solve_ivp's events: each impact (or friction stopping a particle) is located on the
    continuous extension, the reference's collision pass acts there and the integration
    starts again (:func:`_with_impacts`). Emitters and impulses, which act between fixed
    steps, are out of its reach.
    """

    name = "scipy"
    methods = ("RK45", "DOP853", "Radau")
    adaptive_methods = methods
    method_notes = MappingProxyType(
        {
            "RK45": "solve_ivp's Dormand-Prince 5(4) with step control; dt is the tolerance (rtol = atol)",
            "DOP853": "solve_ivp's Dormand-Prince 8(5,3); dt is the tolerance",
            "Radau": "solve_ivp's implicit Radau IIA of order 5; dt is the tolerance",
        }
    )
    """One line per method, for the report's glossary."""
    method_facts = MappingProxyType(
        {
            "RK45": "dopri5",
            "DOP853": MethodFacts(order=8, evaluations_per_step=12, symplectic=False),
            "Radau": MethodFacts(
                order=5,
                evaluations_per_step=None,
                symplectic=False,
                stability=Stability(imaginary=INF, real=INF, a_stable=True),
            ),
        }
    )
    """From scipy's documentation and sources (``scipy/integrate/_ivp``): ``RK45`` is
    Dormand-Prince 5(4), the reference's ``dopri5`` tableau (six evaluations per accepted
    step, first same as last); ``DOP853`` is Dormand-Prince 8(5,3), twelve stages with
    the last reused; ``Radau`` is the three-stage Radau IIA of order 5, A- and L-stable,
    whose evaluations follow its Newton iterations. All three choose their own steps:
    their stability data never give a step limit here."""
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
            Feature.PLANES,
            Feature.THIN_WALLS,
            Feature.FRICTION,
        }
    )

    def __init__(self, *, compiled: bool = True) -> None:
        self.compiled = compiled
        """Whether the right-hand side is the system's compiled twin where it has one."""

    def prepare(self, case: Case, method: str) -> None:
        """Before a run's process is forked: the scene's compiled derivative made (or
        loaded from numba's cache) here, so that the process finds it ready."""
        if self.compiled:
            build_system(case).compiled_derivative()

    def missing(self, case: Case, method: str) -> set[str]:
        return case.features - self.capabilities

    def simulate(self, case: Case, method: str, dt: float, *, monitor: bool = False) -> Trajectory:
        """Run ``case`` with solve_ivp's ``method`` at tolerance ``dt``; ``monitor``: also
        the energy's extremes over every accepted step (before the records are thinned)."""
        system = build_system(case)
        x0 = system.get_state()
        jac = None
        if method == "Radau" and system.jacobian(x0, 0.0) is not None:
            jac = system.jacobian
        options = {} if jac is None else {"jac": lambda t, y: jac(y, t)}
        calls = [0]
        rhs = (system.compiled_derivative() if self.compiled else None) or system.derivative

        def derivative(t: float, y: np.ndarray) -> np.ndarray:
            calls[0] += 1
            dy = rhs(y, t)
            # One reduction (small beside an evaluation): NaN or inf in the state or its
            # derivative, or a derivative beyond 1e154 (a runaway).
            if not math.isfinite(dy @ dy):
                raise _NonFinite(t, y)
            return dy

        start = time.perf_counter()
        try:
            if isinstance(case.scene, ParticleModel) and case.scene.planes:
                sol = _with_impacts(case, system, derivative, method, dt, options)
            else:
                sol = solve_ivp(
                    derivative, (0.0, case.duration), x0, method=method, rtol=dt, atol=dt, **options
                )
        except _NonFinite as bad:  # scipy would step on with NaN (or raise): unstable, here
            return _unstable_at(case, system, x0, bad, calls[0], time.perf_counter() - start)
        wall = time.perf_counter() - start
        t, states = sol.t, sol.y.T
        step_t, step_energy = (
            _step_energies(case, system, getattr(sol, "step_t", sol.t), getattr(sol, "step_y", sol.y).T)
            if monitor
            else (None, None)
        )
        if len(t) > case.max_records + 1:
            keep = np.unique(np.linspace(0, len(t) - 1, case.max_records + 1).round().astype(int))
            t, states = t[keep], states[keep]
        status, t_fail = finite_until(states, t)
        message = ""
        if not sol.success and status == "ok":  # finite, but scipy could not go on
            status, t_fail, message = "solver-failed", float(sol.t[-1]), sol.message
        return trajectory_of_states(
            case,
            system,
            t,
            states,
            status=status,
            t_fail=t_fail,
            nfev=int(sol.nfev),
            steps=int(getattr(sol, "steps", len(sol.t) - 1)),
            wall_s=wall,
            message=message,
            step_t=step_t,
            step_energy=step_energy,
            extremes=None
            if step_t is None or step_energy is None
            else EnergyExtremes.of(step_t, step_energy),
        )


EVENT_DEPTH = 1e-12
"""m (or m/s, for friction's stop): how far past zero an event function is when solve_ivp's
event fires; the collision pass takes the particle from there."""


@dataclass
class _Pieces:
    """solve_ivp's answer for a run cut at its impacts, in the fields the adapter reads:
    ``t`` (T,), ``y`` (dim, T), ``nfev``, ``success``, ``message``, ``steps``, and the
    accepted steps of every piece, ``step_t`` (S,) and ``step_y`` (dim, S)."""

    t: np.ndarray
    y: np.ndarray
    nfev: int
    success: bool
    message: str
    steps: int
    step_t: np.ndarray
    step_y: np.ndarray


def _with_impacts(case: Case, system, derivative, method: str, tol: float, options: dict) -> _Pieces:
    """solve_ivp from impact to impact: each piece integrates until an event function
    (the least distance of a watched particle above a plane, or the least tangential
    speed of a particle friction is stopping: :meth:`ParticleSystem.event_watch`) falls
    through zero, located by solve_ivp's root finding on its continuous extension; the
    collision pass acts there (``located``), and the next piece starts from the state it
    leaves. The run is recorded on the case's grid of ``max_records`` by each piece's
    continuous extension (never at an impact, where the velocity is two-valued)."""
    system.located = True
    system.rest_height = tol
    grid = np.linspace(0.0, case.duration, case.max_records + 1)
    t, x = 0.0, system.get_state()
    ts: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    nfev, steps, ok, message = 0, 0, True, ""
    step_ts, step_ys = [np.array([t])], [x[:, None]]
    slack = 1e-12 * max(1.0, case.duration)
    while case.duration - t > slack:
        watch = system.event_watch()
        g0 = watch(x)
        watched = np.isfinite(g0)

        def event(_t: float, y: np.ndarray, watch=watch, watched=watched) -> float:
            # A particle the pass has just sent off a plane starts exactly on it: the
            # events fire EVENT_DEPTH past the plane, so that its zero now is no event.
            g = watch(y)[watched]
            return float(np.min(g)) + EVENT_DEPTH if len(g) else 1.0

        marked: Any = event  # solve_ivp reads these attributes of an event function
        marked.terminal, marked.direction = True, -1
        sol = solve_ivp(
            derivative,
            (t, case.duration),
            x,
            method=method,
            rtol=tol,
            atol=tol,
            events=event,
            dense_output=True,
            **options,
        )
        nfev += int(sol.nfev)
        steps += len(sol.t) - 1
        step_ts.append(sol.t[1:])
        step_ys.append(sol.y[:, 1:])
        end = float(sol.t[-1])
        inside = grid[(grid >= t - slack) & (grid <= end + slack)]
        if len(inside):
            inside = inside[(inside > t + slack) | (len(ts) == 0)]
        if len(inside):
            ts.append(inside)
            ys.append(sol.sol(inside))
        if not sol.success:
            ok, message = False, sol.message
            break
        if sol.status != 1 or end - t <= slack:  # the end of the run, or no progress
            t = end
            break
        t, y = _just_past(sol, event, end, case.duration)
        system.set_state(y, t)
        system.between_steps(0.0)
        x = system.get_state()
    if not ts or abs(ts[-1][-1] - t) > slack:
        ts.append(np.array([t]))
        ys.append(system.get_state()[:, None])
    return _Pieces(
        np.concatenate(ts),
        np.concatenate(ys, axis=1),
        nfev,
        ok,
        message,
        steps,
        np.concatenate(step_ts),
        np.concatenate(step_ys, axis=1),
    )


def _just_past(sol, event, t_event: float, t_end: float) -> tuple[float, np.ndarray]:
    """The time and state just past a located event, where its function is below zero
    (solve_ivp's root may lie a hair before the crossing, where the collision pass would
    not yet see the particle at the plane): stepping by doubling from 1e-15 of the time,
    along the piece's continuous extension, at most 1e-9 of it."""
    scale = max(1.0, abs(t_event))
    delta = 1e-15 * scale
    while delta <= 1e-9 * scale and t_event + delta <= t_end:
        y = sol.sol(t_event + delta)
        if event(t_event + delta, y) < 0:
            return t_event + delta, y
        delta *= 2
    return t_event, sol.y[:, -1]


def _step_energies(
    case: Case, system, t: np.ndarray, states: np.ndarray
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Times and total energies at every accepted step (``None`` for an ODE without one)."""
    energy = trajectory_of_states(case, system, t, states).energy
    return (None, None) if energy is None else (t, np.asarray(energy, float))


class _NonFinite(Exception):
    """A derivative was asked at, or gave, a non-finite state (time ``t``, state ``y``)."""

    def __init__(self, t: float, y: np.ndarray) -> None:
        super().__init__(f"non-finite state or derivative at t = {t:.6g} s")
        self.t, self.y = float(t), np.array(y, dtype=float)


def _unstable_at(case: Case, system, x0: np.ndarray, bad: _NonFinite, nfev: int, wall: float) -> Trajectory:
    """The start and the first non-finite state: status ``unstable`` at its time."""
    t = np.array([0.0, bad.t])
    states = np.stack([x0, bad.y])
    return trajectory_of_states(
        case,
        system,
        t,
        states,
        energy=isinstance(case.scene, ParticleModel),
        status="unstable",
        t_fail=bad.t,
        nfev=nfev,
        steps=0,
        wall_s=wall,
        message=str(bad),
    )
