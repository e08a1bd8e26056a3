"""The force kinds of :mod:`~truestep.reference_impl.forces`, compiled: one kernel per kind.

The numpy functions of :mod:`~truestep.reference_impl.forces` are the spec and the oracle;
each kind is written here once more as the loop a compiled step runs, with the same
arithmetic in the same order, so that both give the same bits (tested on every case and
method). Newton's ``solvers/euler/kernels.py`` is the model: one kernel per kind, and a
step that calls the kinds its scene has.

A compiled scene declares its forces as a tuple of kinds, in the order of
:func:`~truestep.reference_impl.forces.add_model_forces`. A kind is a ``NamedTuple`` of its
parameters whose class names its kernels, which numba picks by the kind's type when it
compiles a step (:mod:`~truestep.reference_impl.by_type`), never by a test at run time:

``add(kind, F, X, V, t, particles)``
    add its force on every particle of a tile into ``F``;
``at(kind, f, x, v, t, particles, p)``
    (pointwise kinds, which act on each particle alone) the force ``f`` on particle ``p``
    with its own added, as a 3-tuple;
``energy(kind, X, particles)``
    its potential energy, J (kinds without one: ``0.0``);
``cut(kind, lo, hi)``
    (pointwise kinds) the kind for the tile of particles ``lo`` to ``hi``.

Arrays are component-major: positions ``X`` (m), velocities ``V`` (m/s) and forces ``F``
(N) have shape ``(3, m)`` for the ``m`` particles of a tile; ``particles`` is a
:class:`~truestep.reference_impl.particles_kernels.Particles` of the tile. Vectors of one
particle are 3-tuples. The numpy path calls the spring kernels on its ``(n, 3)`` arrays
transposed.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from truestep.reference_impl.class_kernels import carries

TIME_ROUNDOFF = 1e-9
"""Relative margin on the ends of an impulse's window: a step time made by repeated
addition (``4 x 0.0025 = 0.009999999999999998``) counts as the time it stands for."""

KERNEL: dict[str, Any] = {"cache": True, "error_model": "numpy", "inline": "always"}
"""How a kernel of a step's hot path is compiled: into the step that calls it (numba
inlines it before it types the step: a call costs nothing), or on its own and cached when
Python calls it; division by zero gives ``inf`` or ``nan`` as numpy does, never an
exception."""
LEAF: dict[str, Any] = {"cache": True, "error_model": "numpy", "_nrt": False}
"""How a kernel off the hot path of a step is compiled (a collision response, an
energy): once, on its own, cached, and called, so that compiling a step does not
compile it again; without reference counting (a loop has none, :data:`LOOP`). A kernel
in the hot path is inlined (:data:`KERNEL`): a call with its arrays would cost more than
its arithmetic."""

COLD: dict[str, Any] = {"cache": True, "error_model": "numpy", "_nrt": False}
"""How the rarely called parts of a loop are compiled (a tile's start, a collision pass, a
particle stepped again alone, the stop after a blow-up): on their own, called, so that
numba does not copy them into the loop (it copies a function it inlines once for every
place that calls it, a cost that grows with the square of the loop's size)."""
LOOP: dict[str, Any] = {"cache": True, "error_model": "numpy", "_nrt": False, "nogil": True}
"""How a whole loop is compiled: cached on disk, without numba's reference counting (its
arrays all come from Python, which holds them while it runs; it allocates none), so that
passing arrays between the functions it is made of costs nothing, and without Python's
lock while it runs, so that threads may step a run's tiles at once."""


@njit(**KERNEL)
def uncut(kind, lo, hi):
    """A pointwise kind whose parameters are the same for every particle, on a tile."""
    return kind


@njit(**LEAF)
def no_energy(kind, X, particles):
    """The potential energy of a kind that has none (drag, impulses): 0 J."""
    return 0.0


@njit(**LEAF)
def gravity_at(kind, f, x, v, t, particles, p):
    """Uniform gravity ``f += m g`` on particle ``p``: :func:`forces.add_gravity`."""
    m = particles.mass[p]
    g = kind.g
    return (f[0] + m * g[0], f[1] + m * g[1], f[2] + m * g[2])


@njit(**LEAF)
def gravity_energy(kind, X, particles):
    """``-sum m g . x`` of the movable particles, J: the gravity term of
    :func:`particles.total_energy`."""
    g = kind.g
    e = 0.0
    for p in range(X.shape[1]):
        e -= particles.moving_mass[p] * (X[0, p] * g[0] + X[1, p] * g[1] + X[2, p] * g[2])
    return e


@njit(**KERNEL)
def gravity_add(kind, F, X, V, t, particles):
    """:func:`gravity_at` on every particle of the tile."""
    for p in range(F.shape[1]):
        F[0, p], F[1, p], F[2, p] = gravity_at(kind, (F[0, p], F[1, p], F[2, p]), None, None, t, particles, p)


@carries(pointwise=True, at=gravity_at, add=gravity_add, energy=gravity_energy, cut=uncut)
class Gravity(NamedTuple):
    """Uniform gravity; ``g`` (3-tuple, m/s^2) not zero. Twin: :func:`forces.add_gravity`."""

    g: tuple[float, float, float]


@njit(**LEAF)
def drag_at(kind, f, x, v, t, particles, p):
    """Viscous drag ``f -= k v`` on particle ``p``: :func:`forces.add_drag`."""
    k = kind.k
    return (f[0] - k * v[0], f[1] - k * v[1], f[2] - k * v[2])


@njit(**KERNEL)
def drag_add(kind, F, X, V, t, particles):
    """:func:`drag_at` on every particle of the tile."""
    for p in range(F.shape[1]):
        F[0, p], F[1, p], F[2, p] = drag_at(
            kind, (F[0, p], F[1, p], F[2, p]), None, (V[0, p], V[1, p], V[2, p]), t, particles, p
        )


@carries(pointwise=True, at=drag_at, add=drag_add, energy=no_energy, cut=uncut)
class Drag(NamedTuple):
    """Viscous drag; ``k`` (N s/m) not zero. Twin: :func:`forces.add_drag`."""

    k: float


@njit(**LEAF)
def spring_force(d, u, stiffness, damping, rest):
    """The lecture's damped spring (:func:`forces.spring_forces`) for one spring: the
    force (N, 3-tuple) on its first end, from ``d = x_1 - x_2`` (m) and ``u = v_1 - v_2``
    (m/s); ``None``-like zero length is reported by ``length == 0`` (no force then).
    Returns ``(length, f)``."""
    length = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    e0, e1, e2 = d[0] / length, d[1] / length, d[2] / length
    magnitude = stiffness * (length - rest) + damping * (u[0] * e0 + u[1] * e1 + u[2] * e2)
    return length, (magnitude * e0, magnitude * e1, magnitude * e2)


@njit(**KERNEL)
def add_spring_forces(F, X, V, i, j, stiffness, damping, rest):
    """Damped springs between particles ``i[s]`` and ``j[s]`` (int, (m,)): the force of
    :func:`spring_force` subtracted at the first end and added at the second, spring after
    spring; a zero-length spring exerts nothing. Twin: :func:`forces.add_springs`."""
    for s in range(i.shape[0]):
        a, b = i[s], j[s]
        d = (X[0, a] - X[0, b], X[1, a] - X[1, b], X[2, a] - X[2, b])
        u = (V[0, a] - V[0, b], V[1, a] - V[1, b], V[2, a] - V[2, b])
        length, f = spring_force(d, u, stiffness[s], damping[s], rest[s])
        if length == 0.0:
            continue
        F[0, a] -= f[0]
        F[1, a] -= f[1]
        F[2, a] -= f[2]
        F[0, b] += f[0]
        F[1, b] += f[1]
        F[2, b] += f[2]


@njit(**KERNEL)
def add_anchor_forces(F, X, V, i, point, stiffness, damping, rest):
    """Damped springs from particles ``i[s]`` to the fixed points ``point[:, s]`` (m,
    (3, m)): the force of :func:`spring_force` subtracted at the particle. Twin:
    :func:`forces.add_anchors`."""
    for s in range(i.shape[0]):
        a = i[s]
        d = (X[0, a] - point[0, s], X[1, a] - point[1, s], X[2, a] - point[2, s])
        u = (V[0, a], V[1, a], V[2, a])
        length, f = spring_force(d, u, stiffness[s], damping[s], rest[s])
        if length == 0.0:
            continue
        F[0, a] -= f[0]
        F[1, a] -= f[1]
        F[2, a] -= f[2]


@njit(**KERNEL)
def springs_add(kind, F, X, V, t, particles):
    """:func:`add_spring_forces` for a :class:`Springs` kind."""
    add_spring_forces(F, X, V, kind.i, kind.j, kind.stiffness, kind.damping, kind.rest)


@njit(**LEAF)
def stretch_energy(d0, d1, d2, stiffness, rest):
    """``k (|d| - r)^2 / 2`` of one spring stretched to ``d`` (m), J."""
    stretch = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) - rest
    return 0.5 * (stiffness * stretch * stretch)


