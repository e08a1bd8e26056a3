"""Force objects: each adds its force into the accumulator ``f`` and does nothing else.

"Unlike particles, forces are heterogeneous. Force objects: black boxes, point to the
particles they influence, add in their own forces." Every function here takes the
positions ``x`` and velocities ``v`` (shape ``(n, 3)``, m and m/s), the time ``t``
(s) and the accumulator ``f`` (shape ``(n, 3)``, N), vectorised over all particles,
and adds into ``f`` in place. Potential energies (J) sit beside the forces that have one.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from truestep.reference_impl.forces_kernels import (
    TIME_ROUNDOFF,
    add_anchor_forces,
    add_spring_forces,
)
from truestep.reference_impl.model import Anchors, ForceField, Gravitation, ParticleModel, Springs

EARTH_MASS = 5.972e24
"""kg."""
EARTH_RADIUS = 6.371e6
"""Mean radius, m."""


def earth_gravity(G: float = 6.67384e-11) -> float:
    """The lecture's Earth model ``a_e = G m_e / r_e^2`` (m/s^2), about 9.8."""
    return G * EARTH_MASS / EARTH_RADIUS**2


def add_gravity(f: np.ndarray, mass: np.ndarray, g: np.ndarray) -> None:
    """Constant gravity ``f = m g``; ``mass`` shape (n,), ``g`` shape (3,) m/s^2."""
    f += mass[:, None] * g


def add_drag(f: np.ndarray, v: np.ndarray, k_drag: float) -> None:
    """Viscous drag ``f = -k_drag v`` (``k_drag`` in N s/m): "Highly recommended!"."""
    f -= k_drag * v


def spring_forces(
    dx: np.ndarray,
    dv: np.ndarray,
    stiffness: np.ndarray,
    damping: np.ndarray,
    rest: np.ndarray,
) -> np.ndarray:
    """The lecture's damped spring, force on the first end of each spring.

    ``f_1 = -[k_s (|dx| - r) + k_d (dv . dx) / |dx|] dx / |dx|`` with ``dx = x_1 - x_2``
    and ``dv = v_1 - v_2``, all shape (m, 3); ``f_2 = -f_1``. A stretched spring pulls
    the ends together and the damper resists the rate of change of length. (The
    slide's spring-damper pair writes the damper term with a minus sign inside the
    bracket; with ``f`` the force on ``p_1`` and ``p_2 - p_1`` as the direction both terms
    must carry the same sign, as in this form, or the damper would pump energy in.)
    A zero-length spring (``|dx| = 0``) exerts no force: its direction is undefined.
    """
    length = np.sqrt(np.einsum("ij,ij->i", dx, dx))
    unit = dx / np.where(length > 0, length, 1.0)[:, None]  # dx = 0 gives unit = 0: no force
    magnitude = stiffness * (length - rest) + damping * np.einsum("ij,ij->i", dv, unit)
    return -magnitude[:, None] * unit


def add_springs(f: np.ndarray, x: np.ndarray, v: np.ndarray, s: Springs) -> None:
    """Damped springs between particle pairs ``(s.i, s.j)``: :func:`spring_forces` on the
    first end of each spring, its opposite on the second, spring after spring, in one
    compiled pass (:func:`forces_kernels.add_spring_forces`, on the arrays transposed):
    a small scene costs one compiled call, not the dozen numpy calls of the vectorised form."""
    if len(s):
        add_spring_forces(f.T, x.T, v.T, s.i, s.j, s.stiffness, s.damping, s.rest)


def add_anchors(f: np.ndarray, x: np.ndarray, v: np.ndarray, a: Anchors) -> None:
    """Damped springs from particles ``a.i`` to the fixed points ``a.point``
    (:func:`forces_kernels.add_anchor_forces`)."""
    if len(a):
        add_anchor_forces(f.T, x.T, v.T, a.i, np.asarray(a.point).T, a.stiffness, a.damping, a.rest)


def compile_springs() -> None:
    """Compile the spring loop (or load it from numba's cache) for the argument types
    every scene uses. Processes forked afterwards inherit it; each would otherwise load
    it again on its first spring, every process paying the load."""
    one, point = np.ones(1), np.zeros((1, 3))
    f, x, v = np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3))
    add_springs(f, x, v, Springs(np.array([0]), np.array([1]), one, one, one))
    add_anchors(f, x, v, Anchors(np.array([0]), point, one, one, one))


