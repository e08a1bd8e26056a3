"""The reference implementation as an adapter among equals."""

from __future__ import annotations

import numpy as np

from adapters.base import Trajectory
from cases.case import Case
from reference_impl import odes
from reference_impl.integrate import integrate
from reference_impl.particles import ParticleSystem, total_energy
from reference_impl.passes import passes_for
from reference_impl.solvers import METHODS, get_solver
from reference_impl.system import SecondOrderSystem, System

ODE_CLASSES: dict[str, type[System]] = {
    "circle-field": odes.CircleField,
    "kepler": odes.KeplerProblem,
    "arenstorf": odes.Arenstorf,
}


def build_system(case: Case) -> System:
    """The reference system for a case: an ODE of :mod:`reference_impl.odes` or particles."""
    if case.kind == "ode":
        return ODE_CLASSES[case.ode.system](case.ode.y0, **case.ode.params)
    return ParticleSystem(case.model, passes_for(case.model))


def trajectory_from_states(case: Case, t: np.ndarray, states: np.ndarray) -> tuple:
    """Split flat states (T, dim) into positions, velocities and energy as a Trajectory has them."""
    if case.kind == "ode":
        return states[:, None, :], None
    n = case.model.n
    return states[:, : 3 * n].reshape(-1, n, 3), states[:, 3 * n :].reshape(-1, n, 3)


class ReferenceAdapter:
    """Every solver of :mod:`reference_impl.solvers` on every case it can express."""

    name = "reference"
    methods = tuple(METHODS)
    adaptive_methods = tuple(m for m, cls in METHODS.items() if cls.adaptive)
    capabilities = frozenset(
        {
            "ode", "second-order", "point-masses", "2d", "3d", "uniform-gravity", "drag",
            "springs", "spring-damping", "anchored-springs", "universal-gravitation",
            "force-fields", "planes", "friction", "emitters", "pinned-particles", "impulses",
        }
    )

    def missing(self, case: Case, method: str) -> set[str]:
        missing = case.features - self.capabilities
        if METHODS[method].needs_second_order and case.kind == "ode" and "second-order" not in case.features:
            missing.add("second-order")
        return missing

    def simulate(self, case: Case, method: str, dt: float) -> Trajectory:
        system = build_system(case)
        cls = get_solver(method)
        if cls.needs_second_order and not isinstance(system, SecondOrderSystem):
            raise TypeError(f"{method} needs a position/velocity split, {case.name} has none")
        if cls.adaptive:
            solver = cls(system, rtol=dt, atol=dt)
            step = case.duration
        else:
            solver = cls(system)
            step = case.steps_for(dt)[1]
        run = integrate(solver, case.duration, step, max_records=case.max_records)
        x, v = trajectory_from_states(case, run.t, run.x)
        alive = run.extra.get("alive")
        if case.kind == "ode":
            energy = np.array([system.energy(s, t) for s, t in zip(run.x, run.t, strict=True)])
            energy = None if energy.dtype == object else energy
        else:
            energy = np.array([
                total_energy(case.model, xi, vi, None if alive is None else alive[k])
                for k, (xi, vi) in enumerate(zip(x, v, strict=True))
            ])
        return Trajectory(
            t=run.t, x=x, v=v, energy=energy, status=run.status, t_fail=run.t_fail,
            nfev=run.nfev, steps=run.steps, wall_s=run.wall_s, alive=alive,
        )
