"""The lecture's derivative of :class:`~truestep.reference_impl.particles.ParticleSystem`, compiled.

The scene a compiled step reads (:class:`Scene`): its particles' constants, the tuple of
the force kinds it declares (:mod:`~truestep.reference_impl.forces_kernels`), its
impulses and its planes (``None`` when it has none). The derivative is the lecture's
loop, as :meth:`ParticleSystem.acceleration` makes it: clear the accumulator, let every
force kind add in, then the impulses, then the contact force for the particles resting on
a plane, divide by the masses. :func:`accelerations` runs it over a tile in passes (any
scene); :func:`particle_force` for one particle alone (scenes whose forces are all
pointwise). The parts a scene may lack are slots (:mod:`~truestep.reference_impl.compose`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from truestep.reference_impl.collisions_kernels import contact_force
from truestep.reference_impl.compose import slot
from truestep.reference_impl.forces_kernels import KERNEL, LEAF


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


@slot
def add_forces(scene, F, X, V, t):
    """Add the force of every kind in ``scene.forces`` into ``F``, in order (each kind's
    ``add``)."""


@slot
def add_impulses(scene, F, X, V, t):
    """Add the impulses acting at ``t`` into ``F`` (``Impulses.add``), if the scene has any."""


@slot
def add_contact(scene, F, V, contact, any_contact):
    """Add the contact force of every plane to the particles in contact with it
    (:func:`add_contact_forces`), if the scene has planes."""


@slot
def point_force(scene, x, v, t, p):
    """The force (N, 3-tuple) of every kind in ``scene.forces`` on particle ``p`` alone
    (each kind's ``at`` in order, from zero); for scenes whose forces are all pointwise."""


@slot
def point_impulses(scene, f, t, p):
    """``f`` with the impulses on particle ``p`` acting at ``t`` added, if any."""


@slot
def potential_energy(scene, X):
    """The potential energy (J) of every kind in ``scene.forces``, summed in order."""


@njit(**KERNEL)
def tile_particles(particles, lo, hi):
    """The constants of particles ``lo`` to ``hi`` (a tile of a scene whose particles do
    not act on one another)."""
    p = particles
    return Particles(
        p.mass[lo:hi], p.inv_mass[lo:hi], p.radius[lo:hi], p.movable[lo:hi], p.moving_mass[lo:hi]
    )


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
