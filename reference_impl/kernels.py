"""A compiled fast path for the simplest particle scene: independent particles in rain.

:func:`rain_run` advances particles under uniform gravity and viscous drag with the
lecture's update, ``v' = v + a dt`` and ``p' = p + (v + v') dt / 2``, and after every
step applies the point-plane collision and contact pass of
:mod:`truestep.reference_impl.collisions` against one plane (no friction). It computes the same
formulas, in the same order, as :class:`~truestep.reference_impl.particles.ParticleSystem` with
:class:`~truestep.reference_impl.solvers.LectureUpdate` and
:class:`~truestep.reference_impl.collisions.PlaneCollisions`, fused into one loop so that each
particle's state is read and written once per call instead of once per numpy temporary.
The compiler may fuse a multiply and an add into one rounding (``fastmath="contract"``):
results differ from the numpy path by round-off only.

Particles do not interact, so each block of particles can take all ``n_steps`` steps
while it sits in the cache: a block is copied into contiguous per-component arrays,
stepped by :func:`step_block`, and copied back; blocks are spread over the cores with
``prange``. Each step is the lecture's two stages: the solver step for every particle
of the block (a loop the compiler vectorises), then the collision pass for the few
particles that ended within eps of the plane.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from truestep.reference_impl.collisions import EPS_DISTANCE, EPS_SPEED

BLOCK = 256
"""Particles per block: the block's 8 arrays of BLOCK doubles stay in the L1 cache."""


@njit(cache=True, fastmath={"contract"})
def step_block(
    X: np.ndarray,
    V: np.ndarray,
    C: np.ndarray,
    D: np.ndarray,
    m: int,
    dt: float,
    mg: np.ndarray,
    k_drag: float,
    inv_m: float,
    point: np.ndarray,
    normal: np.ndarray,
    radius: float,
    restitution: float,
    n_steps: int,
) -> None:
    """``n_steps`` lecture steps and collision passes for the first ``m`` particles of a block.

    X, V : (3, BLOCK) positions and velocities, one row per component (m, m/s);
    C : (BLOCK,) 1.0 for particles in contact, else 0.0; D : (BLOCK,) scratch for the
    signed distance of each contact point from the plane; mg : (3,) the weight ``m g``.
    """
    nx, ny, nz = normal[0], normal[1], normal[2]
    px, py, pz = point[0], point[1], point[2]
    mgx, mgy, mgz = mg[0], mg[1], mg[2]
    for _ in range(n_steps):
        # 1. the solver step, every particle of the block
        for j in range(m):
            # derivative: the applied force, then the contact force F' = F_T
            fx = mgx - k_drag * V[0, j]
            fy = mgy - k_drag * V[1, j]
            fz = mgz - k_drag * V[2, j]
            if C[j] > 0.0:
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
            V[0, j] = wx
            V[1, j] = wy
            V[2, j] = wz
            D[j] = (X[0, j] - px) * nx + (X[1, j] - py) * ny + (X[2, j] - pz) * nz - radius
        # 2. the collision pass, for the particles within eps of the plane
        for j in range(m):
            C[j] = 0.0
            d = D[j]
            if d < EPS_DISTANCE:
                wx, wy, wz = V[0, j], V[1, j], V[2, j]
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
                    C[j] = 1.0  # on the wall, moving along it, pushing against it
                    vn_new = 0.0
                    X[0, j] -= d * nx
                    X[1, j] -= d * ny
                    X[2, j] -= d * nz
                V[0, j] = wx + (vn_new - vn) * nx
                V[1, j] = wy + (vn_new - vn) * ny
                V[2, j] = wz + (vn_new - vn) * nz


def _rain_run(
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
    stretches: np.ndarray,
    xs: np.ndarray,
    vs: np.ndarray,
) -> None:
    """Take ``stretches[k]`` lecture steps of ``dt`` seconds, then record, for each ``k``.

    One parallel launch for a whole run: each block of particles takes every step while
    it sits in the cache, writing its records on the way.

    Parameters
    ----------
    x, v : ndarray, shape (n, 3), float64
        Positions (m) and velocities (m/s), overwritten with the final state.
    contact : ndarray of bool, shape (n,)
        Particles in contact with the plane (in and out), as ``ParticleSystem.contact[0]``.
    dt : float, s;  g : ndarray, shape (3,), m/s^2;  k_drag : float, N s/m
    mass : float, kg (every particle);  radius : float, m (every particle)
    plane_point, plane_normal : ndarray, shape (3,)   the plane, unit normal
    restitution : float   k_r in ``V' = V_T - k_r V_N``
    stretches : ndarray of int, shape (K,)   steps before each record
    xs, vs : ndarray, shape (K, n, 3)   the records (written), or shape (0, 0, 3): none
    """
    n = x.shape[0]
    mg = mass * g
    record = xs.shape[0] == stretches.shape[0]
    n_blocks = (n + BLOCK - 1) // BLOCK
    for b in prange(n_blocks):
        lo = b * BLOCK
        m = min(BLOCK, n - lo)
        X = np.empty((3, BLOCK))
        V = np.empty((3, BLOCK))
        C = np.empty(BLOCK)
        D = np.empty(BLOCK)
        for j in range(m):
            for c in range(3):
                X[c, j] = x[lo + j, c]
                V[c, j] = v[lo + j, c]
            C[j] = 1.0 if contact[lo + j] else 0.0
        for k in range(stretches.shape[0]):
            step_block(X, V, C, D, m, dt, mg, k_drag, 1.0 / mass, plane_point, plane_normal,
                       radius, restitution, stretches[k])
            if record:
                for j in range(m):
                    for c in range(3):
                        xs[k, lo + j, c] = X[c, j]
                        vs[k, lo + j, c] = V[c, j]
        for j in range(m):
            for c in range(3):
                x[lo + j, c] = X[c, j]
                v[lo + j, c] = V[c, j]
            contact[lo + j] = C[j] > 0.0


rain_run = njit(parallel=True, cache=True)(_rain_run)
"""The run on every core (blocks of particles in parallel): the benchmarks' throughput."""
rain_run_serial = njit(cache=True)(_rain_run)
"""The same loops on one thread. A process that has started numba's parallel layer must
not fork (its children are killed on their first parallel loop); the serial kernel
starts nothing, so the harness, which forks a process per run, uses it."""

_NO_RECORDS = np.zeros((0, 0, 3))


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
    """Take ``n_steps`` lecture steps of ``dt`` seconds for every particle, in place,
    recording nothing: :func:`rain_run` with one stretch (same parameters)."""
    rain_run(x, v, contact, dt, g, k_drag, mass, radius, plane_point, plane_normal,
             restitution, np.array([n_steps]), _NO_RECORDS, _NO_RECORDS)

