"""The splitting methods of :mod:`~truestep.reference_impl.solvers.splitting`, compiled.

A splitting method's step is data (:class:`~truestep.reference_impl.solvers.splitting.Splitting`):
a kick of the velocity by ``kick h`` times the acceleration, a drift of the positions
``q' = q + h (old v + new v')`` by the velocities before and after it, and, when the kick is
a half (velocity Verlet), the other half kick at the new positions, whose acceleration the
next step reuses. :class:`KickDrift` and :class:`KickDriftKick` are those two shapes of
step as a compiled step reads them.
"""

from __future__ import annotations

from typing import NamedTuple

from numba import njit

from truestep.reference_impl.forces_kernels import KERNEL
from truestep.reference_impl.particles_kernels import accelerations
from truestep.reference_impl.tiles import CONTACT, FRESH, axpy, collisions, load, point_accel, store


@njit(**KERNEL)
def drift(method, x, v, u, h):
    """``x + h (old v + new u)`` of one component (m)."""
    return x + h * (method.old * v + method.new * u)


@njit(**KERNEL)
def kick_drift_point(method, x, v, a, h):
    """A particle's kick ``v' = v + h a`` and drift, on 3-tuples: ``(x', v')``."""
    u = (v[0] + h * a[0], v[1] + h * a[1], v[2] + h * a[2])
    return (drift(method, x[0], v[0], u[0], h), drift(method, x[1], v[1], u[1], h),
            drift(method, x[2], v[2], u[2], h)), u


@njit(**KERNEL)
def kick_drift_passes(method, scene, tile, t, h):
    """One kick and drift over a tile, the acceleration in passes at the step's start;
    then the collision pass. Returns the evaluations it made (1)."""
    X, V, A = tile.X, tile.V, tile.A
    accelerations(scene, A, tile.F, X, V, t, tile.contact, tile.count[CONTACT] > 0)
    for j in range(X.shape[1]):
        x, v = kick_drift_point(method, load(X, j), load(V, j), load(A, j), h)
        store(X, j, x)
        store(V, j, v)
    collisions(scene, tile, t + h, h)
    return 1


@njit(**KERNEL)
def kick_drift_point_step(method, scene, tile, x, v, t, h, p):
    """The kick and drift of particle ``p`` alone, its acceleration from the slot
    ``point_accel`` (a filling of :func:`tiles.point_step`)."""
    return kick_drift_point(method, x, v, point_accel(scene, tile, x, v, t, p), h)


class KickDrift(NamedTuple):
    """A whole kick, then the drift with weights ``old`` and ``new``: symplectic Euler
    (0, 1) and the lecture's update (1/2, 1/2); one ``evaluations`` a step. Twins:
    :meth:`SymplecticEuler.step`, :meth:`LectureUpdate.step`."""

    old: float
    new: float
    evaluations: int
    passes = kick_drift_passes
    carries_state = False

    def point_step(self):
        """The step of one particle (a filling of :func:`tiles.point_step`)."""
        return kick_drift_point_step

    def special_step(self):
        """The step of one special particle (a filling of :func:`tiles.special_step`)."""
        return kick_drift_point_step


@njit(**KERNEL)
def kick_drift_kick_passes(method, scene, tile, t, h):
    """Half a kick with the acceleration kept from the last step (evaluated afresh on the
    first step and after a collision pass that changed the state), the drift, the closing
    half kick at the new positions and the half-step velocities; then the collision pass.
    Returns the evaluations it made (1, or 2 afresh)."""
    X, V, VS, A = tile.X, tile.V, tile.VS, tile.A
    count = tile.count
    kick = method.kick * h
    first = 0 if count[FRESH] else 1
    for e in range(first, 2):  # e = 0: the fresh evaluation; e = 1: the closing one
        if e == 1:
            for j in range(X.shape[1]):
                x, v = load(X, j), load(V, j)
                u = axpy(v, kick, load(A, j))
                store(VS, j, u)
                store(X, j, (drift(method, x[0], v[0], u[0], h),
                             drift(method, x[1], v[1], u[1], h),
                             drift(method, x[2], v[2], u[2], h)))
        accelerations(scene, A, tile.F, X, V if e == 0 else VS, t + e * h, tile.contact,
                      count[CONTACT] > 0)
    for j in range(X.shape[1]):
        store(V, j, axpy(load(VS, j), kick, load(A, j)))
    count[FRESH] = collisions(scene, tile, t + h, h)
    return 2 - first


class KickDriftKick(NamedTuple):
    """Half kicks of ``kick`` h around the drift with weights ``old`` and ``new``, the
    closing acceleration reused: velocity Verlet. Twin: :meth:`VelocityVerlet.step`. It
    carries state from step to step over the whole scene (whether any particle's state
    changed between steps), so a scene is one tile."""

    kick: float
    old: float
    new: float
    passes = kick_drift_kick_passes
    carries_state = True
