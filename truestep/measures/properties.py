"""Named metrics a case can ask for (``properties = [...]``) and gate on.

Each property is a pure function ``(case, trajectory) -> float`` of the case and one
run's :class:`~truestep.adapters.base.Trajectory` (positions, velocities and, for emitter scenes,
the ``alive`` mask at every record), whichever engine produced it. Units are in each
docstring; ``nan`` means the property does not apply to the run, ``inf`` that what it
measures never happened (a bounce that was never seen).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import cast

import numpy as np

from truestep.adapters.base import Trajectory
from truestep.cases.case import Case
from truestep.cases.exact_particles import bounce_schedule
from truestep.cases.property_names import PROPERTY_KINDS
from truestep.measures.restitution import bounces, heights
from truestep.reference_impl.emitters import lifetime_values, pool_starts, spawn_count_moments, spawn_mean
from truestep.reference_impl.meshes import signed_volume
from truestep.reference_impl.strands import ballistic_deviation, collect_strands

Property = Callable[[Case, Trajectory], float]
PROPERTIES: dict[str, Property] = {}


FAILURES = {"tunnelled": "tunnelled"}
"""Properties whose non-zero value means the run failed at what the scene tests, even
though it finished: property name -> the word a report uses for that failure."""


def register(fn: Property) -> Property:
    """Add ``fn`` to :data:`PROPERTIES` under its own name, which the cases' vocabulary
    (:data:`~truestep.cases.property_names.PROPERTY_KINDS`) must list."""
    if fn.__name__ not in PROPERTY_KINDS:
        raise ValueError(f"{fn.__name__} is not a property name of truestep.cases.property_names")
    PROPERTIES[fn.__name__] = fn
    return fn


def _alive(case: Case, traj: Trajectory) -> np.ndarray:
    """Particles that exist and move, (T, n) bool."""
    moving = ~case.particles.fixed[None, :]
    if traj.alive is None:
        return np.broadcast_to(moving, traj.x.shape[:2])
    return traj.alive & moving


@register
def momentum_drift(case: Case, traj: Trajectory) -> float:
    """Largest error of the total linear momentum after the impulses, relative:
    ``max |P(t) - P_exact| / P_scale`` over the records from the end of the last impulse.

    ``P = sum m v`` over live, unpinned particles. Internal forces (springs, dampers,
    gravitation) conserve it, so ``P_exact = P(0) + sum_k F_k (t_off,k - t_on,k)``: the
    start's momentum plus every impulse the case applies (and ``M g t`` under uniform
    gravity), which a method must both deliver and keep. ``P_scale`` is the largest of
    ``|P_exact|``, the momentum magnitude ``sum m |v|`` at that record and, if the case's
    ``[reference]`` table gives ``v_scale`` (m/s), ``M v_scale`` (1 kg m/s if all are 0).
    NaN for scenes with external forces besides gravity and impulses (drag, anchors,
    planes, fields, pinned particles, emitters).
    """
    m = case.particles
    if m.drag or len(m.anchors) or m.planes or m.fields or m.emitters or np.any(m.fixed):
        return float("nan")
    live = _alive(case, traj)
    p = np.einsum("tn,n,tni->ti", live, m.mass, cast(np.ndarray, traj.v))
    t0 = max((end for _, _, _, end in m.impulses), default=0.0)
    k0 = int(np.searchsorted(traj.t, t0 - 1e-9 * max(1.0, t0)))
    if k0 >= len(traj.t):
        return float("nan")
    delivered = sum((force * (t_off - t_on) for _, force, t_on, t_off in m.impulses), np.zeros(3))
    exact = (m.mass @ m.v0) + delivered + m.mass.sum() * m.gravity * traj.t[k0:, None]
    mass = np.where(live[k0], m.mass, 0.0)
    scale = max(
        float(np.max(np.linalg.norm(exact, axis=1))),
        float(mass @ np.linalg.norm(cast(np.ndarray, traj.v)[k0], axis=1)),
        float(mass.sum()) * float(case.exact_params.get("v_scale", 0.0)),
    )
    return float(np.max(np.linalg.norm(p[k0:] - exact, axis=1)) / (scale or 1.0))


@register
def min_signed_volume(case: Case, traj: Trajectory) -> float:
    """Smallest signed volume of any closed mesh of the scene over the run, relative to its
    start (1: unchanged, 0: collapsed flat, negative: turned inside out)."""
    surfaces = case.particles.surfaces
    if not surfaces:
        return float("nan")
    worst = np.inf
    for faces in surfaces:
        vol = signed_volume(traj.x, faces)
        worst = min(worst, float(np.min(vol / vol[0])))
    return worst


@register
def max_penetration(case: Case, traj: Trajectory) -> float:
    """Deepest penetration of any live particle's contact point ``X - r N`` below any plane, m.

    0 when nothing ever went below a plane.
    """
    m = case.particles
    live = _alive(case, traj)
    deepest = 0.0
    for plane in m.planes:
        d = (traj.x - plane.point) @ plane.normal - m.radius[None, :]
        deepest = max(deepest, float(np.max(np.where(live, -d, 0.0), initial=0.0)))
    return deepest


@register
def final_speed(case: Case, traj: Trajectory) -> float:
    """Largest speed of any live particle at the last record, m/s (a settled scene: ~0)."""
    live = _alive(case, traj)[-1]
    speed = np.linalg.norm(cast(np.ndarray, traj.v)[-1], axis=1)
    return float(np.max(speed[live], initial=0.0))


@register
def max_strain(case: Case, traj: Trajectory) -> float:
    """Largest relative length change ``| |x_i - x_j| / r - 1 |`` of any spring over the run."""
    s = case.particles.springs
    if not len(s):
        return float("nan")
    length = np.linalg.norm(traj.x[:, s.i] - traj.x[:, s.j], axis=2)
    return float(np.max(np.abs(length / s.rest - 1.0)))


@register
def stopping_distance_error(case: Case, traj: Trajectory) -> float:
    """``|s - v0^2 / (2 mu g)|``, m: distance slid by particle 0 on plane 0 (to the last
    record) against the exact stopping distance under Coulomb friction ``mu``."""
    m = case.particles
    plane = m.planes[0]
    g = float(-(m.gravity @ plane.normal))
    v0 = m.v0[0] - (m.v0[0] @ plane.normal) * plane.normal
    if plane.friction <= 0 or g <= 0:
        return float("nan")
    moved = traj.x[-1, 0] - m.x0[0]
    slid = float(np.linalg.norm(moved - (moved @ plane.normal) * plane.normal))
    return abs(slid - float(v0 @ v0) / (2.0 * plane.friction * g))


def _arcs(case: Case, traj: Trajectory) -> tuple[np.ndarray, np.ndarray, float]:
    """Apex heights (m) and bounce times (s) of the flights of particle 0 off plane 0, as
    the run shows them, and the normal gravity g (m/s^2).

    The bounces are the contacts that :func:`truestep.measures.restitution.bounces` finds (for
    every engine the same detector as the restitution table's): each flight's apex is the
    highest height it reached at a recorded step, each bounce's time that of the
    contact's lowest sample. Both need every step recorded (the case's ``max_records`` at
    least its steps): a run recorded more sparsely gives NaN, not a guess.
    """
    m = case.particles
    plane = m.planes[0]
    g = float(-(m.gravity @ plane.normal))
    if traj.steps and len(traj.t) < traj.steps + 1:
        return np.full(0, np.nan), np.full(0, np.nan), float("nan")
    h, vn = heights(
        traj.x[:, 0], cast(np.ndarray, traj.v)[:, 0], plane.point, plane.normal, float(m.radius[0])
    )
    flights = [b for b in bounces(traj.t, h, vn, g) if b.v_out > 0]
    return (np.array([b.apex for b in flights]), np.array([b.t_low for b in flights]), g)


def _bounces(case: Case) -> int:
    return int(case.exact_params.get("bounces", 3))


@register
def apex_height_error(case: Case, traj: Trajectory) -> float:
    """Largest relative error of the first ``bounces`` apex heights the run reached against
    the exact ``e^(2n) h_0``.

    ``bounces`` comes from the case's ``[reference]`` table (default 3); ``inf`` when the
    run shows fewer bounces; NaN when it was not recorded at every step.
    """
    apex, _, g = _arcs(case, traj)
    if not np.isfinite(g):
        return float("nan")
    k = _bounces(case)
    if len(apex) < k:
        return float("inf")
    m = case.particles
    plane = m.planes[0]
    u0 = float((m.x0[0] - plane.point) @ plane.normal - m.radius[0])
    _, launches = bounce_schedule(u0, float(m.v0[0] @ plane.normal), g, plane.restitution, float(traj.t[-1]))
    exact = launches[:k] ** 2 / (2 * g)
    return float(np.max(np.abs(apex[:k] / exact - 1.0)))


@register
def bounce_time_error(case: Case, traj: Trajectory) -> float:
    """Largest error of the first ``bounces`` bounce times (each contact's lowest sample)
    against the exact impacts, s (``inf`` if fewer were seen; NaN when the run was not
    recorded at every step)."""
    _, when, g = _arcs(case, traj)
    if not np.isfinite(g):
        return float("nan")
    k = _bounces(case)
    if len(when) < k:
        return float("inf")
    m = case.particles
    plane = m.planes[0]
    u0 = float((m.x0[0] - plane.point) @ plane.normal - m.radius[0])
    times, _ = bounce_schedule(u0, float(m.v0[0] @ plane.normal), g, plane.restitution, float(traj.t[-1]))
    return float(np.max(np.abs(when[:k] - times[:k])))


def _frames(spec, t: np.ndarray) -> np.ndarray:
    """Frames begun by each record time (frame 0 begins at t = 0)."""
    return np.floor(t / spec.frame_dt + 1e-9).astype(int)


def _emitter_pools(case: Case, traj: Trajectory):
    m = case.particles
    if not m.emitters or traj.alive is None:
        return []
    return [
        (spec, traj.alive[:, first : first + spec.capacity])
        for spec, first in zip(m.emitters, pool_starts(m), strict=True)
    ]


@register
def spawn_rate_z(case: Case, traj: Trajectory) -> float:
    """z-score of the particles spawned over the run against ``n + r/2`` per frame.

    Spawns are slots that turn alive between records (plus those alive at the start);
    with ``F`` frames begun, ``z = (S - F mu) / sqrt(F sigma^2)`` with ``mu``, ``sigma^2``
    of :func:`~truestep.reference_impl.emitters.spawn_count_moments`. The worst emitter's z.
    """
    worst = float("nan")
    for spec, alive in _emitter_pools(case, traj):
        spawned = int(alive[0].sum() + (alive[1:] & ~alive[:-1]).sum())
        frames = int(_frames(spec, traj.t)[-1]) + 1
        mu, var = spawn_count_moments(spawn_mean(spec), spec.rate_r)
        z = (spawned - frames * mu) / np.sqrt(frames * var)
        if np.isnan(worst) or abs(z) > abs(worst):
            worst = float(z)
    return worst


@register
def population_z(case: Case, traj: Trajectory) -> float:
    """z-score of the mean live population in steady state against ``rate x lifetime``.

    Frames from ``lifetime + jitter`` on (when the first particles have all expired) to
    the end are sampled once each (at their last record). A particle spawned at frame
    ``i`` with lifetime ``l`` is alive at frames ``i .. i + l - 1``; with ``c_i`` the number
    of sampled frames such a particle is counted in, the sum of the samples has mean
    ``sum_i mu E[c_i]`` (= ``mu E[l]`` per frame) and variance
    ``sum_i (mu Var[c_i] + sigma^2 E[c_i]^2)`` over spawn frames ``i`` (independent counts
    and lifetimes). The worst emitter's z.
    """
    worst = float("nan")
    for spec, alive in _emitter_pools(case, traj):
        frames = _frames(spec, traj.t)
        lives = lifetime_values(spec)
        k0 = int(lives.max())
        last = np.flatnonzero(np.r_[frames[1:] != frames[:-1], True])  # last record of a frame
        sampled = last[frames[last] >= k0]
        if not len(sampled):
            continue
        ks = frames[sampled]
        pop = alive[sampled].sum(axis=1)
        mu, var = spawn_count_moments(spawn_mean(spec), spec.rate_r)
        spawn_frames = np.arange(max(0, ks[0] - k0 + 1), ks[-1] + 1)
        end = spawn_frames[:, None] + lives[None, :] - 1
        counts = (
            np.searchsorted(ks, end, side="right") - np.searchsorted(ks, spawn_frames, side="left")[:, None]
        )
        c_mean, c_var = counts.mean(axis=1), counts.var(axis=1)
        expect = mu * c_mean.sum()
        spread = np.sqrt(np.sum(mu * c_var + var * c_mean**2))
        z = (float(pop.sum()) - expect) / spread
        if np.isnan(worst) or abs(z) > abs(worst):
            worst = float(z)
    return worst


@register
def strand_error(case: Case, traj: Trajectory) -> float:
    """Largest distance of any strand point from the exact free flight of its root, m.

    Strands (static particles) are the recorded lives of the emitter's particles; under
    uniform gravity and drag alone each lies on the curve fixed by its first point and
    velocity (:func:`~truestep.reference_impl.strands.ballistic_deviation`).
    """
    m = case.particles
    if traj.alive is None or not m.emitters:
        return float("nan")
    strands = collect_strands(traj.t, traj.x, cast(np.ndarray, traj.v), traj.alive)
    if not len(strands):
        return float("nan")
    dev = ballistic_deviation(strands, m.gravity, m.drag, m.emitters[0].particle_mass)
    return float(np.max(dev))


@register
def strand_count(case: Case, traj: Trajectory) -> float:
    """Number of strands (particle lives) recorded: every spawned particle gives one."""
    if traj.alive is None:
        return float("nan")
    return float(len(collect_strands(traj.t, traj.x, cast(np.ndarray, traj.v), traj.alive)))


@register
def tunnelled(case: Case, traj: Trajectory) -> float:
    """How many particles end the run behind a thin wall they started in front of.

    A particle is behind a wall when its centre lies beyond the wall's back face,
    ``(X - P) . N < -thickness``; only planes with a thickness count.
    """
    m = case.particles
    count = 0
    for plane in m.planes:
        if plane.thickness <= 0:
            continue
        start = (traj.x[0] - plane.point) @ plane.normal
        end = (traj.x[-1] - plane.point) @ plane.normal
        count += int(np.sum((start > 0) & (end < -plane.thickness)))
    return float(count)
