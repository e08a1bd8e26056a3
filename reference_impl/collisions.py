"""Point-plane collisions and contact, the lecture's "add-ons for a particle simulator".

Between solver steps, for every plane ``(X - P) . N = 0`` (the free side along ``N``)
and every particle of radius ``r`` (its contact point is ``X - r N``, so its signed
distance from the plane is ``d = (X - P) . N - r``):

1. **Collision.** Within ``eps`` of the wall and heading in, ``d < eps`` and
   ``N . V < 0``: the response ``V' = V_T - k_r V_N`` with ``V_N = (N . V) N`` and
   ``V_T = V - V_N``.
2. **Penetration.** The lecture's response changes only the velocity, so a particle
   found below the plane would stay below it, and a resting one would sink. As a common
   add-on a penetrating particle is lifted back along ``N`` onto the plane
   (``X' = X - d N`` for ``d < 0``), and it pays the work of its normal force on the way:
   its normal speed becomes the one it had when it reached the plane,
   ``V_N^2 -> V_N^2 - 2 a_N d`` (``a_N = F . N / m``, exact under a constant force), before
   the response. Without that, every bounce would gain ``m |a_N| |d|`` of energy and a
   ball would never come to rest. With it a bounce under gravity keeps exactly the
   fraction ``k_r^2`` of the energy (apex heights ``h_n = k_r^(2n) h_0`` up to rounding
   with the lecture's update), while each bounce is found up to one step late (bounce
   times off by ``O(dt)``), and no recorded state lies below a plane.
3. **Contact.** On the wall (``|d| < eps``), moving along it (``|N . V| < eps_v``) and
   pushing against it (``F . N < 0`` for the applied force ``F`` at the end of the step):
   the particle is in contact. Its normal velocity and distance, zero within the
   tolerances, are set to zero, and until the next pass the derivative replaces its
   force by ``F' = F_T`` (the wall pushes back, cancelling the normal component of
   ``F``: a constraint force), see :func:`add_contact_forces`. A fixed step cannot tell
   a particle at rest from one whose normal speed is below what its normal force
   changes in one step, so the speed tolerance is ``eps_v + |F_N| dt / m``: the endless
   train of ever smaller bounces (``h_n = e^(2n) h_0`` has infinitely many) ends once a
   bounce is smaller than one step can resolve.
4. **Friction** (beyond the lecture, planes with ``friction = mu > 0``). For a particle in
   contact the derivative adds kinetic Coulomb friction ``-mu |F_N| V_T / |V_T|``; at
   ``V_T = 0`` static friction cancels ``F_T`` up to ``mu |F_N|``. Friction can stop a
   particle but never reverse it: when friction could take the tangential speed within
   one step (``|V_T| <= eps_v + mu |F_N| dt / m``) and static friction can hold the
   particle (``|F_T| <= mu |F_N|``), the pass sets ``V_T = 0`` (it stops within the step).

A plane of ``thickness`` w > 0 is a wall, not a half-space: a particle found more than
``w + 2 r`` behind it has crossed the whole wall within one step and is left alone
(tunnelling, as in any engine that tests for overlap between steps).

A box is six planes. Planes are treated one after the other within a pass. The applied
force is evaluated once per pass, at the end of the step, and only when some particle is
within ``eps`` of a plane.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from truestep.reference_impl.model import Plane

if TYPE_CHECKING:
    from truestep.reference_impl.particles import ParticleSystem

EPS_DISTANCE = 1e-9
"""m: "within eps of the wall" for collision and contact (theoretically zero)."""
EPS_SPEED = 1e-9
"""m/s: the part of the contact speed tolerance that does not scale with the step."""


def box_planes(
    lo: np.ndarray, hi: np.ndarray, *, restitution: float = 1.0, friction: float = 0.0
) -> list[Plane]:
    """The six inward-facing walls of the box ``lo <= X <= hi`` (each shape (3,), m)."""
    planes = []
    for axis in range(3):
        n = np.zeros(3)
        n[axis] = 1.0
        planes.append(Plane(np.asarray(lo, float), n.copy(), restitution, friction))
        planes.append(Plane(np.asarray(hi, float), -n, restitution, friction))
    return planes


def signed_distances(x: np.ndarray, radius: np.ndarray, plane: Plane) -> np.ndarray:
    """``d = (X - P) . N - r`` of every particle (n,), m: negative means penetrating."""
    return (x - plane.point) @ plane.normal - radius


def add_contact_forces(f: np.ndarray, v: np.ndarray, contact: np.ndarray, planes: list[Plane]) -> None:
    """Add the contact force (and friction) of every plane to particles in contact.

    f : (n, 3) N, the applied forces, changed in place; v : (n, 3) m/s;
    contact : (len(planes), n) bool. For a particle pushing into the plane
    (``F . N < 0``) the wall cancels the normal component, ``F' = F_T``; with friction
    ``mu`` it also resists sliding with ``mu |F_N|`` (see the module docstring).
    """
    for plane, on in zip(planes, contact, strict=True):
        if not on.any():
            continue
        idx = np.flatnonzero(on)
        n = plane.normal
        fk = f[idx]
        fn = fk @ n
        press = np.minimum(fn, 0.0)  # the normal force the wall must cancel, <= 0
        fk -= press[:, None] * n
        if plane.friction > 0:
            limit = -plane.friction * press  # mu |F_N|, N
            vk = v[idx]
            vt = vk - (vk @ n)[:, None] * n
            speed = np.linalg.norm(vt, axis=1)
            ft = fk - (fk @ n)[:, None] * n
            ft_mag = np.linalg.norm(ft, axis=1)
            sliding = speed > 0
            kinetic = np.where(sliding, limit, 0.0) / np.where(sliding, speed, 1.0)
            held = ~sliding & (ft_mag <= limit)
            slipping = ~sliding & ~held
            static = np.where(held, 1.0, 0.0) + np.where(
                slipping, limit / np.where(slipping, ft_mag, 1.0), 0.0
            )
            fk -= kinetic[:, None] * vt + static[:, None] * ft
        f[idx] = fk


def contact_projection(f: np.ndarray, contact: np.ndarray, planes: list[Plane]) -> np.ndarray:
    """Per-particle ``d F' / d F`` (n, 3, 3) of the contact force: ``I - N N^T`` for pushers.

    The derivative of ``F' = F_T`` with respect to the applied force, for the particles
    that :func:`add_contact_forces` would treat as pushing at forces ``f`` (n, 3); the
    identity for every other particle.
    """
    blocks = np.broadcast_to(np.eye(3), (len(f), 3, 3)).copy()
    for plane, on in zip(planes, contact, strict=True):
        push = on & (f @ plane.normal < 0)
        blocks[push] = (np.eye(3) - np.outer(plane.normal, plane.normal)) @ blocks[push]
    return blocks


class PlaneCollisions:
    """The collision and contact pass for the planes of a scene (see the module docstring).

    Parameters
    ----------
    planes : list of Plane
    radius : ndarray, shape (n,), m       collision radius of each particle
    fixed : ndarray of bool, shape (n,)   pinned particles are never moved
    mass : ndarray, shape (n,), kg
    eps_distance : float, m;  eps_speed : float, m/s   the lecture's epsilons

    Attributes
    ----------
    collisions : int
        Collision responses applied so far (all planes).
    """

    def __init__(
        self,
        planes: list[Plane],
        radius: np.ndarray,
        fixed: np.ndarray,
        mass: np.ndarray,
        *,
        eps_distance: float = EPS_DISTANCE,
        eps_speed: float = EPS_SPEED,
    ) -> None:
        self.planes = planes
        self.radius = radius
        self.fixed = fixed
        self.inv_mass = np.where(fixed, 0.0, 1.0 / mass)
        self.eps_distance = eps_distance
        self.eps_speed = eps_speed
        self.collisions = 0

    def start(self, system: ParticleSystem) -> None:
        """Apply the pass to the initial state (a particle may start on a plane)."""
        self(system, 0.0)

    def __call__(self, system: ParticleSystem, dt: float) -> None:
        x, v = system.positions, system.velocities
        movable = system.alive & ~self.fixed
        system.contact[:] = False
        f = None
        for k, plane in enumerate(self.planes):
            d = signed_distances(x, self.radius, plane)
            inside = d < self.eps_distance
            if plane.thickness > 0:
                inside &= d > -(plane.thickness + 2 * self.radius)
            idx = np.flatnonzero(movable & inside)
            if not len(idx):
                continue
            if f is None:  # the applied force at the end of the step, once per pass
                f = system.accumulate_forces(x, v, system.get_time()).copy()
            system.contact[k, idx] = self._collide(system, plane, idx, f[idx], dt)

    def _collide(
        self, system: ParticleSystem, plane: Plane, idx: np.ndarray, f: np.ndarray, dt: float
    ) -> np.ndarray:
        """Penetration, collision and contact for particles ``idx`` within eps of ``plane``.

        ``f`` (k, 3) is their applied force at the end of the step. A penetrating particle
        is lifted onto the plane and pays the work of its normal force on the way, so its
        normal speed is the one it had when it reached the plane (exact under a constant
        force): ``V_N^2 -> V_N^2 - 2 a_N d``. Returns which of them are in contact.
        """
        x, v = system.positions, system.velocities
        n = plane.normal
        d = signed_distances(x[idx], self.radius[idx], plane)
        vk = v[idx]
        vn = vk @ n
        an = (f @ n) * self.inv_mass[idx]
        if getattr(system, "located", False):  # the step stopped at the impact: no step slack
            dt = 0.0
            rest = np.sqrt(2.0 * np.maximum(-an, 0.0) * system.rest_height)
        else:
            rest = 0.0
        below = d < 0
        vn_new = np.where(below, np.sign(vn) * np.sqrt(np.maximum(vn**2 - 2.0 * an * d, 0.0)), vn)
        x[idx[below]] -= d[below, None] * n
        d = np.where(below, 0.0, d)
        heading_in = vn_new < 0
        self.collisions += int(heading_in.sum())
        vn_new = np.where(heading_in, -plane.restitution * vn_new, vn_new)  # V' = V_T - k_r V_N
        tol = np.maximum(self.eps_speed - an * dt, rest)
        on = (np.abs(d) < self.eps_distance) & (an < 0) & (np.abs(vn_new) <= tol)
        vn_new = np.where(on, 0.0, vn_new)
        x[idx[on]] -= d[on, None] * n
        vk += (vn_new - vn)[:, None] * n
        if plane.friction > 0:
            vk -= self._sticking(plane, on, vk, f, an, dt, rest)[:, None] * (vk - vn_new[:, None] * n)
        v[idx] = vk
        return on

    def _sticking(
        self,
        plane: Plane,
        on: np.ndarray,
        v: np.ndarray,
        f: np.ndarray,
        an: np.ndarray,
        dt: float,
        rest: np.ndarray | float = 0.0,
    ) -> np.ndarray:
        """Which contact particles friction stops now (1.0) or lets slide (0.0), shape (k,).

        A particle stops when friction could take its tangential speed within one step,
        ``|V_T| <= eps_v + mu |a_N| dt``, and static friction can hold it,
        ``|F_T| <= mu |F_N|``: so friction never reverses a particle inside a step. After
        a step stopped at the event (located), the speed is within ``rest`` of zero.
        """
        n, mu = plane.normal, plane.friction
        fn = f @ n
        speed = np.linalg.norm(v - (v @ n)[:, None] * n, axis=1)
        ft = np.linalg.norm(f - fn[:, None] * n, axis=1)
        limit = np.maximum(self.eps_speed - mu * an * dt, mu * rest)
        stop = on & (speed <= limit) & (ft <= -mu * fn)
        return stop.astype(float)
