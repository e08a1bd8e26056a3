"""A particle system behind the lecture's solver interface.

State ``x = [positions, velocities]`` flattened from two ``(n, 3)`` arrays; the
derivative is ``[v, f/m]``, computed by the lecture's loop: clear the force
accumulator, let every force object add its force, divide by the masses. Collisions,
emitters and lifetimes run between solver steps as passes.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from reference_impl import forces
from reference_impl.model import ParticleModel
from reference_impl.system import SecondOrderSystem

Pass = Callable[["ParticleSystem", float], None]
"""Something that acts on the system between solver steps, given the step (s)."""


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
    f : ndarray, shape (n, 3), N
        The force accumulator, reused between evaluations.
    """

    def __init__(self, model: ParticleModel, passes: list[Pass] | None = None) -> None:
        super().__init__(np.concatenate([model.x0.ravel(), model.v0.ravel()]))
        self.model = model
        self.n = model.n
        self.passes = list(passes or [])
        self.alive = np.ones(self.n, dtype=bool)
        self.f = np.zeros((self.n, 3))
        self._inv_mass = np.where(model.fixed, 0.0, 1.0 / model.mass)

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
        """Clear the accumulator and let each force object add in; return ``f`` (n, 3)."""
        m = self.model
        f = self.f
        f[:] = 0.0
        if np.any(m.gravity):
            forces.add_gravity(f, m.mass, m.gravity)
        if m.drag:
            forces.add_drag(f, v, m.drag)
        forces.add_springs(f, x, v, m.springs)
        forces.add_anchors(f, x, v, m.anchors)
        if m.gravitation is not None:
            forces.add_gravitation(f, x, m.mass, m.gravitation)
        if m.fields:
            forces.add_fields(f, m.fields, x, v, m.mass, t)
        for i, force, t_on, t_off in m.impulses:
            if t_on <= t < t_off:
                f[i] += force
        return f

    def acceleration(self, q: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
        x = q.reshape(self.n, 3)
        vel = v.reshape(self.n, 3)
        f = self.accumulate_forces(x, vel, t)
        a = f * self._inv_mass[:, None]
        a[~self.alive] = 0.0
        return a.ravel()

    def between_steps(self, dt: float) -> None:
        for p in self.passes:
            p(self, dt)

    def observe(self) -> dict[str, np.ndarray]:
        return {"alive": self.alive.copy()} if self.model.emitters else {}

    # -- observables -------------------------------------------------------------------
    def energy(self, x: np.ndarray, t: float) -> float | None:
        """Kinetic plus potential energy (gravity, springs, gravitation), J.

        Force fields and impulses have no potential; scenes with them report the
        mechanical energy of the rest, which the metrics then treat as not conserved.
        """
        return total_energy(self.model, x[: 3 * self.n].reshape(-1, 3),
                            x[3 * self.n :].reshape(-1, 3), self.alive)


def total_energy(
    model: ParticleModel, x: np.ndarray, v: np.ndarray, alive: np.ndarray | None = None
) -> float:
    """Kinetic + gravitational + spring energy of particles at ``x``, ``v`` (n, 3), J.

    Potential energy of uniform gravity is ``-m g . x`` (zero at the origin).
    """
    m = np.where(model.fixed, 0.0, model.mass)
    if alive is not None:
        m = np.where(alive, m, 0.0)
    kinetic = 0.5 * float(np.sum(m * np.einsum("ij,ij->i", v, v)))
    potential = -float(np.sum(m * (x @ model.gravity)))
    potential += forces.spring_energy(x, model.springs) + forces.anchor_energy(x, model.anchors)
    if model.gravitation is not None:
        potential += forces.gravitation_energy(x, model.mass, model.gravitation)
    return kinetic + potential
