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

Each extreme is read where it is, not where a grid happens to fall: the path is read at
:data:`GRID` times, and the largest local extremes found there (:data:`REFINED` of each)
are refined between their grid neighbours on the path itself (:func:`peak`): a close
encounter's kinetic-energy peak is far narrower than the grid's spacing.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from truestep.cases.case import Case, OdeSpec, ode_states
from truestep.reference_impl.model import ParticleModel

GRID = 2001
"""Times along the reference path (evenly over the run) at which the scale is first read."""
REFINED = 8
"""How many of the largest local extremes of each energy on the grid are refined."""
ZOOM_POINTS = 33
ZOOMS = 6
"""A refinement reads :data:`ZOOM_POINTS` times across the two grid intervals about an
extreme, then across the two about the best of those, :data:`ZOOMS` times: the extreme's
time to ``(2 / 32)^6`` of the grid's spacing, its value to round-off where it is smooth."""
CHUNK = 2_000_000
"""Particle-times of the path read at once: the times are read in blocks of
``CHUNK // n``, so that the memory the scale takes grows with the particles, not with
the particles times :data:`GRID` (each time's energies are the same either way)."""
COMPILED_RAIN = 20_000
"""Balls from which a ``bouncing-rain`` scene's energies are summed by the compiled pass
(:func:`truestep.cases.bounce_energies.rain_energies`) instead of from its states: memory
and work without the (T, N, 3) arrays (a million balls' scale many times faster than
from the states). Below it, the states' ``total_energy`` as for every other scene; the two
agree to a few units in the last place."""
_CACHE: dict[int, tuple[Case, float]] = {}

Energies = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray | None, np.ndarray]]
"""Times (T,) s -> the times (K,) among them where the path is known (all of them, but for
an exact solution known only at some times: a periodic one at whole periods), and the
kinetic and potential energy (K,) J there (a first-order ODE: ``None`` and ``|E|``)."""


def energy_scale(case: Case) -> float:
    """The case's energy scale :math:`S` (J; NaN where the case has no energy), read once
    per case object along its reference path (:func:`path_at`)."""
    hit = _CACHE.get(id(case))
    if hit is not None and hit[0] is case:
        return hit[1]
    scale = _scale(case)
    if len(_CACHE) > 64:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[id(case)] = (case, scale)
    return scale


def _scale(case: Case) -> float:
    if case.exact is None:
        return _run_scale(case)
    energies = path_energies(case)
    if energies is None:
        return float("nan")
    t, kinetic, potential = energies(np.linspace(0.0, case.duration, GRID))
    if not np.isfinite(potential).any():
        return float("nan")

    def part(k: int, sign: float = 1.0) -> Callable[[np.ndarray], np.ndarray]:
        def at(s: np.ndarray) -> np.ndarray:
            known = energies(s)
            values = known[k]
            if values is None or len(known[0]) != len(s):
                return np.full(len(s), np.nan)
            return sign * np.asarray(values, dtype=float)

        return at

    if kinetic is None:  # a plain first-order ODE: the largest |E|
        return _positive(peak(part(2), t, potential))
    ke_max = peak(part(1), t, kinetic)
    pe_max = peak(part(2), t, potential)
    pe_min = -peak(part(2, -1.0), t, -potential)
    return _positive(max(ke_max, pe_max - pe_min))


def _positive(scale: float) -> float:
    return scale if np.isfinite(scale) and scale > 0 else float("nan")


def peak(f: Callable[[np.ndarray], np.ndarray], t: np.ndarray, values: np.ndarray) -> float:
    """The largest value of ``f`` (times (k,) -> values (k,)) over ``[t[0], t[-1]]``, from
    its ``values`` (T,) at the grid ``t`` (T,): the :data:`REFINED` largest local maxima of
    the grid, each zoomed into between its neighbours (:data:`ZOOMS` rounds of
    :data:`ZOOM_POINTS` evenly spread times, each round about the best of the last, every
    candidate at once); NaN where no value is finite."""
    g = np.where(np.isfinite(values), values, -np.inf)
    if not np.isfinite(g).any():
        return float("nan")
    left = np.concatenate(([-np.inf], g[:-1]))
    right = np.concatenate((g[1:], [-np.inf]))
    local = np.flatnonzero((g >= left) & (g >= right) & np.isfinite(g))
    top = local[np.argsort(-g[local], kind="stable")][:REFINED]
    lo, hi = t[np.maximum(top - 1, 0)], t[np.minimum(top + 1, len(t) - 1)]
    best = float(np.max(g))
    steps = np.linspace(0.0, 1.0, ZOOM_POINTS)
    for _ in range(ZOOMS):
        times = lo[:, None] + (hi - lo)[:, None] * steps[None, :]  # (k, ZOOM_POINTS)
        found = np.asarray(f(times.ravel()), dtype=float).reshape(times.shape)
        found = np.where(np.isfinite(found), found, -np.inf)
        if not np.isfinite(found).any():
            break
        best = max(best, float(np.max(found)))
        j = np.argmax(found, axis=1)
        rows = np.arange(len(lo))
        lo = times[rows, np.maximum(j - 1, 0)]
        hi = times[rows, np.minimum(j + 1, ZOOM_POINTS - 1)]
    return best


