"""scipy's ``solve_ivp`` as the peer users already know (plain ODE scenes and particles)."""

from __future__ import annotations

import math
import time
from types import MappingProxyType

import numpy as np
from scipy.integrate import solve_ivp

from truestep.adapters.base import EnergyExtremes, Trajectory, finite_until
from truestep.adapters.reference import build_system, trajectory_from_states
from truestep.cases.case import Case
from truestep.reference_impl.particles import total_energy
from truestep.reference_impl.solvers import MethodFacts, Stability

INF = float("inf")


class ScipyAdapter:
    """``scipy.integrate.solve_ivp`` with RK45, DOP853 and Radau, all adaptive.

    The right-hand side is the reference system's derivative, so the comparison is of
    integrators alone. ``dt`` is the tolerance (rtol = atol). Scenes with events
    between steps (collisions, emitters) are out of reach of a continuous integrator.
    """

    name = "scipy"
    methods = ("RK45", "DOP853", "Radau")
    adaptive_methods = methods
    method_facts = MappingProxyType({
        "RK45": "dopri5",
        "DOP853": MethodFacts(order=8, evaluations_per_step=12, symplectic=False),
        "Radau": MethodFacts(order=5, evaluations_per_step=None, symplectic=False,
                             stability=Stability(imaginary=INF, real=INF, a_stable=True)),
    })
    """From scipy's documentation and sources (``scipy/integrate/_ivp``): ``RK45`` is
    Dormand-Prince 5(4), the reference's ``dopri5`` tableau (six evaluations per accepted
    step, first same as last); ``DOP853`` is Dormand-Prince 8(5,3), twelve stages with
    the last reused; ``Radau`` is the three-stage Radau IIA of order 5, A- and L-stable,
    whose evaluations follow its Newton iterations. All three choose their own steps:
    their stability data never give a step limit here."""
    capabilities = frozenset(
        {
            "ode", "second-order", "point-masses", "2d", "3d", "uniform-gravity", "drag",
            "springs", "spring-damping", "anchored-springs", "universal-gravitation",
            "force-fields", "pinned-particles",
        }
    )

    def missing(self, case: Case, method: str) -> set[str]:
        return case.features - self.capabilities

    def simulate(self, case: Case, method: str, dt: float, *, monitor: bool = False
                 ) -> Trajectory:
        """Run ``case`` with solve_ivp's ``method`` at tolerance ``dt``; ``monitor``: also
        the energy's extremes over every accepted step (before the records are thinned)."""
        system = build_system(case)
        x0 = system.get_state()
        jac = None
        if method == "Radau" and system.jacobian(x0, 0.0) is not None:
            jac = system.jacobian
        options = {} if jac is None else {"jac": lambda t, y: jac(y, t)}
        calls = [0]

        def derivative(t: float, y: np.ndarray) -> np.ndarray:
            calls[0] += 1
            dy = system.derivative(y, t)
            # One reduction (about 1 us, a few percent of an evaluation): NaN or inf in the
            # state or its derivative, or a derivative beyond 1e154 (a runaway).
            if not math.isfinite(dy @ dy):
                raise _NonFinite(t, y)
            return dy

        start = time.perf_counter()
        try:
            sol = solve_ivp(derivative, (0.0, case.duration), x0, method=method,
                            rtol=dt, atol=dt, **options)
        except _NonFinite as bad:  # scipy would step on with NaN (or raise): unstable, here
            return _unstable_at(case, system, x0, bad, calls[0], time.perf_counter() - start)
        wall = time.perf_counter() - start
        t, states = sol.t, sol.y.T
        extremes = _extremes(case, system, t, states) if monitor else None
        if len(t) > case.max_records + 1:
            keep = np.unique(np.linspace(0, len(t) - 1, case.max_records + 1).round().astype(int))
            t, states = t[keep], states[keep]
        x, v = trajectory_from_states(case, t, states)
        if case.kind == "ode":
            e = [system.energy(s, ti) for s, ti in zip(states, t, strict=True)]
            energy = None if e[0] is None else np.array(e)
        else:
            energy = total_energy(case.model, x, v)
        status, t_fail = finite_until(states, t)
        message = ""
        if not sol.success and status == "ok":  # finite, but scipy could not go on
            status, t_fail, message = "solver-failed", float(sol.t[-1]), sol.message
        return Trajectory(
            t=t, x=x, v=v, energy=energy, status=status, t_fail=t_fail,
            nfev=int(sol.nfev), steps=len(sol.t) - 1, wall_s=wall, message=message,
            extremes=extremes,
        )


def _extremes(case: Case, system, t: np.ndarray, states: np.ndarray) -> EnergyExtremes | None:
    """The energy's extremes over every accepted step."""
    x, v = trajectory_from_states(case, t, states)
    if case.kind == "ode":
        e = [system.energy(s, ti) for s, ti in zip(states, t, strict=True)]
        return None if e[0] is None else EnergyExtremes.of(t, np.array(e, dtype=float))
    with np.errstate(all="ignore"):
        return EnergyExtremes.of(t, total_energy(case.model, x, v))


class _NonFinite(Exception):
    """A derivative was asked at, or gave, a non-finite state (time ``t``, state ``y``)."""

    def __init__(self, t: float, y: np.ndarray) -> None:
        super().__init__(f"non-finite state or derivative at t = {t:.6g} s")
        self.t, self.y = float(t), np.array(y, dtype=float)


def _unstable_at(case: Case, system, x0: np.ndarray, bad: _NonFinite, nfev: int,
                 wall: float) -> Trajectory:
    """The start and the first non-finite state: status ``unstable`` at its time."""
    t = np.array([0.0, bad.t])
    states = np.stack([x0, bad.y])
    x, v = trajectory_from_states(case, t, states)
    energy = None
    if case.kind != "ode":
        energy = total_energy(case.model, x, v)
    return Trajectory(t=t, x=x, v=v, energy=energy, status="unstable", t_fail=bad.t, nfev=nfev,
                      steps=0, wall_s=wall, message=str(bad))
