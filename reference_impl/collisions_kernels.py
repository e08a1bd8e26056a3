"""Point-plane collision and contact of :mod:`~truestep.reference_impl.collisions`, compiled.

One particle against one plane, on 3-tuples: the same formulas as the numpy pass
:class:`~truestep.reference_impl.collisions.PlaneCollisions` and
:func:`~truestep.reference_impl.collisions.add_contact_forces`, in the same order, so that
every layout of a compiled step (:mod:`~truestep.reference_impl.tiles`) collides its
particles with these functions and nothing else. A scene's planes are a tuple of
:class:`Plane` (the pass treats them in order), or ``None`` for a scene without planes.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from numba import njit

from truestep.reference_impl.collisions import EPS_DISTANCE, EPS_SPEED
from truestep.reference_impl.forces_kernels import LEAF


class Plane(NamedTuple):
    """A collision plane ``(X - point) . normal = 0`` (:class:`model.Plane`): ``point`` (m)
    and unit ``normal`` as 3-tuples, ``restitution``, ``friction`` (Coulomb mu) and
    ``thickness`` (m; 0 for a half-space)."""

    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    restitution: float
    friction: float
    thickness: float


@njit(**LEAF)
def dot(a, b):
    """``a . b`` of two 3-tuples, summed in the order of the components."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(**LEAF)
def signed_distance(x, radius, plane):
    """``d = (X - P) . N - r`` (m) of a particle at ``x`` with ``radius``:
    :func:`collisions.signed_distances`."""
    p, n = plane.point, plane.normal
    return ((x[0] - p[0]) * n[0] + (x[1] - p[1]) * n[1] + (x[2] - p[2]) * n[2]) - radius


@njit(**LEAF)
def within(d, radius, plane):
    """Whether a particle at signed distance ``d`` is within eps of ``plane`` and has not
    crossed the whole of a thin wall (the ``inside`` test of ``PlaneCollisions``)."""
    if not d < EPS_DISTANCE:
        return False
    return not (plane.thickness > 0.0 and not d > -(plane.thickness + 2.0 * radius))


@njit(**LEAF)
def contact_force(f, v, plane):
    """The applied force ``f`` (N) of a particle in contact with ``plane``, moving at
    ``v`` (m/s), with the contact force added: the push into the plane cancelled, then
    Coulomb friction, kinetic on the tangential velocity or static up to its limit.
    :func:`collisions.add_contact_forces` for one particle and one plane."""
    n0, n1, n2 = plane.normal
    f0, f1, f2 = f
    press = min(f0 * n0 + f1 * n1 + f2 * n2, 0.0)
    f0 -= press * n0
    f1 -= press * n1
    f2 -= press * n2
    mu = plane.friction
    if not mu > 0.0:
        return (f0, f1, f2)
    limit = -mu * press
    vn = dot(v, plane.normal)
    t0, t1, t2 = v[0] - vn * n0, v[1] - vn * n1, v[2] - vn * n2
    speed = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    ffn = f0 * n0 + f1 * n1 + f2 * n2
    s0, s1, s2 = f0 - ffn * n0, f1 - ffn * n1, f2 - ffn * n2
    ft = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    if speed > 0.0:
        kinetic = limit / speed
        return (f0 - kinetic * t0, f1 - kinetic * t1, f2 - kinetic * t2)
    if ft <= limit:
        return (f0 - s0, f1 - s1, f2 - s2)
    static = limit / ft
    return (f0 - static * s0, f1 - static * s1, f2 - static * s2)


@njit(**LEAF)
def sticking(w, f, fn, an, plane, dt):
    """Whether friction stops a particle in contact within the step (``PlaneCollisions.
    _sticking``): its tangential speed (of ``w``, m/s) at most ``eps_v + mu |a_N| dt`` and
    its tangential force (of ``f``, N) at most ``mu |F_N|``."""
    n0, n1, n2 = plane.normal
    mu = plane.friction
    un = w[0] * n0 + w[1] * n1 + w[2] * n2
    t0, t1, t2 = w[0] - un * n0, w[1] - un * n1, w[2] - un * n2
    speed = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    s0, s1, s2 = f[0] - fn * n0, f[1] - fn * n1, f[2] - fn * n2
    ft = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    return speed <= EPS_SPEED - mu * an * dt and ft <= -mu * fn


@njit(**LEAF)
def collide(x, v, f, inv_mass, d, plane, dt):
    """Penetration, collision and contact of one particle within eps of ``plane``
    (``PlaneCollisions._collide``): at ``x`` (m), ``v`` (m/s), signed distance ``d`` (m),
    under the applied force ``f`` (N) at the end of a step of ``dt`` (s). Returns the new
    ``(x, v, on)``, ``on`` whether it is in contact now."""
    n0, n1, n2 = plane.normal
    x0, x1, x2 = x
    fn = f[0] * n0 + f[1] * n1 + f[2] * n2
    vn = v[0] * n0 + v[1] * n1 + v[2] * n2
    an = fn * inv_mass
    vn_new = vn
    if d < 0.0:  # lifted onto the plane, paying the work of its normal force
        sign = 1.0 if vn > 0.0 else (-1.0 if vn < 0.0 else 0.0)
        vn_new = sign * math.sqrt(max(vn * vn - 2.0 * an * d, 0.0))
        x0, x1, x2 = x0 - d * n0, x1 - d * n1, x2 - d * n2
        d = 0.0
    if vn_new < 0.0:
        vn_new = -plane.restitution * vn_new
    on = abs(d) < EPS_DISTANCE and an < 0.0 and abs(vn_new) <= EPS_SPEED - an * dt
    if on:
        vn_new = 0.0
        x0, x1, x2 = x0 - d * n0, x1 - d * n1, x2 - d * n2
    w0 = v[0] + (vn_new - vn) * n0
    w1 = v[1] + (vn_new - vn) * n1
    w2 = v[2] + (vn_new - vn) * n2
    if plane.friction > 0.0 and on and sticking((w0, w1, w2), f, fn, an, plane, dt):
        w0 -= w0 - vn_new * n0
        w1 -= w1 - vn_new * n1
        w2 -= w2 - vn_new * n2
    return (x0, x1, x2), (w0, w1, w2), on