@njit(**LEAF)
def springs_energy(kind, X, particles):
    """:func:`forces.spring_energy`, J."""
    e = 0.0
    for s in range(kind.i.shape[0]):
        a, b = kind.i[s], kind.j[s]
        e += stretch_energy(
            X[0, a] - X[0, b], X[1, a] - X[1, b], X[2, a] - X[2, b], kind.stiffness[s], kind.rest[s]
        )
    return e


@carries(pointwise=False, add=springs_add, energy=springs_energy)
class Springs(NamedTuple):
    """Damped springs between particle pairs (int64 ``i``, ``j``; float64 ``stiffness``
    N/m, ``damping`` N s/m, ``rest`` m; all (m,)). Twin: :func:`forces.add_springs`."""

    i: np.ndarray
    j: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    rest: np.ndarray


@njit(**KERNEL)
def anchors_add(kind, F, X, V, t, particles):
    """:func:`add_anchor_forces` for an :class:`Anchors` kind."""
    add_anchor_forces(F, X, V, kind.i, kind.point, kind.stiffness, kind.damping, kind.rest)


@njit(**LEAF)
def anchors_energy(kind, X, particles):
    """:func:`forces.anchor_energy`, J."""
    e = 0.0
    for s in range(kind.i.shape[0]):
        a = kind.i[s]
        e += stretch_energy(
            X[0, a] - kind.point[0, s],
            X[1, a] - kind.point[1, s],
            X[2, a] - kind.point[2, s],
            kind.stiffness[s],
            kind.rest[s],
        )
    return e