def path_energies(case: Case) -> Energies | None:
    """Kinetic and potential energy along the case's reference path at any times
    (:func:`path_at`), or ``None`` without an exact solution, or for a particle scene whose
    path has no velocities."""
    at = path_at(case)
    if at is None:
        return None
    match case.scene:
        case OdeSpec():
            from truestep.adapters.reference import build_system
            from truestep.reference_impl.system import SecondOrderSystem

            system = build_system(case)
            half = system.half if isinstance(system, SecondOrderSystem) else None

            def ode(t: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
                ex, _ = at(t)
                states = ode_states(ex)
                e = np.array([system.energy(s, ti) for s, ti in zip(states, ex.t, strict=True)])
                if e.dtype == object:  # a system without an energy
                    e = np.full(len(ex.t), np.nan)
                e = e.astype(float)
                if half is None:
                    return ex.t, None, np.abs(e)
                kinetic = 0.5 * np.sum(np.asarray(states)[:, half:] ** 2, axis=1)
                return ex.t, kinetic, e - kinetic

            return ode
        case ParticleModel():
            if case.exact == "bouncing-rain" and case.particles.n >= COMPILED_RAIN:
                from truestep.cases.bounce_energies import rain_energies

                return lambda t: rain_energies(case, t)
            if at(np.zeros(1))[0].v is None:
                return None

            def particles(t: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
                block = max(1, CHUNK // max(1, case.particles.n))
                parts = []
                for k in range(0, len(t), block):
                    ex, alive = at(t[k : k + block])
                    parts.append((ex.t, *_particle_energies(case, ex.x, ex.v, alive)))
                if not parts:
                    return t, np.zeros(0), np.zeros(0)
                times, kinetic, potential = (np.concatenate(p) for p in zip(*parts, strict=True))
                return times, kinetic, potential

            return particles
    return None


def _particle_energies(
    case: Case, x: np.ndarray, v: np.ndarray, alive: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Kinetic and potential energy (T,) J of particle states ``x``, ``v`` (T, n, 3)."""
    from truestep.reference_impl.particles import total_energy

    m = np.where(case.particles.fixed, 0.0, case.particles.mass)
    mass = m if alive is None else np.where(alive, m, 0.0)
    with np.errstate(invalid="ignore"):
        x0 = np.nan_to_num(x)
        v0 = np.nan_to_num(v)
        kinetic = 0.5 * np.sum(mass * np.sum(v0 * v0, axis=-1), axis=-1)
        potential = total_energy(case.particles, x0, v0, alive) - kinetic
    return kinetic, potential


RUN_METHOD = "rk4"
"""The reference method that runs a case without an exact solution for its energy scale."""


def _run_scale(case: Case) -> float:
    """Without an exact solution or reference run: the scale along a run of the reference
    implementation (:data:`RUN_METHOD` at the case's finest step, read at its records), NaN
    if that run fails or the scene is an ODE without one."""
    if not isinstance(case.scene, ParticleModel):
        return float("nan")
    from truestep.adapters.reference import ReferenceAdapter

    if ReferenceAdapter().missing(case, RUN_METHOD):
        return float("nan")
    run = ReferenceAdapter().simulate(case, RUN_METHOD, min(case.dts))
    if run.status != "ok" or run.v is None:
        return float("nan")
    kinetic, potential = _particle_energies(case, run.x, run.v, run.alive)
    ok = np.isfinite(kinetic) & np.isfinite(potential)
    if not ok.any():
        return float("nan")
    kinetic, potential = kinetic[ok], potential[ok]
    return _positive(max(float(np.max(kinetic)), float(np.max(potential) - np.min(potential))))


def path_at(case: Case) -> Callable[[np.ndarray], tuple] | None:
    """The case's reference path at times (k,) s: ``(Exact, alive (k, n) or None)``; ``None``
    without an exact solution."""
    if case.exact is None:
        return None
    from truestep.cases.exact import exact_named, reference_path_at

    if case.exact == "reference-run":
        return lambda t: reference_path_at(case, t)
    solution = exact_named(case.exact)
    if solution is None:
        raise ValueError(f"{case.name}: no exact solution named {case.exact!r}")
    return lambda t: (solution(case, t), None)
