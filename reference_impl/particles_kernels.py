"""The lecture's derivative of :class:`~truestep.reference_impl.particles.ParticleSystem`, compiled.

The scene a compiled step reads (:class:`Scene`): its particles' constants, the tuple of
the force kinds it declares (:mod:`~truestep.reference_impl.forces_kernels`), its
impulses and its planes (``None`` when it has none). The derivative is the lecture's
loop, as :meth:`ParticleSystem.acceleration` makes it: clear the accumulator, let every
force kind add in, then the impulses, then the contact force for the particles resting on
a plane, divide by the masses. :func:`accelerations` runs it over a tile in passes (any
scene); :func:`particle_force` for one particle alone (scenes whose forces are all
pointwise). The calls that depend on what a scene holds are resolved by its types
(:mod:`~truestep.reference_impl.by_type`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from numba.core import types
from numba.extending import overload

from truestep.reference_impl.by_type import BY_TYPE, field_type, fold, is_none, kernel
from truestep.reference_impl.collisions_kernels import contact_force
from truestep.reference_impl.forces_kernels import KERNEL, LEAF, LOOP, impulse_at, impulses_add


class Particles(NamedTuple):
    """The constants of a tile's particles, each (m,): ``mass`` (kg), ``inv_mass`` (1/kg, 0
    for pinned particles), ``radius`` (m), ``movable`` (bool: not pinned) and
    ``moving_mass`` (kg, 0 for pinned particles: what their energy counts)."""

    mass: np.ndarray
    inv_mass: np.ndarray
    radius: np.ndarray
    movable: np.ndarray
    moving_mass: np.ndarray


class Scene(NamedTuple):
    """A particle scene as a compiled step reads it.

    particles : Particles
    forces : tuple of force kinds, only those the scene declares, in the order of
        :func:`forces.add_model_forces` (impulses apart)
    impulses : forces_kernels.Impulses or None
    planes : tuple of collisions_kernels.Plane, or None
    """

    particles: Particles
    forces: tuple
    impulses: object
    planes: object


def add_forces(scene, F, X, V, t):
    """Add the force of every kind in ``scene.forces`` into ``F``, in order (each kind's
    ``add``)."""
    for kind in scene.forces:
        type(kind).add(kind, F, X, V, t, scene.particles)


def _then_add(previous, i: int, kind):
    add = kernel(kind, "add")

    def added(kinds, F, X, V, t, particles):
        previous(kinds, F, X, V, t, particles)
        add(kinds[i], F, X, V, t, particles)

    return added


@overload(add_forces, **BY_TYPE)
def _add_forces(scene, F, X, V, t):
    adds = fold(field_type(scene, "forces"), lambda kinds, F, X, V, t, particles: None, _then_add)
    return lambda scene, F, X, V, t: adds(scene.forces, F, X, V, t, scene.particles)


def add_impulses(scene, F, X, V, t):
    """Add the impulses acting at ``t`` into ``F`` (``Impulses.add``), if the scene has any."""
    if scene.impulses is not None:
        impulses_add(scene.impulses, F, X, V, t, scene.particles)


@overload(add_impulses, **BY_TYPE)
def _add_impulses(scene, F, X, V, t):
    if is_none(scene, "impulses"):
        return lambda scene, F, X, V, t: None
    return lambda scene, F, X, V, t: impulses_add(scene.impulses, F, X, V, t, scene.particles)


def add_contact(scene, F, V, contact, any_contact):
    """Add the contact force of every plane to the particles in contact with it
    (:func:`add_contact_forces`), if the scene has planes."""
    if scene.planes is not None:
        add_contact_forces(scene, F, V, contact, any_contact)


@overload(add_contact, **BY_TYPE)
def _add_contact(scene, F, V, contact, any_contact):
    if is_none(scene, "planes"):
        return lambda scene, F, V, contact, any_contact: None
    return lambda scene, F, V, contact, any_contact: add_contact_forces(scene, F, V, contact, any_contact)


def point_force(scene, x, v, t, p):
    """The force (N, 3-tuple) of every kind in ``scene.forces`` on particle ``p`` alone
    (each kind's ``at`` in order, from zero); for scenes whose forces are all pointwise
    (zero for any other)."""
    f = (0.0, 0.0, 0.0)
    if all(type(kind).pointwise for kind in scene.forces):
        for kind in scene.forces:
            f = type(kind).at(kind, f, x, v, t, scene.particles, p)
    return f


def _then_at(previous, i: int, kind):
    at = kernel(kind, "at")

    def added(kinds, f, x, v, t, particles, p):
        return at(kinds[i], previous(kinds, f, x, v, t, particles, p), x, v, t, particles, p)

    return added


@overload(point_force, **BY_TYPE)
def _point_force(scene, x, v, t, p):
    kinds = field_type(scene, "forces")
    if not all(kernel(k, "pointwise") for k in kinds):
        return lambda scene, x, v, t, p: (0.0, 0.0, 0.0)
    ats = fold(kinds, lambda kinds, f, x, v, t, particles, p: f, _then_at)
    return lambda scene, x, v, t, p: ats(scene.forces, (0.0, 0.0, 0.0), x, v, t, scene.particles, p)


def point_impulses(scene, f, t, p):
    """``f`` with the impulses on particle ``p`` acting at ``t`` added, if any."""
    if scene.impulses is None:
        return f
    return impulse_at(scene.impulses, f, None, None, t, scene.particles, p)


@overload(point_impulses, **BY_TYPE)
def _point_impulses(scene, f, t, p):
    if is_none(scene, "impulses"):
        return lambda scene, f, t, p: f
    return lambda scene, f, t, p: impulse_at(scene.impulses, f, None, None, t, scene.particles, p)


def potential_energy(scene, X):
    """The potential energy (J) of every kind in ``scene.forces``, summed in order."""
    e = 0.0
    for kind in scene.forces:
        e += type(kind).energy(kind, X, scene.particles)
    return e


def _then_energy(previous, i: int, kind):
    energy = kernel(kind, "energy")

    def added(kinds, X, particles):
        return previous(kinds, X, particles) + energy(kinds[i], X, particles)

    return added


@overload(potential_energy, **BY_TYPE)
def _potential_energy(scene, X):
    energies = fold(field_type(scene, "forces"), lambda kinds, X, particles: 0.0, _then_energy)
    return lambda scene, X: energies(scene.forces, X, scene.particles)


@njit(**KERNEL)
def tile_particles(particles, lo, hi):
    """The constants of particles ``lo`` to ``hi`` (a tile of a scene whose particles do
    not act on one another)."""
    p = particles
    return Particles(
        p.mass[lo:hi], p.inv_mass[lo:hi], p.radius[lo:hi], p.movable[lo:hi], p.moving_mass[lo:hi]
    )


def cut(scene, lo, hi):
    """``scene`` for its particles ``lo`` to ``hi`` (a tile of a scene whose particles do
    not act on one another): its particles' constants, each kind cut by its ``cut`` kernel
    (a kind without one is the same for every tile), its impulses cut alike."""
    kinds = tuple(type(k).cut(k, lo, hi) if hasattr(type(k), "cut") else k for k in scene.forces)
    return Scene(
        tile_particles(scene.particles, lo, hi), kinds, cut_or_none(scene.impulses, lo, hi), scene.planes
    )


def _then_cut(previous, i: int, kind):
    if not hasattr(kind.instance_class, "cut"):
        return lambda kinds, lo, hi: (*previous(kinds, lo, hi), kinds[i])
    one = kernel(kind, "cut")
    return lambda kinds, lo, hi: (*previous(kinds, lo, hi), one(kinds[i], lo, hi))


@overload(cut, **BY_TYPE)
def _cut(scene, lo, hi):
    cuts = fold(field_type(scene, "forces"), lambda kinds, lo, hi: (), _then_cut)

    def impl(scene, lo, hi):
        kinds = cuts(scene.forces, lo, hi)
        impulses = cut_or_none(scene.impulses, lo, hi)
        return Scene(tile_particles(scene.particles, lo, hi), kinds, impulses, scene.planes)

    return impl


def cut_or_none(kind, lo, hi):
    """``kind`` cut to particles ``lo`` to ``hi`` by its ``cut`` kernel, or ``None``."""
    return None if kind is None else type(kind).cut(kind, lo, hi)


@overload(cut_or_none, **BY_TYPE)
def _cut_or_none(kind, lo, hi):
    if isinstance(kind, types.NoneType):
        return lambda kind, lo, hi: None
    first = kernel(kind, "cut")
    return lambda kind, lo, hi: first(kind, lo, hi)


@njit(**KERNEL)
def applied_forces(scene, F, X, V, t):
    """Clear ``F`` (N, (3, m)) and let every force of the scene add in, impulses last:
    :meth:`ParticleSystem.accumulate_forces` (the contact force is not applied)."""
    for p in range(F.shape[1]):
        F[0, p] = 0.0
        F[1, p] = 0.0
        F[2, p] = 0.0
    add_forces(scene, F, X, V, t)
    add_impulses(scene, F, X, V, t)


@njit(**LEAF)
def add_contact_forces(scene, F, V, contact, any_contact):
    """The contact force of each plane for the particles in contact with it
    (``contact`` (planes, m) bool), plane after plane, when any particle is:
    :func:`collisions.add_contact_forces`."""
    if not any_contact:
        return
    planes = scene.planes
    for k in range(len(planes)):
        plane = planes[k]
        for p in range(F.shape[1]):
            if contact[k, p]:
                f = contact_force((F[0, p], F[1, p], F[2, p]), (V[0, p], V[1, p], V[2, p]), plane)
                F[0, p], F[1, p], F[2, p] = f


@njit(**KERNEL)
def accelerations(scene, A, F, X, V, t, contact, any_contact):
    """``A = F / m`` (m/s^2, (3, m)) at positions ``X`` and velocities ``V`` at time ``t``:
    :meth:`ParticleSystem.acceleration`, in passes over the tile; ``F`` is scratch."""
    applied_forces(scene, F, X, V, t)
    add_contact(scene, F, V, contact, any_contact)
    w = scene.particles.inv_mass
    for p in range(A.shape[1]):
        A[0, p] = F[0, p] * w[p]
        A[1, p] = F[1, p] * w[p]
        A[2, p] = F[2, p] * w[p]


@njit(**LOOP)
def flat_derivative(scene, y, t, out, X, V, F, A, contact):
    """``dy/dt`` of a flat state ``y`` (6 m,: the positions (m, 3) then the velocities,
    each particle's three components together, as :class:`ParticleSystem` keeps them) at
    time ``t`` into ``out`` (6 m,): the velocities, then :func:`accelerations` (no
    particle in contact: a scene without planes). ``X``, ``V``, ``F``, ``A`` ((3, m)) and
    ``contact`` are scratch. :meth:`SecondOrderSystem.derivative` of a
    :class:`ParticleSystem`, bit for bit; compiled for a scene by
    :func:`compiled.derivative_for`."""
    m = X.shape[1]
    for p in range(m):
        for c in range(3):
            X[c, p] = y[3 * p + c]
            V[c, p] = y[3 * m + 3 * p + c]
            out[3 * p + c] = y[3 * m + 3 * p + c]
    accelerations(scene, A, F, X, V, t, contact, False)
    for p in range(m):
        for c in range(3):
            out[3 * m + 3 * p + c] = A[c, p]


@njit(**KERNEL)
def particle_force(scene, x, v, t, p):
    """The applied force on particle ``p`` alone, its impulses last, for scenes whose
    forces are all pointwise."""
    return point_impulses(scene, point_force(scene, x, v, t, p), t, p)


@njit(**LEAF)
def resting_force(scene, f, v, contact, p):
    """``f`` with the contact force of every plane particle ``p`` rests on added."""
    planes = scene.planes
    for k in range(len(planes)):
        if contact[k, p]:
            f = contact_force(f, v, planes[k])
    return f


@njit(**LEAF)
def scaled(f, w):
    """``f * w`` of a 3-tuple: a force times an inverse mass."""
    return (f[0] * w, f[1] * w, f[2] * w)


@njit(**LEAF)
def kinetic_energy(V, particles):
    """``sum m |v|^2 / 2`` of the movable particles, J."""
    e = 0.0
    for p in range(V.shape[1]):
        e += particles.moving_mass[p] * (V[0, p] * V[0, p] + V[1, p] * V[1, p] + V[2, p] * V[2, p])
    return 0.5 * e


@njit(**KERNEL)
def total_energy(scene, X, V):
    """Kinetic plus potential energy of the tile (J): :func:`particles.total_energy`
    (impulses have no potential)."""
    return kinetic_energy(V, scene.particles) + potential_energy(scene, X)
