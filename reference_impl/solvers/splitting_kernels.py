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

from truestep.reference_impl.class_kernels import carries
from truestep.reference_impl.forces_kernels import KERNEL, LEAF
from truestep.reference_impl.tiles import FRESH, axpy, load, point_accel, store


@njit(**LEAF)
def drift(method, x, v, u, h):
    """``x + h (old v + new u)`` of one component (m)."""
    return x + h * (method.old * v + method.new * u)


@njit(**LEAF)
def kick_drift_point(method, x, v, a, h):
    """A particle's kick ``v' = v + h a`` and drift, on 3-tuples: ``(x', v')``."""
    u = (v[0] + h * a[0], v[1] + h * a[1], v[2] + h * a[2])
    return (
        drift(method, x[0], v[0], u[0], h),
        drift(method, x[1], v[1], u[1], h),
        drift(method, x[2], v[2], u[2], h),
    ), u


@njit(**KERNEL)
def kick_drift_finish(method, tile, h):
    """A kick and drift over a tile in passes, its acceleration ``A`` evaluated at the
    step's start."""
    X, V, A = tile.X, tile.V, tile.A
    for j in range(X.shape[1]):
        x, v = kick_drift_point(method, load(X, j), load(V, j), load(A, j), h)
        store(X, j, x)
        store(V, j, v)


@njit(**KERNEL)
def kick_drift_point_step(method, special, scene, tile, x, v, t, h, p):
    """The kick and drift of particle ``p`` alone, its acceleration a ``special``
    particle's or not (:func:`tiles.point_accel`)."""
    return kick_drift_point(method, x, v, point_accel(special, scene, tile, x, v, t, p), h)


@carries(carries_state=False)
class KickDrift(NamedTuple):
    """A whole kick, then the drift with weights ``old`` and ``new``: symplectic Euler
    (0, 1) and the lecture's update (1/2, 1/2); one ``evaluations`` a step. Twins:
    :meth:`SymplecticEuler.step`, :meth:`LectureUpdate.step`."""

    old: float
    new: float
    evaluations: int


@njit(**KERNEL)
def kick_drift_kick_input(method, e, tile, t, h):
    """What evaluation ``e`` of velocity Verlet's step in passes evaluates: (where its
    accelerations go, positions, velocities, time). ``e = 0``, the acceleration at the
    step's start (evaluated afresh on the first step and after a collision pass that
    changed the state; else the last step's is kept); ``e = 1``, at the new positions
    after the half kick (into ``VS``) and the drift, and the half-step velocities."""
    X, V, VS, A = tile.X, tile.V, tile.VS, tile.A
    if e == 0:
        return A, X, V, t
    kick = method.kick * h
    for j in range(X.shape[1]):
        x, v = load(X, j), load(V, j)
        u = axpy(v, kick, load(A, j))
        store(VS, j, u)
        store(
            X,
            j,
            (
                drift(method, x[0], v[0], u[0], h),
                drift(method, x[1], v[1], u[1], h),
                drift(method, x[2], v[2], u[2], h),
            ),
        )
    return A, X, VS, t + h


@njit(**KERNEL)
def kick_drift_kick_finish(method, tile, h):
    """The closing half kick of velocity Verlet's step from the half-step velocities."""
    X, V, VS, A = tile.X, tile.V, tile.VS, tile.A
    kick = method.kick * h
    for j in range(X.shape[1]):
        store(V, j, axpy(load(VS, j), kick, load(A, j)))


@njit(**KERNEL)
def kick_drift_kick_point(method, special, scene, tile, x, v, t, h, p, a):
    """Velocity Verlet's step of particle ``p`` alone from ``x``, ``v`` with ``a``, the
    acceleration at the step's start: the half kick, the drift, the closing acceleration
    (kept in column ``p`` of ``A`` for the next step) and the closing half kick."""
    kick = method.kick * h
    u = axpy(v, kick, a)
    y = (
        drift(method, x[0], v[0], u[0], h),
        drift(method, x[1], v[1], u[1], h),
        drift(method, x[2], v[2], u[2], h),
    )
    closing = point_accel(special, scene, tile, y, u, t + h, p)
    store(tile.A, p, closing)
    return y, axpy(u, kick, closing)


@njit(**KERNEL)
def kick_drift_kick_point_step(method, special, scene, tile, x, v, t, h, p):
    """Velocity Verlet's step of particle ``p`` alone, its acceleration a ``special``
    particle's or not (:func:`tiles.point_accel`): the acceleration at the start evaluated afresh when the
    step is (:data:`tiles.FRESH`), else the one kept in ``A``."""
    if tile.count[FRESH]:
        return kick_drift_kick_point(
            method, special, scene, tile, x, v, t, h, p, point_accel(special, scene, tile, x, v, t, p)
        )
    return kick_drift_kick_point(method, special, scene, tile, x, v, t, h, p, load(tile.A, p))


@njit(**KERNEL)
def kick_drift_kick_special_step(method, special, scene, tile, x, v, t, h, p):
    """:func:`kick_drift_kick_point_step` of a special particle, stepped again from the
    step's start: its kept acceleration is where the fused step saved it (``F``)."""
    if tile.count[FRESH]:
        return kick_drift_kick_point(
            method, special, scene, tile, x, v, t, h, p, point_accel(special, scene, tile, x, v, t, p)
        )
    return kick_drift_kick_point(method, special, scene, tile, x, v, t, h, p, load(tile.F, p))


@carries(carries_state=True)
class KickDriftKick(NamedTuple):
    """Half kicks of ``kick`` h around the drift with weights ``old`` and ``new``, the
    closing acceleration reused: velocity Verlet. Twin: :meth:`VelocityVerlet.step`. It
    carries state from step to step over the whole scene (whether any particle's state
    changed between steps), so a scene is one tile."""

    kick: float
    old: float
    new: float
