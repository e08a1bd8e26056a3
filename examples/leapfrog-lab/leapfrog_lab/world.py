"""A particle world stepped by drift-kick-drift leapfrog (position Verlet).

One step of ``h`` seconds::

    x_half = x + h v / 2                     drift half a step
    a      = F(x_half, v) / m                forces at the midpoint
    v'     = v + h a                         kick
    x'     = x_half + h v' / 2               drift the other half
    then every plane pushes penetrating particles back out and reflects their
    normal velocity: v_N' = -e v_N

Second order and symplectic for position-dependent forces (the damping of springs and
the drag read ``v`` at the start of the step, which makes those terms first order).
Forces: uniform gravity, linear drag ``-k v``, springs and anchored springs with the
damper ``-k_d ((v_i - v_j) . u) u``. Arrays are structure of arrays: ``x``, ``v`` shape
``(n, 3)`` in m and m/s, ``m`` shape ``(n,)`` in kg.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class World:
    """The state and parameters of a scene. Pinned particles (``fixed``) never move."""

    x: np.ndarray
    v: np.ndarray
    m: np.ndarray
    fixed: np.ndarray
    radius: np.ndarray
    gravity: np.ndarray
    drag: float = 0.0
    springs: tuple = ()  # (i, j, stiffness, damping, rest), arrays of shape (s,)
    anchors: tuple = ()  # (i, point (a, 3), stiffness, damping, rest)
    planes: tuple = ()  # ((point (3,), unit normal (3,), restitution), ...)

    def forces(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Total force on every particle at positions ``x`` and velocities ``v``, N."""
        f = self.m[:, None] * self.gravity - self.drag * v
        if self.springs:
            i, j, k, c, rest = self.springs
            f_ij = spring_force(x[i] - x[j], v[i] - v[j], k, c, rest)
            np.add.at(f, i, f_ij)
            np.add.at(f, j, -f_ij)
        if self.anchors:
            i, point, k, c, rest = self.anchors
            np.add.at(f, i, spring_force(x[i] - point, v[i], k, c, rest))
        return f

    def step(self, h: float) -> None:
        """One drift-kick-drift step of ``h`` seconds, then the plane collisions."""
        free = ~self.fixed
        x_half = self.x + 0.5 * h * self.v
        a = self.forces(x_half, self.v) / self.m[:, None]
        v_new = np.where(free[:, None], self.v + h * a, self.v)
        self.x = np.where(free[:, None], x_half + 0.5 * h * v_new, self.x)
        self.v = v_new
        for point, normal, e in self.planes:
            collide(self.x, self.v, self.radius, point, normal, e)


def spring_force(d: np.ndarray, dv: np.ndarray, k: np.ndarray, c: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """Force on the first end of springs with ends ``d`` apart (s, 3), relative
    velocity ``dv``: ``-(k (|d| - rest) + c (dv . u)) u``, ``u = d / |d|``."""
    length = np.linalg.norm(d, axis=1)
    u = d / np.where(length > 0, length, 1.0)[:, None]
    along = np.einsum("ij,ij->i", dv, u)
    return -(k * (length - rest) + c * along)[:, None] * u


def collide(
    x: np.ndarray, v: np.ndarray, radius: np.ndarray, point: np.ndarray, normal: np.ndarray, e: float
) -> None:
    """Push particles inside the plane back onto it and reflect their normal velocity
    (``v_N -> -e v_N``) when they move into it; ``x``, ``v`` changed in place."""
    depth = (x - point) @ normal - radius
    hit = depth < 0
    if not np.any(hit):
        return
    x[hit] -= depth[hit, None] * normal
    vn = v[hit] @ normal
    into = vn < 0
    v_t = v[hit] - vn[:, None] * normal
    v[hit] = np.where(into[:, None], v_t - e * vn[:, None] * normal, v[hit])