def spring_jacobians(
    dx: np.ndarray,
    dv: np.ndarray,
    stiffness: np.ndarray,
    damping: np.ndarray,
    rest: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Derivatives of :func:`spring_forces` ``f_1`` by ``dx`` and by ``dv``, each (m, 3, 3).

    With ``L = |dx|``, ``u = dx / L``, ``P = I - u u^T`` and
    ``S = k_s (L - r) + k_d (dv . u)``: ``df_1/ddx = -u (k_s u + k_d P dv / L)^T - S P / L``
    and ``df_1/ddv = -k_d u u^T``. Zero-length springs contribute nothing.
    """
    length = np.sqrt(np.einsum("ij,ij->i", dx, dx))
    ok = length > 0
    safe = np.where(ok, length, 1.0)
    u = dx / safe[:, None]
    uu = u[:, :, None] * u[:, None, :]
    proj = np.eye(3) - uu
    rate = np.einsum("ij,ij->i", dv, u)
    s_mag = stiffness * (length - rest) + damping * rate
    dv_perp = np.einsum("ijk,ik->ij", proj, dv) / safe[:, None]
    grad = stiffness[:, None] * u + damping[:, None] * dv_perp
    jx = -u[:, :, None] * grad[:, None, :] - (s_mag / safe)[:, None, None] * proj
    jv = -damping[:, None, None] * uu
    jx[~ok] = 0.0
    jv[~ok] = 0.0
    return jx, jv


def spring_energy(x: np.ndarray, s: Springs) -> float | np.ndarray:
    """Potential energy ``sum k_s (|dx| - r)^2 / 2`` of springs between pairs, J.

    ``x`` is (n, 3), or (T, n, 3) for T states (the result then has shape (T,)).
    """
    if not len(s):
        return 0.0
    length = np.linalg.norm(x[..., s.i, :] - x[..., s.j, :], axis=-1)
    return 0.5 * np.sum(s.stiffness * (length - s.rest) ** 2, axis=-1)


def anchor_energy(x: np.ndarray, a: Anchors) -> float | np.ndarray:
    """Potential energy of anchored springs, J; ``x`` (n, 3) or (T, n, 3)."""
    if not len(a):
        return 0.0
    length = np.linalg.norm(x[..., a.i, :] - a.point, axis=-1)
    return 0.5 * np.sum(a.stiffness * (length - a.rest) ** 2, axis=-1)


def add_gravitation(f: np.ndarray, x: np.ndarray, mass: np.ndarray, g: Gravitation) -> None:
    """Universal gravitation between all pairs, each pulled toward the other.

    ``f_i = sum_j G m_i m_j (x_j - x_i) / (r_ij^2 + eps^2)^(3/2)``: the lecture's
    ``G m_i m_j / r^2`` along the line between them, softened by ``eps`` (Plummer) so that
    close encounters stay finite. Vectorised over the (n, n) pair matrix: fine for the
    n-body scenes of the lecture (tens of bodies), not meant for thousands.
    """
    d = x[None, :, :] - x[:, None, :]  # d[i, j] = x_j - x_i
    r2 = np.einsum("ijk,ijk->ij", d, d) + g.softening**2
    np.fill_diagonal(r2, np.inf)
    w = g.G * mass[None, :] / (r2 * np.sqrt(r2))
    f += mass[:, None] * np.einsum("ij,ijk->ik", w, d)


def gravitation_jacobian(x: np.ndarray, mass: np.ndarray, g: Gravitation) -> np.ndarray:
    """Blocks ``d f_i / d x_j`` (n, n, 3, 3) of :func:`add_gravitation`.

    For ``j != i``: ``G m_i m_j (I / s^3 - 3 d d^T / s^5)`` with ``d = x_j - x_i`` and
    ``s^2 = |d|^2 + eps^2``; the diagonal block is minus the sum of the others.
    """
    n = len(mass)
    d = x[None, :, :] - x[:, None, :]
    s2 = np.einsum("ijk,ijk->ij", d, d) + g.softening**2
    np.fill_diagonal(s2, np.inf)
    w = g.G * mass[:, None] * mass[None, :] / (s2 * np.sqrt(s2))
    blocks = w[:, :, None, None] * (
        np.eye(3) - 3.0 * d[:, :, :, None] * d[:, :, None, :] / s2[:, :, None, None]
    )
    blocks[np.arange(n), np.arange(n)] = -blocks.sum(axis=1)
    return blocks


def gravitation_energy(x: np.ndarray, mass: np.ndarray, g: Gravitation) -> float | np.ndarray:
    """Potential energy ``-sum_{i<j} G m_i m_j / sqrt(r^2 + eps^2)``, J; ``x`` (n, 3) or
    (T, n, 3)."""
    iu = np.triu_indices(len(mass), 1)
    d = x[..., iu[0], :] - x[..., iu[1], :]
    r = np.sqrt(np.einsum("...k,...k->...", d, d) + g.softening**2)
    return -np.sum(g.G * mass[iu[0]] * mass[iu[1]] / r, axis=-1)


def field_force(field: ForceField, x: np.ndarray, v: np.ndarray, mass: np.ndarray, t: float) -> np.ndarray:
    """The force (N, shape (n, 3)) of a position/time-dependent field on every particle.

    ``vortex``: ``f = strength * m * (axis x r_perp) * min(1, (core / |r_perp|)^2)`` where
    ``r_perp`` is the offset from the axis through ``center``: a swirl about the axis that
    grows linearly with distance inside the ``core`` radius and falls off as
    ``1 / |r_perp|`` outside it (a Rankine-like vortex); parameters ``center`` (3,),
    ``axis`` (3,), ``strength`` (1/s^2), ``core`` (m).

    ``wind``: a gusting wind velocity ``w(t) = direction * (speed + gust * sin(2 pi freq t))``
    that drags particles toward it, ``f = k (w(t) - v)``, parameters ``direction`` (3,),
    ``speed`` (m/s), ``gust`` (m/s), ``freq`` (Hz), ``k`` (N s/m).
    """
    p: dict[str, Any] = field.params  # each kind's numbers (float) and vectors (list)
    if field.kind == "vortex":
        center = np.asarray(p.get("center", [0.0, 0.0, 0.0]), float)
        axis = np.asarray(p.get("axis", [0.0, 1.0, 0.0]), float)
        axis = axis / np.linalg.norm(axis)
        r = x - center
        r_perp = r - np.outer(r @ axis, axis)
        dist = np.linalg.norm(r_perp, axis=1)
        core = float(p.get("core", 0.5))
        falloff = np.where(dist < core, 1.0, (core / np.maximum(dist, 1e-300)) ** 2)
        return float(p["strength"]) * mass[:, None] * falloff[:, None] * np.cross(axis, r_perp)
    if field.kind == "wind":
        direction = np.asarray(p["direction"], float)
        direction = direction / np.linalg.norm(direction)
        speed = float(p.get("speed", 0.0)) + float(p.get("gust", 0.0)) * np.sin(
            2 * np.pi * float(p.get("freq", 0.0)) * t
        )
        return float(p.get("k", 1.0)) * (speed * direction - v)
    raise ValueError(f"force field: unknown kind {field.kind!r} (known: vortex, wind)")


def add_fields(
    f: np.ndarray,
    fields: list[ForceField],
    x: np.ndarray,
    v: np.ndarray,
    mass: np.ndarray,
    t: float,
) -> None:
    """Add every force field's force."""
    for fld in fields:
        f += field_force(fld, x, v, mass, t)


def add_model_forces(
    f: np.ndarray,
    model: ParticleModel,
    x: np.ndarray,
    v: np.ndarray,
    t: float,
    *,
    gravity: bool = True,
) -> np.ndarray:
    """The lecture's force loop for a whole scene: clear ``f`` (n, 3), then let every force
    object of ``model`` add in (gravity unless ``gravity=False``, drag, springs, anchors,
    gravitation, fields, impulses active at ``t``). Returns ``f``, N.

    Engines that integrate gravity themselves call it with ``gravity=False``.
    """
    f[:] = 0.0
    if gravity and np.any(model.gravity):
        add_gravity(f, model.mass, model.gravity)
    if model.drag:
        add_drag(f, v, model.drag)
    add_springs(f, x, v, model.springs)
    add_anchors(f, x, v, model.anchors)
    if model.gravitation is not None:
        add_gravitation(f, x, model.mass, model.gravitation)
    if model.fields:
        add_fields(f, model.fields, x, v, model.mass, t)
    add_impulses(f, model.impulses, t)
    return f


def impulse_active(t_on: float, t_off: float, t: float) -> bool:
    """Whether a force acting over ``[t_on, t_off)`` (s) acts at time ``t`` (s), the ends
    compared with a margin of :data:`TIME_ROUNDOFF` (relative, at least 1e-9 s)."""
    eps = TIME_ROUNDOFF * max(1.0, abs(t))
    return t_on - eps <= t < t_off - eps


def add_impulses(f: np.ndarray, impulses: list, t: float) -> np.ndarray:
    """Add every impulse force (particle, force (3,) N, t_on, t_off) active at ``t`` into ``f``."""
    for i, force, t_on, t_off in impulses:
        if impulse_active(t_on, t_off, t):
            f[i] += force
    return f
