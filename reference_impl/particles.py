"""A particle system behind the lecture's solver interface.

State ``x = [positions, velocities]`` flattened from two ``(n, 3)`` arrays; the
derivative is ``[v, f/m]``, computed by the lecture's loop: clear the force
accumulator, let every force object add its force, divide by the masses. Collisions,
emitters and lifetimes run between solver steps as passes.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from truestep.reference_impl import collisions, forces
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.system import SecondOrderSystem

if TYPE_CHECKING:
    import scipy.sparse as sp

DENSE_JACOBIAN = 240
"""Up to this state dimension the Jacobian is returned as a dense array."""

Pass = Callable[["ParticleSystem", float], None]
"""Something that acts on the system between solver steps, given the step (s).

A pass that needs the initial state (contact at rest, an emitter's first frame) also has
a method ``start(system)``, called once when the system is built.
"""


class ParticleSystem(SecondOrderSystem):
    """Particles of a :class:`ParticleModel`, stepped by any reference solver.

    Parameters
    ----------
    model : ParticleModel
        Masses, springs, fields, planes; never changed by stepping.
    passes : list of callables ``p(system, dt)``, optional
        Run in order after every solver step (collisions, emitters, lifetimes).

    Attributes
    ----------
    alive : ndarray of bool, shape (n,)
        Particles taking part (all, unless an emitter manages a pool).
    contact : ndarray of bool, shape (len(model.planes), n)
        Particles in resting or sliding contact with each plane, set by the collision
        pass (:mod:`truestep.reference_impl.collisions`); the derivative adds the contact force
        (and friction) for them.
    f : ndarray, shape (n, 3), N
        The force accumulator, reused between evaluations.
    """

    def __init__(self, model: ParticleModel, passes: list[Pass] | None = None) -> None:
        super().__init__(np.concatenate([model.x0.ravel(), model.v0.ravel()]))
        self.model = model
        self.n = model.n
        self.passes = list(passes or [])
        self.alive = np.ones(self.n, dtype=bool)
        self.alive[self.n - sum(e.capacity for e in model.emitters) :] = False  # empty pools
        self.contact = np.zeros((len(model.planes), self.n), dtype=bool)
        self.f = np.zeros((self.n, 3))
        self._inv_mass = np.where(model.fixed, 0.0, 1.0 / model.mass)
        self._has_gravity = bool(np.any(model.gravity))
        for p in self.passes:
            start = getattr(p, "start", None)
            if start is not None:
                start(self)

    # -- structured views of the flat state ------------------------------------------
    @property
    def positions(self) -> np.ndarray:
        """Current positions, a view of shape (n, 3), m."""
        return self._x[: 3 * self.n].reshape(self.n, 3)

    @property
    def velocities(self) -> np.ndarray:
        """Current velocities, a view of shape (n, 3), m/s."""
        return self._x[3 * self.n :].reshape(self.n, 3)

    # -- the lecture's derivative loop -----------------------------------------------
    def accumulate_forces(self, x: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
        """Clear the accumulator and let each force object add in; return ``f`` (n, 3).

        These are the applied forces; the contact force is added by :meth:`acceleration`.
        """
        return forces.add_model_forces(self.f, self.model, x, v, t, gravity=self._has_gravity)

    def acceleration(self, q: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
        x = q.reshape(self.n, 3)
        vel = v.reshape(self.n, 3)
        f = self.accumulate_forces(x, vel, t)
        if self.model.planes and self.contact.any():
            collisions.add_contact_forces(f, vel, self.contact, self.model.planes)
        a = f * self._inv_mass[:, None]
        if self.model.emitters:
            a[~self.alive] = 0.0
        return a.ravel()

    def compiled_derivative(self) -> Callable[[np.ndarray, float], np.ndarray] | None:
        """:meth:`derivative` compiled (:func:`~truestep.reference_impl.compiled.derivative_for`),
        or ``None`` for a scene with planes, fields or emitters, whose derivative reads what
        the passes between steps set."""
        from truestep.reference_impl.compiled import derivative_for

        return derivative_for(self.model)

    def jacobian(self, x: np.ndarray, t: float) -> sp.csr_matrix | np.ndarray | None:
        """Sparse ``d[v, a]/d[x, v]`` (dim, dim): gravity, drag, springs, anchors, gravitation.

        The rows of ``a`` are the force derivatives (3x3 blocks per particle pair) times the
        inverse mass; for a particle pushing into a plane it is in contact with they are
        also projected by ``I - N N^T`` (the contact force ``F' = F_T``). Friction and
        impulses are left out (piecewise constant in the state; implicit Euler uses the
        Jacobian only as its Newton matrix). Scenes with force fields return ``None``: the
        solver then differences. Small systems (``dim <= DENSE_JACOBIAN``) get a dense
        array, for which a dense LU is faster than a sparse one.
        """
        m = self.model
        if m.fields:
            return None
        n = self.n
        pos = x[: 3 * n].reshape(n, 3)
        vel = x[3 * n :].reshape(n, 3)
        rows, cols, kx, kv = (
            [np.arange(n)],
            [np.arange(n)],
            [np.zeros((n, 3, 3))],
            [np.broadcast_to(-m.drag * np.eye(3), (n, 3, 3))],
        )
        s, a = m.springs, m.anchors
        if len(s):
            jx, jv = forces.spring_jacobians(
                pos[s.i] - pos[s.j], vel[s.i] - vel[s.j], s.stiffness, s.damping, s.rest
            )
            rows += [s.i, s.i, s.j, s.j]
            cols += [s.i, s.j, s.i, s.j]
            kx += [jx, -jx, -jx, jx]
            kv += [jv, -jv, -jv, jv]
        if len(a):
            jx, jv = forces.spring_jacobians(pos[a.i] - a.point, vel[a.i], a.stiffness, a.damping, a.rest)
            rows += [a.i]
            cols += [a.i]
            kx += [jx]
            kv += [jv]
        if m.gravitation is not None:
            ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
            rows += [ii.ravel()]
            cols += [jj.ravel()]
            kx += [forces.gravitation_jacobian(pos, m.mass, m.gravitation).reshape(-1, 3, 3)]
            kv += [np.zeros((n * n, 3, 3))]
        r, c = np.concatenate(rows), np.concatenate(cols)
        scale = self._inv_mass * (self.alive if m.emitters else 1.0)
        left = scale[:, None, None] * np.eye(3)  # (n, 3, 3): what multiplies a row of forces
        if self.contact.any():
            f = self.accumulate_forces(pos, vel, t)
            left = left @ collisions.contact_projection(f, self.contact, m.planes)
        ax = left[r] @ np.concatenate(kx)
        av = left[r] @ np.concatenate(kv)
        block_rows = np.concatenate([np.arange(n), n + r, n + r])
        block_cols = np.concatenate([n + np.arange(n), c, n + c])
        blocks = np.concatenate([np.broadcast_to(np.eye(3), (n, 3, 3)), ax, av])
        ri = 3 * block_rows[:, None, None] + np.arange(3)[None, :, None]
        ci = 3 * block_cols[:, None, None] + np.arange(3)[None, None, :]
        ri, ci = np.broadcast_arrays(ri, ci)
        if self.dim <= DENSE_JACOBIAN:
            jac = np.zeros((self.dim, self.dim))
            np.add.at(jac, (ri, ci), blocks)
            return jac
        from scipy.sparse import csr_matrix  # here, not at import: scipy.sparse is a tenth of a second

        return csr_matrix((blocks.ravel(), (ri.ravel(), ci.ravel())), shape=(self.dim, self.dim))

    def between_steps(self, dt: float) -> None:
        for p in self.passes:
            p(self, dt)

    def next_pass_time(self) -> float:
        """The earliest next frame of the scene's emitters (s), ``inf`` without any."""
        return min((float(p.next_time) for p in self.passes if hasattr(p, "next_time")), default=math.inf)

    located: bool = False
    """Set by an adaptive integration that stops its steps at impacts
    (:meth:`event_watch`): the collision pass then reads contact with the precision of a
    located event, not of a step."""
    rest_height: float = 0.0
    """With :attr:`located`: a bounce whose hop would rise less than this (m) is rest (the
    adaptive method's tolerance: a smaller hop is below what it resolves)."""

    def event_watch(self) -> PlaneEvents | None:
        """For the coming step, with the contacts as they are now: each free particle's
        distance above each plane (an impact when it turns negative), and each particle
        sliding with friction its tangential velocity along its direction now (friction
        stops it when that turns negative) (:class:`PlaneEvents`); ``None`` without
        planes."""
        return PlaneEvents(self) if self.model.planes else None

    def observe(self) -> dict[str, np.ndarray]:
        return {"alive": self.alive.copy()} if self.model.emitters else {}

    # -- observables -------------------------------------------------------------------
    def energy(self, x: np.ndarray, t: float) -> float | None:
        """Kinetic plus potential energy (gravity, springs, gravitation), J.

        Force fields and impulses have no potential; scenes with them report the
        mechanical energy of the rest, which the metrics then treat as not conserved.
        """
        n3 = 3 * self.n
        return float(total_energy(self.model, x[:n3].reshape(-1, 3), x[n3:].reshape(-1, 3), self.alive))


class PlaneEvents:
    """The event functions of a particle system's planes for one step (see
    :meth:`ParticleSystem.event_watch`): called on a flat state (dim,), the components
    ``[d_plane0 (n), slide_plane0 (n), d_plane1 (n), ...]``, ``inf`` where a particle is
    not watched; :meth:`focus` evaluates only some of them, from part of the state."""

    def __init__(self, system: ParticleSystem) -> None:
        m = system.model
        self.n, self.planes, self.radius = system.n, m.planes, m.radius
        free = system.alive & ~m.fixed
        pos, vel = system.positions, system.velocities
        self.watched, self.sliding, self.direction = [], [], []
        for plane, on in zip(m.planes, system.contact, strict=True):
            watched = free & ~on
            if plane.thickness > 0:  # a wall: watched only from its front, where it is now
                d0 = collisions.signed_distances(pos, self.radius, plane)
                watched &= d0 > -(plane.thickness + 2 * self.radius)
            vt = vel - (vel @ plane.normal)[:, None] * plane.normal
            speed = np.linalg.norm(vt, axis=1)
            moving = on & free & (speed > 0) & (plane.friction > 0)
            self.watched.append(watched)
            self.sliding.append(moving)
            self.direction.append(
                np.where(moving[:, None], vt / np.where(speed > 0, speed, 1.0)[:, None], 0.0)
            )

    def __call__(self, x: np.ndarray) -> np.ndarray:
        n = self.n
        pos, vel = x[: 3 * n].reshape(n, 3), x[3 * n :].reshape(n, 3)
        out = []
        for plane, watched, moving, u in zip(
            self.planes, self.watched, self.sliding, self.direction, strict=True
        ):
            out.append(np.where(watched, collisions.signed_distances(pos, self.radius, plane), np.inf))
            out.append(np.where(moving, np.sum(vel * u, axis=1), np.inf))
        return np.concatenate(out)

    def focus(self, mask: np.ndarray) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
        """The state indices the components ``mask`` (bool, like a call's result) read, and
        a function of the state at those indices giving those components (vectorised per
        plane and kind)."""
        n = self.n
        groups = mask.reshape(-1, n)
        index, parts, at = [], [], 0
        for k, plane in enumerate(self.planes):
            for slide, chosen in ((False, groups[2 * k]), (True, groups[2 * k + 1])):
                i = np.flatnonzero(chosen)
                if not len(i):
                    continue
                base = 3 * i + (3 * n if slide else 0)
                index.append((base[:, None] + np.arange(3)).ravel())
                parts.append((slide, plane, i, k, at, at + 3 * len(i)))
                at += 3 * len(i)
        index_arr = np.concatenate(index) if index else np.zeros(0, int)

        def values(sub: np.ndarray) -> np.ndarray:
            out = []
            for slide, plane, i, k, a, b in parts:
                triples = sub[a:b].reshape(-1, 3)
                if slide:
                    out.append(np.sum(triples * self.direction[k][i], axis=1))
                else:
                    out.append((triples - plane.point) @ plane.normal - self.radius[i])
            return np.concatenate(out) if out else np.zeros(0)

        return index_arr, values


def total_energy(
    model: ParticleModel, x: np.ndarray, v: np.ndarray, alive: np.ndarray | None = None
) -> np.ndarray:
    """Kinetic + gravitational + spring energy of particles at ``x``, ``v``, J.

    ``x`` and ``v`` have shape (n, 3) for one state, or (T, n, 3) for T recorded states
    at once (then ``alive`` is (T, n) and the result an array of shape (T,); for one
    state, an array of shape ()). Potential
    energy of uniform gravity is ``-m g . x`` (zero at the origin).
    """
    m = np.where(model.fixed, 0.0, model.mass)
    if alive is not None:
        m = np.where(alive, m, 0.0)
    energy = 0.5 * np.sum(m * np.einsum("...ij,...ij->...i", v, v), axis=-1)
    energy -= np.sum(m * (x @ model.gravity), axis=-1)
    energy += forces.spring_energy(x, model.springs) + forces.anchor_energy(x, model.anchors)
    if model.gravitation is not None:
        energy += forces.gravitation_energy(x, model.mass, model.gravitation)
    return np.asarray(energy)
