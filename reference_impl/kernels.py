"""A compiled fast path for the simplest particle scene: independent particles in rain.

:func:`rain_step` advances particles under uniform gravity and viscous drag with the
lecture's update, ``v' = v + a dt`` and ``p' = p + (v + v') dt / 2``, and after every
step applies the point-plane collision and contact pass of
:mod:`reference_impl.collisions` against one plane (no friction). It computes the same
formulas, in the same order, as :class:`~reference_impl.particles.ParticleSystem` with
:class:`~reference_impl.solvers.LectureUpdate` and
:class:`~reference_impl.collisions.PlaneCollisions`, fused into one loop so that each
particle's state is read and written once per call instead of once per numpy temporary.

Particles do not interact, so each block of particles can take all ``n_steps`` steps
while it sits in the cache: a block is copied into contiguous per-component arrays (the
compiler vectorises the inner loop over particles), stepped, and copied back. Blocks
are spread over the cores with ``prange``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from reference_impl.collisions import EPS_DISTANCE, EPS_SPEED

BLOCK = 256
"""Particles per block: 7 arrays of BLOCK doubles stay in the L1 cache while stepping."""


@njit(parallel=True, cache=True, fastmath={"contract"})
def rain_step(
    x: np.ndarray,
    v: np.ndarray,
    contact: np.ndarray,
    dt: float,
    g: np.ndarray,
    k_drag: float,
    mass: float,
    radius: float,
    plane_point: np.ndarray,
    plane_normal: np.ndarray,
    restitution: float,
    n_steps: int,
) -> None:
    """Take ``n_steps`` lecture steps of ``dt`` seconds for every particle, in place.

    Parameters
    ----------
    x, v : ndarray, shape (n, 3), float64
        Positions (m) and velocities (m/s), overwritten with the new state.
    contact : ndarray of bool, shape (n,)
        Particles in contact with the plane (in and out), as ``ParticleSystem.contact[0]``.
    dt : float, s;  g : ndarray, shape (3,), m/s^2;  k_drag : float, N s/m
    mass : float, kg (every particle);  radius : float, m (every particle)
    plane_point, plane_normal : ndarray, shape (3,)   the plane, unit normal
    restitution : float   k_r in ``V' = V_T - k_r V_N``
    n_steps : int
    """
    n = x.shape[0]
    inv_m = 1.0 / mass
    nx, ny, nz = plane_normal[0], plane_normal[1], plane_normal[2]
    px, py, pz = plane_point[0], plane_point[1], plane_point[2]
    mgx, mgy, mgz = mass * g[0], mass * g[1], mass * g[2]
    n_blocks = (n + BLOCK - 1) // BLOCK
    for b in prange(n_blocks):
        lo = b * BLOCK
        m = min(BLOCK, n - lo)
        X = np.empty((3, BLOCK))
        V = np.empty((3, BLOCK))
        C = np.empty(BLOCK, dtype=np.bool_)
        for j in range(m):
            for c in range(3):
                X[c, j] = x[lo + j, c]
                V[c, j] = v[lo + j, c]
            C[j] = contact[lo + j]
        for _ in range(n_steps):
            for j in range(m):
                # derivative: applied force, then the contact force F' = F_T
                fx = mgx - k_drag * V[0, j]
                fy = mgy - k_drag * V[1, j]
                fz = mgz - k_drag * V[2, j]
                if C[j]:
                    press = min(fx * nx + fy * ny + fz * nz, 0.0)
                    fx -= press * nx
                    fy -= press * ny
                    fz -= press * nz
                # the lecture's update
                wx = V[0, j] + dt * (fx * inv_m)
                wy = V[1, j] + dt * (fy * inv_m)
                wz = V[2, j] + dt * (fz * inv_m)
                X[0, j] = X[0, j] + 0.5 * dt * (V[0, j] + wx)
                X[1, j] = X[1, j] + 0.5 * dt * (V[1, j] + wy)
                X[2, j] = X[2, j] + 0.5 * dt * (V[2, j] + wz)
                # the collision pass
                d = (X[0, j] - px) * nx + (X[1, j] - py) * ny + (X[2, j] - pz) * nz - radius
                on = False
                if d < EPS_DISTANCE:
                    an = ((mgx - k_drag * wx) * nx + (mgy - k_drag * wy) * ny
                          + (mgz - k_drag * wz) * nz) * inv_m
                    vn = wx * nx + wy * ny + wz * nz
                    vn_new = vn
                    if d < 0.0:  # lift onto the plane, paying the normal force's work
                        vn_new = np.sign(vn) * np.sqrt(max(vn * vn - 2.0 * an * d, 0.0))
                        X[0, j] -= d * nx
                        X[1, j] -= d * ny
                        X[2, j] -= d * nz
                        d = 0.0
                    if vn_new < 0.0:  # heading in: V' = V_T - k_r V_N
                        vn_new = -restitution * vn_new
                    if abs(d) < EPS_DISTANCE and an < 0.0 and abs(vn_new) <= EPS_SPEED - an * dt:
                        on = True  # on the wall, moving along it, pushing against it
                        vn_new = 0.0
                        X[0, j] -= d * nx
                        X[1, j] -= d * ny
                        X[2, j] -= d * nz
                    wx += (vn_new - vn) * nx
                    wy += (vn_new - vn) * ny
                    wz += (vn_new - vn) * nz
                V[0, j] = wx
                V[1, j] = wy
                V[2, j] = wz
                C[j] = on
        for j in range(m):
            for c in range(3):
                x[lo + j, c] = X[c, j]
                v[lo + j, c] = V[c, j]
            contact[lo + j] = C[j]
