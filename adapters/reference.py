"""The reference implementation as an adapter among equals."""

from __future__ import annotations

import time
from types import MappingProxyType

import numpy as np

from truestep.adapters.base import Trajectory, finite_until
from truestep.cases.case import Case
from truestep.cases.plugins import ode_system
from truestep.reference_impl.integrate import integrate
from truestep.reference_impl.particles import ParticleSystem, total_energy
from truestep.reference_impl.passes import passes_for
from truestep.reference_impl.solvers import METHODS, get_solver
from truestep.reference_impl.system import SecondOrderSystem, System


def build_system(case: Case) -> System:
    """The reference system for a case: its ODE system (the lecture's or an installed
    one, :func:`truestep.cases.plugins.ode_system`) or its particles."""
    if case.kind == "ode":
        return ode_system(case.ode.system)(case.ode.y0, **case.ode.params)
    return ParticleSystem(case.model, passes_for(case.model))


def trajectory_from_states(case: Case, t: np.ndarray, states: np.ndarray) -> tuple:
    """Split flat states (T, dim) into positions, velocities and energy as a Trajectory has them."""
    if case.kind == "ode":
        return states[:, None, :], None
    n = case.model.n
    return states[:, : 3 * n].reshape(-1, n, 3), states[:, 3 * n :].reshape(-1, n, 3)


def fused_rain_applies(case: Case, method: str) -> bool:
    """Whether the compiled kernel of :mod:`truestep.reference_impl.kernels` can run this case.

    It fuses the lecture's update with gravity, drag and one frictionless half-space for
    particles of one mass and radius; anything more and the general path runs.
    """
    m = case.model
    return (
        method == "lecture" and m is not None and len(m.planes) == 1
        and m.planes[0].friction == 0 and m.planes[0].thickness == 0
        and not len(m.springs) and not len(m.anchors)
        and m.gravitation is None and not m.fields and not m.emitters and not m.impulses
        and not np.any(m.fixed) and np.ptp(m.mass) == 0 and np.ptp(m.radius) == 0
    )


def simulate_fused_rain(case: Case, dt: float) -> Trajectory:
    """The lecture's update for independent particles through the compiled kernel.

    The same formulas as :class:`ParticleSystem` with :class:`LectureUpdate` and the
    plane-collision pass (tested equal to round-off), every step and record in one
    call, on one thread (the serial build of the kernel): the engines step on one core,
    and so does this comparison; and a process that ran it may still fork. The kernel's
    multi-core throughput is measured in ``benchmarks/test_particle_step.py``.
    """
    from truestep.reference_impl.integrate import record_indices
    from truestep.reference_impl.kernels import rain_run_serial

    m = case.model
    system = ParticleSystem(m, passes_for(m))
    x, v = system.positions.copy(), system.velocities.copy()
    contact = system.contact[0].copy()
    plane = m.planes[0]
    n_steps, step = case.steps_for(dt)
    marks = record_indices(n_steps, case.max_records)
    xs, vs = np.empty((len(marks), m.n, 3)), np.empty((len(marks), m.n, 3))
    xs[0], vs[0] = x, v
    stretches = np.diff(marks)
    start = time.perf_counter()
    rain_run_serial(x, v, contact, step, m.gravity, float(m.drag), float(m.mass[0]),
                    float(m.radius[0]), plane.point, plane.normal, float(plane.restitution),
                    stretches, xs[1:], vs[1:])
    wall = time.perf_counter() - start
    t = marks * step
    status, t_fail = finite_until(xs, t)
    energy = total_energy(m, xs, vs)
    return Trajectory(t=t, x=xs, v=vs, energy=energy, status=status, t_fail=t_fail,
                      nfev=n_steps, steps=n_steps, wall_s=wall,
                      message="fused compiled kernel, one thread")


class ReferenceAdapter:
    """Every solver of :mod:`truestep.reference_impl.solvers` on every case it can express."""

    name = "reference"
    methods = tuple(METHODS)
    adaptive_methods = tuple(m for m, cls in METHODS.items() if cls.adaptive)

    @property
    def method_facts(self) -> MappingProxyType:
        """Each solver's own facts, read from its class attribute ``facts`` when asked."""
        return MappingProxyType({m: cls.facts for m, cls in METHODS.items()})

    capabilities = frozenset(
        {
            "ode", "second-order", "point-masses", "2d", "3d", "uniform-gravity", "drag",
            "springs", "spring-damping", "anchored-springs", "universal-gravitation",
            "force-fields", "planes", "thin-walls", "friction", "emitters", "pinned-particles", "impulses",
        }
    )

    def missing(self, case: Case, method: str) -> set[str]:
        missing = case.features - self.capabilities
        if METHODS[method].needs_second_order and case.kind == "ode" and "second-order" not in case.features:
            missing.add("second-order")
        return missing

    def simulate(self, case: Case, method: str, dt: float) -> Trajectory:
        if fused_rain_applies(case, method):
            return simulate_fused_rain(case, dt)
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
            energy = total_energy(case.model, x, v, alive)
        return Trajectory(
            t=run.t, x=x, v=v, energy=energy, status=run.status, t_fail=run.t_fail,
            nfev=run.nfev, steps=run.steps, wall_s=run.wall_s, alive=alive,
        )
