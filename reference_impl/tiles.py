"""How a compiled step lays out its particles: tiles, and the collision pass of each layout.

A tile is a run of particles whose state a step holds component-major (positions ``X``
and velocities ``V`` of shape (3, m), with its scratch: :class:`Tile`). A scene whose
particles act on one another is one tile; a scene whose particles do not is cut into
tiles of :data:`BLOCK` particles, and the driver (:mod:`~truestep.reference_impl.integrate_kernels`)
takes each tile through every step before the next (temporal blocking: the tile stays in
the cache). A tile is stepped in one of two layouts, chosen when a run is packed
(:mod:`~truestep.reference_impl.compiled`):

:class:`Passes`
    any scene: the derivative in passes over the tile (clear, each force kind, impulses,
    contact, divide), then the method's update, then the collision pass of
    :class:`~truestep.reference_impl.collisions.PlaneCollisions` over the tile.
:class:`Fused`
    scenes whose forces are all pointwise (gravity, drag, anchors, impulses): each
    particle's whole step, every stage, in one loop the compiler vectorises
    (:func:`fused_step`, with the method's step of one particle), the rare particles that
    rest on a plane or feel an impulse (the tile's *special* particles) stepped again
    alone; the collision pass then visits only the particles near a plane or resting on
    one.

Both collide a particle with :func:`collisions_kernels.collide` and nothing else.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from numba.core import types
from numba.extending import overload

from truestep.reference_impl.by_type import BY_TYPE, fold, is_none
from truestep.reference_impl.class_kernels import carries
from truestep.reference_impl.collisions import EPS_DISTANCE
from truestep.reference_impl.collisions_kernels import collide, signed_distance, within
from truestep.reference_impl.forces_kernels import COLD, KERNEL, LEAF
from truestep.reference_impl.particles_kernels import (
    applied_forces,
    particle_force,
    point_force,
    resting_force,
    scaled,
)

BLOCK = 256
"""Particles of a tile of independent particles: its state and scratch (about 100 bytes
a particle) stay in the L1 cache through all its steps."""

SPECIAL, FRESH, CONTACT, VISITED = 0, 1, 2, 3
"""Entries of :attr:`Tile.count`: how many special particles ``special`` lists (fused);
whether the next step evaluates its first acceleration afresh (a method that reuses the
last one); how many particles the last collision pass left in contact; how many it
visited (fused, listed in ``visited``)."""


class Tile(NamedTuple):
    """The state and scratch of a tile of ``m`` particles.

    X, V : (3, m) positions (m) and velocities (m/s), the state
    F, A : (3, m) forces (N) and accelerations (m/s^2)
    XS, VS : (3, m) a stage's state, or the state a fused step saved
    KX, KV : (stages, 3, m) the stage derivatives of a tableau
    DX, DV : (3, m) their weighted sums
    contact : (planes, m) bool, the particles in contact with each plane
    resting : (m,) bool, in contact with any plane (fused)
    flags : (8 ceil(m / 8),) int64, the particles the fused collision pass visits (as wide
        as the state, so that the loop that sets them stays vectorised)
    special : (m,) int64, the special particles (fused), ``count[SPECIAL]`` of them
    visited : (m,) int64, the particles the last fused collision pass visited
    count : (4,) int64, see :data:`SPECIAL`
    """

    X: np.ndarray
    V: np.ndarray
    F: np.ndarray
    A: np.ndarray
    XS: np.ndarray
    VS: np.ndarray
    KX: np.ndarray
    KV: np.ndarray
    DX: np.ndarray
    DV: np.ndarray
    contact: np.ndarray
    resting: np.ndarray
    flags: np.ndarray
    special: np.ndarray
    visited: np.ndarray
    count: np.ndarray  # type: ignore[assignment]  # a field named like tuple.count, as numba reads it


LINE = 64
"""Bytes of a cache line: each scratch buffer starts on one and owns the lines it touches."""


def _owned(count: int, dtype: type = np.float64) -> np.ndarray:
    """``count`` zeros of ``dtype`` that share no cache line with any other array: a view
    into a larger allocation, starting on a line and followed by a line of its own. Tiles
    stepped on several threads at once (:func:`~truestep.reference_impl.integrate_kernels.run`)
    write their scratch at every step; two threads' buffers on one line would pass it
    between their cores at every write."""
    item = np.dtype(dtype).itemsize
    raw: np.ndarray = np.zeros(count + 3 * LINE // item, dtype=dtype)
    skip = (-raw.ctypes.data % LINE) // item
    return raw[skip : skip + count]


def scratch(size: int, stages: int, planes: int) -> Tile:
    """The buffers of a tile of up to ``size`` particles (one-dimensional, each field of
    :class:`Tile` flattened, each on cache lines of its own: :func:`_owned`), allocated
    once per run by Python: a compiled step allocates nothing (it is compiled without
    numba's reference counting, see :data:`forces_kernels.LOOP`)."""
    size = max(size, 1)
    f = [_owned(3 * size) for _ in range(6)]
    return Tile(  # type: ignore[call-arg]  # mypy drops the field count (see Tile)
        *f,
        _owned(stages * 3 * size),
        _owned(stages * 3 * size),
        _owned(3 * size),
        _owned(3 * size),
        _owned(planes * size, np.bool_),
        _owned(size, np.bool_),
        _owned(8 * ((size + 7) // 8), np.int64),
        _owned(size, np.int64),
        _owned(size, np.int64),
        _owned(4, np.int64),
    )


@njit(**COLD)
def tile_view(buffers, m):
    """The tile of ``m`` particles in ``buffers`` (:func:`scratch`), its counts cleared."""
    b = buffers
    stages = b.KX.shape[0] // (3 * max(b.resting.shape[0], 1))
    planes = b.contact.shape[0] // max(b.resting.shape[0], 1)
    for k in range(b.count.shape[0]):
        b.count[k] = 0
    return Tile(
        b.X[: 3 * m].reshape((3, m)),
        b.V[: 3 * m].reshape((3, m)),
        b.F[: 3 * m].reshape((3, m)),
        b.A[: 3 * m].reshape((3, m)),
        b.XS[: 3 * m].reshape((3, m)),
        b.VS[: 3 * m].reshape((3, m)),
        b.KX[: stages * 3 * m].reshape((stages, 3, m)),
        b.KV[: stages * 3 * m].reshape((stages, 3, m)),
        b.DX[: 3 * m].reshape((3, m)),
        b.DV[: 3 * m].reshape((3, m)),
        b.contact[: planes * m].reshape((planes, m)),
        b.resting[:m],
        b.flags[: 8 * ((m + 7) // 8)],
        b.special[:m],
        b.visited[:m],
        b.count,
    )


def near_planes(scene, x, radius):
    """Whether a particle at ``x`` (3-tuple, m) of ``radius`` (m) is within eps of a plane
    of the scene (NaN counts as near), each plane's :func:`near_plane` or'ed; ``False``
    without planes."""
    return any_near(scene.planes, x, radius)


@overload(near_planes, **BY_TYPE)
def _near_planes(scene, x, radius):
    return lambda scene, x, radius: any_near(scene.planes, x, radius)


def any_near(planes, x, radius):
    """Whether a particle at ``x`` of ``radius`` is :func:`near_plane` to any of
    ``planes`` (a tuple, or ``None``), every plane tested."""
    near = False
    for plane in planes or ():
        near = near | near_plane(plane, x, radius)
    return near


def _then_near(previous, i: int, plane):
    return lambda planes, x, radius: previous(planes, x, radius) | near_plane(planes[i], x, radius)


@overload(any_near, **BY_TYPE)
def _any_near(planes, x, radius):
    if isinstance(planes, types.NoneType):
        return lambda planes, x, radius: False
    return fold(planes, lambda planes, x, radius: False, _then_near).py_func


def point_contact(scene, tile, f, v, p):
    """``f`` with the contact force of every plane particle ``p`` rests on added
    (:func:`particles_kernels.resting_force`); ``f`` without planes."""
    return f if scene.planes is None else resting_force(scene, f, v, tile.contact, p)


@overload(point_contact, **BY_TYPE)
def _point_contact(scene, tile, f, v, p):
    if is_none(scene, "planes"):
        return lambda scene, tile, f, v, p: f
    return lambda scene, tile, f, v, p: resting_force(scene, f, v, tile.contact, p)


@njit(**LEAF)
def axpy(y, a, x):
    """``y + a x`` of 3-tuples (``a`` a float), component by component."""
    return (y[0] + a * x[0], y[1] + a * x[1], y[2] + a * x[2])


@njit(**LEAF)
def load(A, p):
    """Column ``p`` of a (3, m) array as a 3-tuple."""
    return (A[0, p], A[1, p], A[2, p])


@njit(**LEAF)
def store(A, p, a):
    """Set column ``p`` of a (3, m) array to the 3-tuple ``a``."""
    A[0, p], A[1, p], A[2, p] = a


@njit(**LEAF)
def same_bits(a, b):
    """Whether two floats have the same bits (``-0.0`` and ``0.0`` differ, as bytes do;
    NaN counts as changed)."""
    return a == b and np.copysign(1.0, a) == np.copysign(1.0, b)


@njit(**LEAF)
def moved(x, v, y, u):
    """Whether the state ``(y, u)`` differs from ``(x, v)`` in any bit (3-tuples)."""
    return not (
        same_bits(x[0], y[0])
        and same_bits(x[1], y[1])
        and same_bits(x[2], y[2])
        and same_bits(v[0], u[0])
        and same_bits(v[1], u[1])
        and same_bits(v[2], u[2])
    )


@njit(**LEAF)
def near_plane(plane, x, radius):
    """Whether a particle at ``x`` of ``radius`` is within eps of ``plane`` or its
    distance is NaN: it is one the collision pass must see."""
    return not signed_distance(x, radius, plane) >= EPS_DISTANCE


@njit(**COLD)
def passes_collisions(scene, tile, t, dt):
    """The collision and contact pass over a tile (:class:`collisions.PlaneCollisions`):
    planes one after the other, the applied force evaluated once, when the first particle
    is found within eps of a plane. Sets the contact flags and ``count[CONTACT]``; returns
    whether it changed any particle's state."""
    X, V, F, contact = tile.X, tile.V, tile.F, tile.contact
    par = scene.particles
    planes = scene.planes
    for k in range(contact.shape[0]):
        for p in range(contact.shape[1]):
            contact[k, p] = False
    have_force = False
    changed = False
    on_any = 0
    for k in range(len(planes)):
        plane = planes[k]
        for p in range(X.shape[1]):
            if not par.movable[p]:
                continue
            x = load(X, p)
            d = signed_distance(x, par.radius[p], plane)
            if not within(d, par.radius[p], plane):
                continue
            if not have_force:  # the applied force at the end of the step, once per pass
                applied_forces(scene, F, X, V, t)
                have_force = True
            v = load(V, p)
            y, u, on = collide(x, v, load(F, p), par.inv_mass[p], d, plane, dt)
            changed = changed or moved(x, v, y, u)
            store(X, p, y)
            store(V, p, u)
            contact[k, p] = on
            on_any += on
    tile.count[CONTACT] = on_any
    return changed


@njit(**COLD)
def passes_start(scene, tile, t):
    """The collision pass on the first state (a particle may start on a plane); the first
    step evaluates afresh."""
    passes_collide(scene, tile, t, 0.0)
    tile.count[FRESH] = 1


@carries(name="passes", start=passes_start)
class Passes(NamedTuple):
    """The layout that runs the derivative in passes over a tile (any scene), in tiles of
    ``size`` particles."""

    size: int


@njit(**COLD)
def collide_particle(scene, tile, p, t, dt):
    """The collision and contact pass for particle ``p`` alone (its force depends on no
    other particle): :func:`passes_collisions` restricted to it. Returns whether it rests
    on any plane now."""
    planes = scene.planes
    par = scene.particles
    for k in range(len(planes)):
        tile.contact[k, p] = False
    if not par.movable[p]:
        return False
    x, v = load(tile.X, p), load(tile.V, p)
    f = (0.0, 0.0, 0.0)
    have_force = False
    resting = False
    for k in range(len(planes)):
        plane = planes[k]
        d = signed_distance(x, par.radius[p], plane)
        if not within(d, par.radius[p], plane):
            continue
        if not have_force:  # the applied force at the end of the step, once per pass
            f = particle_force(scene, x, v, t, p)
            have_force = True
        x, v, on = collide(x, v, f, par.inv_mass[p], d, plane, dt)
        tile.contact[k, p] = on
        resting = resting or on
    store(tile.X, p, x)
    store(tile.V, p, v)
    return resting


def kicked(scene, p):
    """Whether particle ``p`` has impulses (``False`` for a scene without)."""
    return scene.impulses is not None and scene.impulses.start[p + 1] > scene.impulses.start[p]


@overload(kicked, **BY_TYPE)
def _kicked(scene, p):
    if is_none(scene, "impulses"):
        return lambda scene, p: False
    return lambda scene, p: scene.impulses.start[p + 1] > scene.impulses.start[p]


def list_kicked(scene, special):
    """Write the particles that have impulses into ``special`` (int64); return how many
    (0 for a scene without)."""
    if scene.impulses is None:
        return 0
    k = scene.impulses.kicked
    for q in range(k.shape[0]):
        special[q] = k[q] - scene.impulses.first
    return k.shape[0]


@overload(list_kicked, **BY_TYPE)
def _list_kicked(scene, special):
    if is_none(scene, "impulses"):
        return lambda scene, special: 0

    def impl(scene, special):
        k = scene.impulses.kicked
        for q in range(k.shape[0]):
            special[q] = k[q] - scene.impulses.first
        return k.shape[0]

    return impl


@njit(**KERNEL)
def list_special(scene, tile):
    """List the tile's special particles in ``special``: those with impulses, then those
    the last collision pass visited that rest on a plane and have none."""
    n = list_kicked(scene, tile.special)
    for q in range(tile.count[VISITED]):
        p = tile.visited[q]
        if tile.resting[p] and not kicked(scene, p):
            tile.special[n] = p
            n += 1
    tile.count[SPECIAL] = n


@njit(**KERNEL)
def fused_collisions(scene, tile, t, dt):
    """The collision pass of a fused step: on the particles ``flags`` marks (near a plane,
    or special), each alone (:func:`collide_particle`), the flags cleared and the visited
    ones listed. The flags are read eight at a time: most runs of eight have none.
    Returns whether it changed any particle's state."""
    flags = tile.flags
    seen = 0
    changed = False
    for k in range(flags.shape[0] // 8):
        b = 8 * k
        if (
            flags[b]
            | flags[b + 1]
            | flags[b + 2]
            | flags[b + 3]
            | flags[b + 4]
            | flags[b + 5]
            | flags[b + 6]
            | flags[b + 7]
        ) == 0:
            continue
        for p in range(8 * k, 8 * k + 8):
            if flags[p]:
                flags[p] = 0
                x, v = load(tile.X, p), load(tile.V, p)
                tile.resting[p] = collide_particle(scene, tile, p, t, dt)
                changed = changed or moved(x, v, load(tile.X, p), load(tile.V, p))
                tile.visited[seen] = p
                seen += 1
    tile.count[VISITED] = seen
    return changed


def passes_collide(scene, tile, t, dt):
    """The collision pass of the passes layout (:func:`passes_collisions`) after a step of
    ``dt`` (s) ending at ``t``; nothing (``False``) for a scene without planes. Returns
    whether it changed any particle's state."""
    return scene.planes is not None and passes_collisions(scene, tile, t, dt)


def fused_collide(scene, tile, t, dt):
    """The collision pass of the fused layout (:func:`fused_collisions`), as
    :func:`passes_collide`."""
    return scene.planes is not None and fused_collisions(scene, tile, t, dt)


def _collide_if_planes(collide):
    """The overload of a layout's generic collision pass: ``collide`` for a scene with
    planes, ``False`` without."""

    def pick(scene, tile, t, dt):
        if is_none(scene, "planes"):
            return lambda scene, tile, t, dt: False
        return lambda scene, tile, t, dt: collide(scene, tile, t, dt)

    return pick


overload(passes_collide, **BY_TYPE)(_collide_if_planes(passes_collisions))
overload(fused_collide, **BY_TYPE)(_collide_if_planes(fused_collisions))


@njit(**COLD)
def fused_start(scene, tile, t):
    """The collision pass on the first state, every particle visited (with planes), then
    the special particles listed; the first step evaluates afresh."""
    flags = tile.flags
    for p in range(tile.X.shape[1]):
        flags[p] = 1
    fused_collide(scene, tile, t, 0.0)
    for p in range(flags.shape[0]):
        flags[p] = 0
    list_special(scene, tile)
    tile.count[FRESH] = 1


@carries(name="fused", start=fused_start)
class Fused(NamedTuple):
    """The layout that steps each particle of a tile in one loop, for scenes whose forces
    are all pointwise, in tiles of ``size`` particles."""

    size: int


@njit(**KERNEL)
def mark_special(scene, tile):
    """Mark the special particles for the fused collision pass."""
    for q in range(tile.count[SPECIAL]):
        tile.flags[tile.special[q]] = 1


@njit(**KERNEL)
def smooth_accel(scene, tile, x, v, t, p):
    """The acceleration of particle ``p`` under the scene's pointwise kinds (every force
    but impulses and contact)."""
    return scaled(point_force(scene, x, v, t, p), scene.particles.inv_mass[p])


@njit(**KERNEL)
def special_accel(scene, tile, x, v, t, p):
    """The acceleration of particle ``p`` under its whole force: the pointwise kinds, its
    impulses and the contact force of the planes it rests on."""
    f = point_contact(scene, tile, particle_force(scene, x, v, t, p), v, p)
    return scaled(f, scene.particles.inv_mass[p])


@njit(**KERNEL)
def point_accel(special, scene, tile, x, v, t, p):
    """The acceleration (m/s^2, 3-tuple) of particle ``p`` at ``x``, ``v``, time ``t``, in
    a fused step: :func:`special_accel` for a ``special`` particle, else
    :func:`smooth_accel` (a fused step passes a constant: the compiler keeps one)."""
    if special:
        return special_accel(scene, tile, x, v, t, p)
    return smooth_accel(scene, tile, x, v, t, p)