@njit(**KERNEL)
def anchors_at(kind, f, x, v, t, particles, p):
    """The anchored springs of particle ``p`` alone (entries ``start[p]`` to
    ``start[p + 1]`` of ``order``, in the case's order) subtracted from ``f``: what
    :func:`add_anchor_forces` does to it, the same sums in the same order."""
    f0, f1, f2 = f
    point = kind.point
    for q in range(kind.start[p], kind.start[p + 1]):
        s = kind.order[q]
        d = (x[0] - point[0, s], x[1] - point[1, s], x[2] - point[2, s])
        length, g = spring_force(d, v, kind.stiffness[s], kind.damping[s], kind.rest[s])
        if length == 0.0:
            continue
        f0 -= g[0]
        f1 -= g[1]
        f2 -= g[2]
    return (f0, f1, f2)


@njit(**KERNEL)
def anchors_cut(kind, lo, hi):
    """The anchors of particles ``lo`` to ``hi`` of a tile, numbered from ``lo``."""
    return Anchors(
        kind.i, kind.point, kind.stiffness, kind.damping, kind.rest, kind.start[lo : hi + 1], kind.order
    )


@carries(pointwise=True, at=anchors_at, add=anchors_add, energy=anchors_energy, cut=anchors_cut)
class Anchors(NamedTuple):
    """Damped springs from particles ``i`` (int64, (m,)) to fixed points ``point`` (m,
    (3, m)); ``stiffness``, ``damping``, ``rest`` as :class:`Springs`. An anchor acts on
    its particle alone, so the kind is pointwise: particle ``p``'s anchors are entries
    ``start[p]`` to ``start[p + 1]`` (int64, (n + 1,)) of ``order`` (int64, (m,): the
    anchors grouped by particle, each particle's in the case's order). Twin:
    :func:`forces.add_anchors`."""

    i: np.ndarray
    point: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    rest: np.ndarray
    start: np.ndarray
    order: np.ndarray


