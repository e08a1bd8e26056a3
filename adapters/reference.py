"""The reference implementation as an adapter among equals.

On the CPU (the default) every case runs, through the compiled path where it applies, else
through the numpy system. Put on a GPU (``truestep run --device reference=cuda:0``; never
by a bare ``--device cuda:0``, which moves the GPU engines only), the reference runs the
scenes of independent particles with the lecture's update and symplectic Euler as one Warp
kernel (:mod:`~truestep.reference_impl.warp_particles`, tested equal to the compiled path
bit for bit on Warp's CPU device), and says ``unsupported`` for the rest: the same
reference on the CPU is the other half of the twin rows.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from types import MappingProxyType
from typing import Any

import numpy as np

from truestep.adapters.base import (
    COPY_HIDDEN_STEP_S,
    MONITOR_BYTES,
    EnergyExtremes,
    Trajectory,
    particle_trajectory,
    thin_records,
    unwatched_note,
)
from truestep.adapters.devices import CPU, chosen
from truestep.cases.case import Case, OdeSpec
from truestep.cases.plugins import ode_system
from truestep.reference_impl.compiled import compiled_reason, prepared, run_compiled
from truestep.reference_impl.features import Feature
from truestep.reference_impl.integrate import integrate
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.odes_loop import ode_reason
from truestep.reference_impl.odes_loop import run as run_ode
from truestep.reference_impl.odes_loop import warm as warm_ode_loop
from truestep.reference_impl.particles import ParticleSystem, total_energy
from truestep.reference_impl.passes import passes_for
from truestep.reference_impl.precompile import compile_all
from truestep.reference_impl.solvers import METHODS, get_solver
from truestep.reference_impl.system import SecondOrderSystem, System


def build_system(case: Case) -> System:
    """The reference system for a case: its ODE system (the lecture's or an installed
    one, :func:`truestep.cases.plugins.ode_system`) or its particles."""
    match case.scene:
        case OdeSpec() as ode:
            system = ode_system(ode.system)
            if system is None:  # the loader refuses an unknown name; a case built by hand may not
                raise ValueError(f"{case.name}: no ODE system is registered as {ode.system!r}")
            return system(ode.y0, **ode.params)
        case ParticleModel() as model:
            return ParticleSystem(model, passes_for(model))


def trajectory_of_states(
    case: Case, system: System, t: np.ndarray, states: np.ndarray, *, energy: bool = True, **fields
) -> Trajectory:
    """The Trajectory of flat states (T, dim) at times ``t`` (T,) s: an ODE's states as
    they are (``y``), a particle scene's split into positions and velocities (T, n, 3);
    with the energy (J) of each record when ``energy``; ``fields`` are the Trajectory's
    other attributes (``status``, ``nfev``, ``alive`` ...)."""
    match case.scene:
        case OdeSpec():
            e = [system.energy(s, ti) for s, ti in zip(states, t, strict=True)] if energy else []
            known = bool(e) and all(v is not None for v in e)
            return Trajectory.of_ode(t, states, np.array(e, dtype=float) if known else None, **fields)
        case ParticleModel() as model:
            n = model.n
            x, v = states[:, : 3 * n].reshape(-1, n, 3), states[:, 3 * n :].reshape(-1, n, 3)
            with np.errstate(all="ignore"):
                e_particles = total_energy(model, x, v, fields.get("alive")) if energy else None
            return Trajectory(t=t, x=x, v=v, energy=e_particles, **fields)


DEVICE_METHODS = ("lecture", "symplectic-euler")
"""The methods the reference runs on a GPU (:data:`~truestep.reference_impl.warp_particles.KICK_DRIFT`)."""
DEVICE_CAPABILITIES = frozenset(
    {
        Feature.POINT_MASSES,
        Feature.PLANAR,
        Feature.SPATIAL,
        Feature.UNIFORM_GRAVITY,
        Feature.DRAG,
        Feature.PLANES,
        Feature.THIN_WALLS,
        Feature.FRICTION,
    }
)
"""What the reference models on a GPU: independent particles (the Warp kernel's scenes)."""


class ReferenceAdapter:
    """Every solver of :mod:`truestep.reference_impl.solvers` on every case it can express.

    Parameters
    ----------
    compiled : bool
        Whether runs take the compiled path where it applies (default), or the numpy one.
    threads : int
        Threads that step a scene of independent particles at once, a tile of
        :data:`~truestep.reference_impl.tiles.BLOCK` particles each at a time (the
        compiled path; the same numbers as one thread, bit for bit). Default 1: a run's
        timed rows keep one core each, as every engine's do.
    """

    def __init__(self, *, compiled: bool = True, threads: int = 1, device: str | None = None) -> None:
        if not (isinstance(threads, int) and threads >= 1):
            raise ValueError(f"threads: a whole number of at least 1, got {threads!r}")
        self.compiled = compiled
        self.threads = threads
        self.device = device or chosen(self.name) or CPU
        """Where the runs compute: ``cpu``, or a Warp device (``cuda:N``) for the scenes
        and methods of :mod:`~truestep.reference_impl.warp_particles`."""
        if self.device != CPU:
            from truestep.adapters.warp_runtime import want_gpu

            want_gpu(self.device)
            self.methods = DEVICE_METHODS
            self.adaptive_methods = ()
            self.bounce_methods = tuple(m for m in type(self).bounce_methods if m in DEVICE_METHODS)

    name = "reference"
    methods: tuple[str, ...] = tuple(METHODS)
    adaptive_methods: tuple[str, ...] = tuple(m for m, cls in METHODS.items() if cls.adaptive)
    method_notes = MappingProxyType(
        {
            "euler": "explicit (forward) Euler: order 1",
            "midpoint": "explicit midpoint rule: order 2",
            "heun": "Heun's method (explicit trapezoid): order 2",
            "rk4": "classical Runge-Kutta: order 4",
            "dopri5": "Dormand-Prince 5(4) with step control; its dt is the tolerance (rtol = atol)",
            "symplectic-euler": "symplectic (semi-implicit) Euler, velocity first: order 1, symplectic",
            "verlet": "velocity Verlet: order 2 (1 with velocity-dependent forces), symplectic",
            "implicit-euler": "backward Euler by Newton's method: order 1, damps the motion",
            "lecture": "the lecture's update v' = v + a h, x' = x + (v + v') h / 2: order 1",
        }
    )
    """One line per method, for the report's glossary."""

    @property
    def method_facts(self) -> MappingProxyType:
        """Each solver's own facts, read from its class attribute ``facts`` when asked."""
        return MappingProxyType({m: cls.facts for m, cls in METHODS.items()})

    light_watch: tuple[str, ...] = ("implicit-euler", "dopri5")
    """The methods whose watched run (``monitor=True``) adds no more than keeping the state
    after each step to the stepping of a plain one, inside its timed region (Adapter
    protocol, item 9): both run on the numpy path, and Dormand-Prince keeps every accepted
    step in a plain run too. A long row of theirs whose steps take :attr:`watched_step_s`
    or more is timed from its watched run."""
    watched_step_s: Mapping[str, float] = MappingProxyType(
        {"implicit-euler": COPY_HIDDEN_STEP_S, "dopri5": 0.0}
    )
    """The shortest step (s) whose watch is hidden in it, per method: implicit Euler's
    watch keeps the state after each step, 0.3 to 2.8 microseconds (one body to the stiff
    cloth's), under 1% of a step of :data:`~truestep.adapters.base.COPY_HIDDEN_STEP_S`;
    Dormand-Prince's watched run is its plain run (``benchmarks/light_watch.py --engine
    reference``)."""
    bounce_methods: tuple[str, ...] = ("lecture", "symplectic-euler", "rk4")
    """The methods of the restitution sweep: the collision pass is the same for all, so a
    first-order, a symplectic and a fourth-order integrator show whether the integrator
    matters at all."""
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
            Feature.PLANES,
            Feature.THIN_WALLS,
            Feature.FRICTION,
            Feature.EMITTERS,
            Feature.PINNED_PARTICLES,
            Feature.IMPULSES,
        }
    )

    device_named_only = True
    """A bare ``--device cuda:0`` leaves the reference on the CPU: it moves there only when
    named (``reference=cuda:0``), since on a GPU it models fewer scenes."""
    unsupported_notes = MappingProxyType(
        {
            f: "on a GPU the reference steps independent particles only (gravity, drag, planes)"
            for f in (
                Feature.ODE,
                Feature.SECOND_ORDER,
                Feature.SPRINGS,
                Feature.SPRING_DAMPING,
                Feature.ANCHORED_SPRINGS,
                Feature.UNIVERSAL_GRAVITATION,
                Feature.FORCE_FIELDS,
                Feature.EMITTERS,
                Feature.PINNED_PARTICLES,
                Feature.IMPULSES,
            )
        }
    )
    """Why a feature is beyond the reference, which is only ever so on a GPU."""

    def missing(self, case: Case, method: str) -> set[str]:
        if self.device != CPU:
            return set(case.features - DEVICE_CAPABILITIES)
        missing = case.features - self.capabilities
        if (
            METHODS[method].needs_second_order
            and isinstance(case.scene, OdeSpec)
            and Feature.SECOND_ORDER not in case.features
        ):
            missing.add(Feature.SECOND_ORDER)
        return missing

    def prepare(self, case: Case, method: str) -> None:
        """Compile the loop ``method`` runs ``case`` with (or load it from numba's cache;
        shown on standard error when slow), where the compiled path applies: called in
        the parent before it forks a sweep's runs, so that they find it ready."""
        if self.device == CPU and self.compiled and compiled_reason(case.model, method) is None:
            prepared(case.particles, method)
        elif self.device == CPU and self.compiled and isinstance(case.scene, OdeSpec):
            if ode_reason(build_system(case), method) is None:
                warm_ode_loop()  # one loop for every system and method: compiled once, or loaded

    def prepare_all(self, pairs: list[tuple[Case, str]], *, workers: int = 1) -> None:
        """:meth:`prepare` every (case, method) of ``pairs``, the loops they need compiled
        on ``workers`` cores at once (:func:`~truestep.reference_impl.precompile.compile_all`)."""
        if self.device == CPU and self.compiled:
            compile_all(pairs=[(case.model, method) for case, method in pairs], workers=workers)
            if any(isinstance(case.scene, OdeSpec) for case, _ in pairs):
                warm_ode_loop()

    def simulate(self, case: Case, method: str, dt: float, *, monitor: bool = False) -> Trajectory:
        """Run ``case`` with ``method``: through the compiled loop where it applies
        (:func:`~truestep.reference_impl.compiled.compiled_reason`; not with
        ``compiled=False``), else through the numpy system and solver classes; the
        Trajectory's ``path`` says which.

        ``monitor``: also find the lowest and highest energy over every step
        (``extremes``): the run records every step (an adaptive run records every
        accepted step anyway) and keeps the records it would have kept. A run whose every
        state would exceed :data:`MONITOR_BYTES` is watched at its records only."""
        unwatched = ""
        if monitor and not get_solver(method).adaptive:
            n_steps = case.steps_for(dt)[0]
            size = n_steps * case.bodies * 48
            if n_steps > case.max_records and size <= MONITOR_BYTES:
                traj = self._simulate(replace(case, max_records=n_steps), method, dt)
                return thin_records(traj, n_steps, case.max_records)
            if n_steps > case.max_records:
                unwatched = unwatched_note(size)
        traj = self._simulate(case, method, dt)
        if monitor and traj.energy is not None:
            traj.extremes = EnergyExtremes.of(traj.t, traj.energy)
        if unwatched:
            traj.message = "; ".join(m for m in (traj.message, unwatched) if m)
        return traj

    def _simulate(self, case: Case, method: str, dt: float) -> Trajectory:
        if self.device != CPU:
            return self._simulate_on_device(case, method, dt)
        if self.compiled and compiled_reason(case.model, method) is None:
            return self._simulate_compiled(case, method, dt)
        system = build_system(case)
        cls = get_solver(method)
        if cls.needs_second_order and not isinstance(system, SecondOrderSystem):
            raise TypeError(f"{method} needs a position/velocity split, {case.name} has none")
        on_loop = self.compiled and isinstance(case.scene, OdeSpec) and ode_reason(system, method) is None
        samples = None
        if on_loop:  # the plain ODE systems' compiled loop: the numpy path's run, bit for bit
            run = run_ode(system, method, case.duration, case.steps_for(dt)[1], max_records=case.max_records)
        else:
            if cls.adaptive:
                adaptive: Any = cls  # an adaptive solver takes its tolerances (Solver, ``adaptive = True``)
                solver = adaptive(system, rtol=dt, atol=dt)
                step = case.duration
                samples = np.linspace(0.0, case.duration, case.max_records + 1)
            else:
                solver = cls(system)
                step = case.steps_for(dt)[1]
            if self.compiled:  # a step with no compiled loop (implicit Euler) still calls a compiled f
                solver.use_compiled_derivative()
            run = integrate(solver, case.duration, step, max_records=case.max_records, sample_at=samples)
        return trajectory_of_states(
            case,
            system,
            run.t,
            run.x,
            status=run.status,
            t_fail=run.t_fail,
            nfev=run.nfev,
            steps=run.steps,
            wall_s=run.wall_s,
            alive=run.extra.get("alive"),
            path="compiled" if on_loop else "numpy",
            message=run.message,
        )

    def _simulate_on_device(self, case: Case, method: str, dt: float) -> Trajectory:
        """The run on :attr:`device` (:func:`~truestep.reference_impl.warp_particles.run`); a
        run in which a particle ran away is made again on the CPU, whose records and stop
        are the row's (its message says so)."""
        from truestep.adapters.warp_runtime import start
        from truestep.reference_impl.warp_particles import run as run_on_device

        start()
        n_steps, h = case.steps_for(dt)
        run = run_on_device(
            case.particles, method, h, n_steps, device=self.device, max_records=case.max_records
        )
        if run.blew_up is not None:
            again = self._simulate_compiled(case, method, dt)
            words = (
                f"a particle ran away by step {run.blew_up} on {self.device}: "
                "the records and the stop are the CPU's run of the same steps"
            )
            again.message = "; ".join(m for m in (again.message, words) if m)
            return again
        fields = {"nfev": run.nfev, "steps": run.steps, "wall_s": run.wall_s, "path": "warp"}
        return particle_trajectory(case, run.t, run.x, run.v, status="ok", t_fail=None, **fields)

    def _simulate_compiled(self, case: Case, method: str, dt: float) -> Trajectory:
        run, wall = run_compiled(
            case.particles,
            method,
            case.duration,
            case.steps_for(dt)[1],
            max_records=case.max_records,
            threads=self.threads,
        )
        message = "non-finite or runaway state (beyond 1e12)" if run.status == "unstable" else ""
        return particle_trajectory(
            case,
            run.t,
            run.x,
            run.v,
            status=run.status,
            t_fail=run.t_fail,
            nfev=run.nfev,
            steps=run.steps,
            wall_s=wall,
            path="compiled",
            message=message,
        )
