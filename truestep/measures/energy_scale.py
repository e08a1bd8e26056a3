"""The energy scale of a case: what energy drift and "far from the start" are measured
against, the same wherever the case puts the zero of its potential energy.

Dividing by ``|E(0)|`` makes a number of the origin: a pendulum whose potential is zero at
its anchor has ``E(0) = 0``, one lifted by 20 m has a ``|E(0)|`` that hides any error. The
scale here is the energy the motion exchanges, read along the case's reference path (its
exact solution, or the fine reference run a case names):

    ``S = max(KE_max, PE_max - PE_min)``

with ``PE = E - KE``: the largest kinetic energy, or the largest swing of potential energy
where that is larger (a cloth falling from rest). An oscillator's ``S`` is its energy; a
Kepler orbit's, its kinetic energy at pericentre. Neither moves when the scene is
translated or its potential shifted. A plain first-order ODE (no kinetic part) keeps
``max |E|`` along the path, the energy of its own definition. A particle scene without
an exact solution or reference run is read along a run of the reference (RK4 at its finest
step).
"""

from __future__ import annotations

import numpy as np

from truestep.cases.case import Case, OdeSpec, ode_states
from truestep.reference_impl.model import ParticleModel

GRID = 2001
"""Times along the reference path (evenly over the run) at which the scale is read."""
_CACHE: dict[int, tuple[Case, float]] = {}


def energy_scale(case: Case) -> float:
    """The case's energy scale :math:`S` (J; NaN where the case has no energy), read once
    per case object along its reference path (:func:`reference_path`)."""
    hit = _CACHE.get(id(case))
    if hit is not None and hit[0] is case:
        return hit[1]
    scale = _scale(case)
    if len(_CACHE) > 64:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[id(case)] = (case, scale)
    return scale


def _scale(case: Case) -> float:
    path = reference_path(case)
    if path is None:
        return _run_scale(case)
    t, x, v, alive = path
    match case.scene:
        case OdeSpec():
            return _ode_scale(case, t, x)
        case ParticleModel():
            return float("nan") if v is None else _particle_scale(case, x, v, alive)


def _particle_scale(case: Case, x: np.ndarray, v: np.ndarray, alive: np.ndarray | None) -> float:
    from truestep.reference_impl.particles import total_energy

    m = np.where(case.particles.fixed, 0.0, case.particles.mass)
    mass = m if alive is None else np.where(alive, m, 0.0)
    with np.errstate(invalid="ignore"):
        x0 = np.nan_to_num(x)
        v0 = np.nan_to_num(v)
        kinetic = 0.5 * np.sum(mass * np.sum(v0 * v0, axis=-1), axis=-1)
        potential = total_energy(case.particles, x0, v0, alive) - kinetic
    return _combine(kinetic, potential)


def _combine(kinetic: np.ndarray, potential: np.ndarray) -> float:
    ok = np.isfinite(kinetic) & np.isfinite(potential)
    if not ok.any():
        return float("nan")
    kinetic, potential = kinetic[ok], potential[ok]
    scale = max(float(np.max(kinetic)), float(np.max(potential) - np.min(potential)))
    return scale if scale > 0 else float("nan")


def _ode_scale(case: Case, t: np.ndarray, states: np.ndarray) -> float:
    from truestep.adapters.reference import build_system
    from truestep.reference_impl.system import SecondOrderSystem

    system = build_system(case)
    energy = np.array([system.energy(s, ti) for s, ti in zip(states, t, strict=True)])
    if energy.dtype == object or not np.isfinite(energy.astype(float)).any():
        return float("nan")
    energy = energy.astype(float)
    if isinstance(system, SecondOrderSystem):
        half = system.half
        kinetic = 0.5 * np.sum(states[:, half:] ** 2, axis=1)
        return _combine(kinetic, energy - kinetic)
    scale = float(np.max(np.abs(energy[np.isfinite(energy)])))
    return scale if scale > 0 else float("nan")


RUN_METHOD = "rk4"
"""The reference method that runs a case without an exact solution for its energy scale."""


def _run_scale(case: Case) -> float:
    """Without an exact solution or reference run: the scale along a run of the reference
    implementation (:data:`RUN_METHOD` at the case's finest step), NaN if that run fails or
    the scene is an ODE without one."""
    if not isinstance(case.scene, ParticleModel):
        return float("nan")
    from truestep.adapters.reference import ReferenceAdapter

    if ReferenceAdapter().missing(case, RUN_METHOD):
        return float("nan")
    run = ReferenceAdapter().simulate(case, RUN_METHOD, min(case.dts))
    if run.status != "ok" or run.v is None:
        return float("nan")
    return _particle_scale(case, run.x, run.v, run.alive)


def reference_path(case: Case) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None] | None:
    """The case's motion as truestep knows it best, at :data:`GRID` times or the reference
    run's records: ``(t, x, v, alive)`` with ``x``, ``v`` of shape (T, n, 3) (an ODE's
    states as ``x`` of shape (T, dim), ``v`` None); ``None`` without an exact solution."""
    if case.exact is None:
        return None
    from truestep.cases.exact import exact_named
    from truestep.cases.exact import reference_path as run_path

    if case.exact == "reference-run":
        ex, alive = run_path(case)
    else:
        solution = exact_named(case.exact) if case.exact is not None else None
        if solution is None:
            raise ValueError(f"{case.name}: no exact solution named {case.exact!r}")
        ex = solution(case, np.linspace(0.0, case.duration, GRID))
        alive = None
    if isinstance(case.scene, OdeSpec):
        return ex.t, ode_states(ex), None, None
    if ex.v is None or len(ex.t) < 2:
        return None
    return ex.t, ex.x, ex.v, alive