@njit(**KERNEL)
def gravitation_add(kind, F, X, V, t, particles):
    """Universal gravitation between all pairs, softened: :func:`forces.add_gravitation`.
    For each particle the pulls of the others are summed in their order, then times its
    mass added into ``F``."""
    n = X.shape[1]
    eps2 = kind.softening * kind.softening
    mass = particles.mass
    for p in range(n):
        g0 = 0.0
        g1 = 0.0
        g2 = 0.0
        for q in range(n):
            if q == p:
                continue
            d0 = X[0, q] - X[0, p]
            d1 = X[1, q] - X[1, p]
            d2 = X[2, q] - X[2, p]
            r2 = d0 * d0 + d1 * d1 + d2 * d2 + eps2
            w = kind.G * mass[q] / (r2 * math.sqrt(r2))
            g0 += w * d0
            g1 += w * d1
            g2 += w * d2
        F[0, p] += mass[p] * g0
        F[1, p] += mass[p] * g1
        F[2, p] += mass[p] * g2


@njit(**LEAF)
def gravitation_energy(kind, X, particles):
    """``-sum_{p<q} G m_p m_q / sqrt(r^2 + eps^2)``, J: :func:`forces.gravitation_energy`."""
    eps2 = kind.softening * kind.softening
    mass = particles.mass
    e = 0.0
    for p in range(X.shape[1]):
        for q in range(p + 1, X.shape[1]):
            d0 = X[0, p] - X[0, q]
            d1 = X[1, p] - X[1, q]
            d2 = X[2, p] - X[2, q]
            e -= kind.G * mass[p] * mass[q] / math.sqrt(d0 * d0 + d1 * d1 + d2 * d2 + eps2)
    return e


@carries(pointwise=False, add=gravitation_add, energy=gravitation_energy)
class Gravitation(NamedTuple):
    """Universal gravitation: ``G`` (m^3 kg^-1 s^-2), Plummer ``softening`` (m). Twin:
    :func:`forces.add_gravitation`."""

    G: float
    softening: float


@njit(**KERNEL)
def impulse_at(kind, f, x, v, t, particles, p):
    """The impulse forces on particle ``p`` acting at ``t`` (s) added to ``f``, in their
    order in the case: :func:`forces.add_impulses` with :func:`forces.impulse_active`."""
    eps = TIME_ROUNDOFF * max(1.0, abs(t))
    f0, f1, f2 = f
    for k in range(kind.start[p], kind.start[p + 1]):
        if kind.on[k] - eps <= t < kind.off[k] - eps:
            f0 += kind.force[0, k]
            f1 += kind.force[1, k]
            f2 += kind.force[2, k]
    return (f0, f1, f2)


@njit(**KERNEL)
def impulses_add(kind, F, X, V, t, particles):
    """:func:`impulse_at` on every particle of the tile that has impulses."""
    for q in range(kind.kicked.shape[0]):
        p = kind.kicked[q] - kind.first
        F[0, p], F[1, p], F[2, p] = impulse_at(kind, (F[0, p], F[1, p], F[2, p]), None, None, t, particles, p)


@njit(**KERNEL)
def impulses_cut(kind, lo, hi):
    """The impulses of particles ``lo`` to ``hi`` of a tile, numbered from ``lo``."""
    k = kind.kicked
    a, b = np.searchsorted(k, lo), np.searchsorted(k, hi)
    return Impulses(kind.start[lo : hi + 1], kind.force, kind.on, kind.off, k[a:b], lo)


@carries(pointwise=True, at=impulse_at, add=impulses_add, energy=no_energy, cut=impulses_cut)
class Impulses(NamedTuple):
    """Forces on single particles over time windows, grouped by particle (each particle's
    in the case's order): particle ``p``'s are entries ``start[p]`` to ``start[p + 1]``
    (int64, (m + 1,) for a tile of m particles) of ``force`` (N, (3, k)), ``on`` and
    ``off`` (s, (k,)); ``kicked`` (int64, ascending): the particles that have any,
    numbered in the scene, of which the tile's first is ``first``. Twin:
    :func:`forces.add_impulses`."""

    start: np.ndarray
    force: np.ndarray
    on: np.ndarray
    off: np.ndarray
    kicked: np.ndarray
    first: int
