"""The reference's fixed-step methods on a particle scene, the whole run compiled.

:func:`run_compiled` takes a :class:`~truestep.reference_impl.model.ParticleModel` and a
fixed-step method of :mod:`truestep.reference_impl.solvers` (``euler``, ``midpoint``,
``heun``, ``rk4``, ``symplectic-euler``, ``verlet``, ``lecture``) and runs the same loop
as :func:`~truestep.reference_impl.integrate.integrate` over a
:class:`~truestep.reference_impl.particles.ParticleSystem` with its passes: every step
the method's stages, each stage the lecture's derivative (clear the accumulator, let each
force the scene has add in, the contact force for particles resting on a plane, divide by
the masses), then the point-plane collision and contact pass of
:mod:`truestep.reference_impl.collisions`; the recorded steps and the blow-up check every
:data:`CHECK_EVERY` steps as ``integrate`` makes them. The formulas are the same, in the
same order, written as loops over particles: results equal the numpy path's to
round-off (tested on every case and method), and the Python overhead per step is gone.

Assembled from what the scene has: the scene is packed into arrays once
(:class:`PackedScene`), and the derivative runs only the force loops the scene needs
(gravity, drag, springs, anchors, universal gravitation, impulses, contact). Scenes with
force fields or emitters are not compiled (:func:`compiled_reason` says why) and run on
the numpy path; implicit Euler (a Newton solve per step) and dopri5 (adaptive) stay
there too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from truestep.reference_impl.collisions import EPS_DISTANCE, EPS_SPEED
from truestep.reference_impl.forces import TIME_ROUNDOFF, _add_spring_loop
from truestep.reference_impl.integrate import BLOWUP, record_indices
from truestep.reference_impl.model import ParticleModel

CHECK_EVERY = 64
"""Steps between blow-up checks, as in :func:`~truestep.reference_impl.integrate.integrate`."""
RK, SYMPLECTIC_EULER, VERLET, LECTURE = 0, 1, 2, 3
"""The kinds of step the compiled loop takes."""
SPLITTING = {"symplectic-euler": SYMPLECTIC_EULER, "verlet": VERLET, "lecture": LECTURE}
_NO_INT = np.zeros(0, dtype=np.int64)
_NO_POINTS = np.zeros((0, 3))


def independent(model: ParticleModel) -> bool:
    """Whether no particle of ``model`` acts on another (no springs, anchors or
    gravitation): then each takes its whole step alone (:func:`_run_independent`)."""
    return not len(model.springs) and not len(model.anchors) and model.gravitation is None


def compiled_reason(model: ParticleModel | None, method: str) -> str | None:
    """Why ``method`` on ``model`` cannot take the compiled path, or ``None`` if it can."""
    from truestep.reference_impl.solvers import METHODS
    from truestep.reference_impl.solvers.explicit_rk import ExplicitRungeKutta

    if model is None:
        return "an ODE case (its system is Python code)"
    cls = METHODS.get(method)
    if cls is None or not (issubclass(cls, ExplicitRungeKutta) or method in SPLITTING):
        return f"{method} is not a fixed-step explicit method"
    if model.fields:
        return "force fields"
    if model.emitters:
        return "emitters"
    return None


@dataclass
class PackedScene:
    """A particle model as the flat arrays the compiled loop reads (float64 / int64).

    mass, inv_mass (0 for pinned particles), radius : (n,);  movable : (n,) bool
    gravity : (3,) m/s^2;  drag : N s/m
    springs (i, j, stiffness, damping, rest) and anchors (i, point (a, 3), stiffness,
    damping, rest);  gravitation: G and softening (``G = 0``: none)
    impulses: particle (k,), force (k, 3) N, start and end (k,) s
    planes: point and unit normal (p, 3), restitution, friction, thickness (p,)
    """

    mass: np.ndarray
    inv_mass: np.ndarray
    radius: np.ndarray
    movable: np.ndarray
    gravity: np.ndarray
    drag: float
    springs: tuple
    anchors: tuple
    gravitation: tuple[float, float]
    impulses: tuple
    planes: tuple

    @classmethod
    def of(cls, m: ParticleModel) -> PackedScene:
        s, a = m.springs, m.anchors
        f64 = lambda arr: np.ascontiguousarray(arr, dtype=np.float64)  # noqa: E731
        i64 = lambda arr: np.ascontiguousarray(arr, dtype=np.int64)  # noqa: E731
        imp = m.impulses
        return cls(
            mass=f64(m.mass), inv_mass=f64(np.where(m.fixed, 0.0, 1.0 / m.mass)),
            radius=f64(m.radius), movable=np.ascontiguousarray(~m.fixed),
            gravity=f64(m.gravity), drag=float(m.drag),
            springs=(i64(s.i), i64(s.j), f64(s.stiffness), f64(s.damping), f64(s.rest)),
            anchors=(i64(a.i), f64(a.point).reshape(-1, 3), f64(a.stiffness), f64(a.damping),
                     f64(a.rest)),
            gravitation=((float(m.gravitation.G), float(m.gravitation.softening))
                         if m.gravitation is not None else (0.0, 0.0)),
            impulses=(i64([i for i, _, _, _ in imp]), f64([f for _, f, _, _ in imp]).reshape(-1, 3),
                      f64([t0 for _, _, t0, _ in imp]), f64([t1 for _, _, _, t1 in imp])),
            planes=(f64([p.point for p in m.planes]).reshape(-1, 3),
                    f64([p.normal for p in m.planes]).reshape(-1, 3),
                    f64([p.restitution for p in m.planes]), f64([p.friction for p in m.planes]),
                    f64([p.thickness for p in m.planes])),
        )

    def impulses_by_particle(self) -> tuple:
        """The impulses sorted by particle (stably: each particle's in the case's order),
        with ``ptr`` (n + 1,): particle ``p``'s are entries ``ptr[p]`` to ``ptr[p + 1]``."""
        i, force, start, end = self.impulses
        order = np.argsort(i, kind="stable")
        ptr = np.zeros(len(self.mass) + 1, dtype=np.int64)
        np.add.at(ptr, i + 1, 1)
        return (np.cumsum(ptr), np.ascontiguousarray(force[order]),
                np.ascontiguousarray(start[order]), np.ascontiguousarray(end[order]))

    def args(self) -> tuple:
        """The arrays in the order the compiled functions take them."""
        return (self.mass, self.inv_mass, self.radius, self.movable, self.gravity, self.drag,
                *self.springs, *self.anchors, *self.gravitation, *self.impulses, *self.planes)


@njit(cache=True, error_model="numpy")
def _applied_forces(f, x, v, t, mass, gravity, drag, si, sj, sk, sc, sr, ai, ap, ak, ac, ar,
                    grav_g, grav_eps, imp_i, imp_f, imp_on, imp_off):
    """The applied forces (N, (n, 3), into ``f``): :func:`forces.add_model_forces` without
    fields, each force adding in the same order."""
    n = x.shape[0]
    for p in range(n):
        f[p, 0] = 0.0
        f[p, 1] = 0.0
        f[p, 2] = 0.0
    if gravity[0] != 0.0 or gravity[1] != 0.0 or gravity[2] != 0.0:
        for p in range(n):
            f[p, 0] += mass[p] * gravity[0]
            f[p, 1] += mass[p] * gravity[1]
            f[p, 2] += mass[p] * gravity[2]
    if drag != 0.0:
        for p in range(n):
            f[p, 0] -= drag * v[p, 0]
            f[p, 1] -= drag * v[p, 1]
            f[p, 2] -= drag * v[p, 2]
    if si.shape[0] > 0:
        _add_spring_loop(f, x, v, si, sj, ap[:0], sk, sc, sr)
    if ai.shape[0] > 0:
        _add_spring_loop(f, x, v, ai, si[:0], ap, ak, ac, ar)
    if grav_g != 0.0:
        eps2 = grav_eps * grav_eps
        for p in range(n):
            g0 = 0.0
            g1 = 0.0
            g2 = 0.0
            for q in range(n):
                if q == p:
                    continue
                d0 = x[q, 0] - x[p, 0]
                d1 = x[q, 1] - x[p, 1]
                d2 = x[q, 2] - x[p, 2]
                r2 = d0 * d0 + d1 * d1 + d2 * d2 + eps2
                w = grav_g * mass[q] / (r2 * math.sqrt(r2))
                g0 += w * d0
                g1 += w * d1
                g2 += w * d2
            f[p, 0] += mass[p] * g0
            f[p, 1] += mass[p] * g1
            f[p, 2] += mass[p] * g2
    eps = TIME_ROUNDOFF * max(1.0, abs(t))
    for k in range(imp_i.shape[0]):
        if imp_on[k] - eps <= t < imp_off[k] - eps:
            p = imp_i[k]
            f[p, 0] += imp_f[k, 0]
            f[p, 1] += imp_f[k, 1]
            f[p, 2] += imp_f[k, 2]


@njit(cache=True, error_model="numpy", inline="always")
def _plane_contact(f0, f1, f2, v0, v1, v2, n0, n1, n2, mu):
    """One particle's applied force ``f`` (N) with a plane's contact force added: the
    push into the plane (unit normal ``n``) cancelled, then Coulomb friction ``mu`` on
    the tangential velocity ``v`` (kinetic), or holding it at rest (static, up to the
    limit): :func:`collisions.add_contact_forces` for one particle and one plane."""
    press = min(f0 * n0 + f1 * n1 + f2 * n2, 0.0)
    f0 -= press * n0
    f1 -= press * n1
    f2 -= press * n2
    if mu > 0.0:
        limit = -mu * press
        vn = v0 * n0 + v1 * n1 + v2 * n2
        t0, t1, t2 = v0 - vn * n0, v1 - vn * n1, v2 - vn * n2
        speed = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        ffn = f0 * n0 + f1 * n1 + f2 * n2
        s0, s1, s2 = f0 - ffn * n0, f1 - ffn * n1, f2 - ffn * n2
        ft = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        if speed > 0.0:
            kinetic = limit / speed
            f0 -= kinetic * t0
            f1 -= kinetic * t1
            f2 -= kinetic * t2
        elif ft <= limit:
            f0 -= s0
            f1 -= s1
            f2 -= s2
        else:
            static = limit / ft
            f0 -= static * s0
            f1 -= static * s1
            f2 -= static * s2
    return f0, f1, f2


@njit(cache=True, error_model="numpy")
def _add_contact_forces(f, v, contact, pn, pmu):
    """:func:`collisions.add_contact_forces` for the particles in contact."""
    n = f.shape[0]
    for k in range(pn.shape[0]):
        n0, n1, n2 = pn[k, 0], pn[k, 1], pn[k, 2]
        mu = pmu[k]
        for p in range(n):
            if not contact[k, p]:
                continue
            f[p, 0], f[p, 1], f[p, 2] = _plane_contact(f[p, 0], f[p, 1], f[p, 2], v[p, 0],
                                                       v[p, 1], v[p, 2], n0, n1, n2, mu)


@njit(cache=True, error_model="numpy")
def _acceleration(a, f, x, v, t, contact, any_contact, mass, inv_mass, gravity, drag, si, sj,
                  sk, sc, sr, ai, ap, ak, ac, ar, grav_g, grav_eps, imp_i, imp_f, imp_on,
                  imp_off, pn, pmu):
    """``a = F / m`` (m/s^2, (n, 3)): :meth:`ParticleSystem.acceleration`."""
    _applied_forces(f, x, v, t, mass, gravity, drag, si, sj, sk, sc, sr, ai, ap, ak, ac, ar,
                    grav_g, grav_eps, imp_i, imp_f, imp_on, imp_off)
    if any_contact:
        _add_contact_forces(f, v, contact, pn, pmu)
    for p in range(f.shape[0]):
        a[p, 0] = f[p, 0] * inv_mass[p]
        a[p, 1] = f[p, 1] * inv_mass[p]
        a[p, 2] = f[p, 2] * inv_mass[p]


@njit(cache=True, error_model="numpy")
def _collide(x, v, t, dt, contact, f, radius, movable, inv_mass, mass, gravity, drag, si, sj,
             sk, sc, sr, ai, ap, ak, ac, ar, grav_g, grav_eps, imp_i, imp_f, imp_on, imp_off,
             pp, pn, pe, pmu, pth):
    """The collision and contact pass (:class:`collisions.PlaneCollisions`) after a step of
    ``dt`` s ending at ``t``; returns whether any particle is in contact now."""
    n = x.shape[0]
    any_on = False
    have_force = False
    for k in range(pp.shape[0]):
        for p in range(n):
            contact[k, p] = False
    for k in range(pp.shape[0]):
        n0, n1, n2 = pn[k, 0], pn[k, 1], pn[k, 2]
        for p in range(n):
            if not movable[p]:
                continue
            d = ((x[p, 0] - pp[k, 0]) * n0 + (x[p, 1] - pp[k, 1]) * n1
                 + (x[p, 2] - pp[k, 2]) * n2) - radius[p]
            if not d < EPS_DISTANCE:
                continue
            if pth[k] > 0.0 and not d > -(pth[k] + 2.0 * radius[p]):
                continue
            if not have_force:  # the applied force at the end of the step, once per pass
                _applied_forces(f, x, v, t, mass, gravity, drag, si, sj, sk, sc, sr, ai, ap, ak,
                                ac, ar, grav_g, grav_eps, imp_i, imp_f, imp_on, imp_off)
                have_force = True
            fn = f[p, 0] * n0 + f[p, 1] * n1 + f[p, 2] * n2
            vn = v[p, 0] * n0 + v[p, 1] * n1 + v[p, 2] * n2
            an = fn * inv_mass[p]
            vn_new = vn
            if d < 0.0:
                s = 1.0 if vn > 0.0 else (-1.0 if vn < 0.0 else 0.0)
                vn_new = s * math.sqrt(max(vn * vn - 2.0 * an * d, 0.0))
                x[p, 0] -= d * n0
                x[p, 1] -= d * n1
                x[p, 2] -= d * n2
                d = 0.0
            if vn_new < 0.0:
                vn_new = -pe[k] * vn_new
            tol = EPS_SPEED - an * dt
            on = abs(d) < EPS_DISTANCE and an < 0.0 and abs(vn_new) <= tol
            if on:
                vn_new = 0.0
                x[p, 0] -= d * n0
                x[p, 1] -= d * n1
                x[p, 2] -= d * n2
                any_on = True
            v0 = v[p, 0] + (vn_new - vn) * n0
            v1 = v[p, 1] + (vn_new - vn) * n1
            v2 = v[p, 2] + (vn_new - vn) * n2
            if pmu[k] > 0.0 and on:
                mu = pmu[k]
                un = v0 * n0 + v1 * n1 + v2 * n2
                t0, t1, t2 = v0 - un * n0, v1 - un * n1, v2 - un * n2
                speed = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
                s0, s1, s2 = f[p, 0] - fn * n0, f[p, 1] - fn * n1, f[p, 2] - fn * n2
                ft = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
                if speed <= EPS_SPEED - mu * an * dt and ft <= -mu * fn:
                    v0 -= v0 - vn_new * n0
                    v1 -= v1 - vn_new * n1
                    v2 -= v2 - vn_new * n2
            v[p, 0] = v0
            v[p, 1] = v1
            v[p, 2] = v2
            contact[k, p] = on
    return any_on


@njit(cache=True, error_model="numpy")
def _finite(x, v):
    """Every component finite and within BLOWUP (NaN fails both comparisons)."""
    for p in range(x.shape[0]):
        for c in range(3):
            if not (-BLOWUP < x[p, c] < BLOWUP and -BLOWUP < v[p, c] < BLOWUP):
                return False
    return True


@njit(cache=True, error_model="numpy")
def _same_bits(a, b):
    ua = a.reshape(-1).view(np.uint64)
    ub = b.reshape(-1).view(np.uint64)
    for k in range(ua.shape[0]):
        if ua[k] != ub[k]:
            return False
    return True


@njit(cache=True, error_model="numpy")
def _run(kind, rk_a, rk_b, rk_c, x, v, t0, h, n_steps, record, check_every, xs, vs, ts,
         mass, inv_mass, radius, movable, gravity, drag, si, sj, sk, sc, sr, ai, ap, ak, ac,
         ar, grav_g, grav_eps, imp_i, imp_f, imp_on, imp_off, pp, pn, pe, pmu, pth):
    """Step ``n_steps`` steps of ``h`` s from time ``t0``; returns (records kept, steps,
    evaluations, unstable). ``x``, ``v`` (n, 3) hold the state (changed); ``xs``, ``vs``
    (R, n, 3) and ``ts`` (R,) receive the records, the first being the start."""
    n = x.shape[0]
    n_planes = pp.shape[0]
    f = np.zeros((n, 3))
    a = np.zeros((n, 3))
    contact = np.zeros((n_planes, n), dtype=np.bool_)
    stages = rk_b.shape[0]
    kx = np.zeros((stages, n, 3))
    kv = np.zeros((stages, n, 3))
    xi = np.zeros((n, 3))
    vi = np.zeros((n, 3))
    x_new = np.zeros((n, 3))
    v_new = np.zeros((n, 3))
    a_last = np.zeros((n, 3))
    have_last = False
    t = t0
    any_contact = False
    if n_planes > 0:
        any_contact = _collide(x, v, t, 0.0, contact, f, radius, movable, inv_mass, mass,
                               gravity, drag, si, sj, sk, sc, sr, ai, ap, ak, ac, ar, grav_g,
                               grav_eps, imp_i, imp_f, imp_on, imp_off, pp, pn, pe, pmu, pth)
    xs[0] = x
    vs[0] = v
    ts[0] = t
    kept = 1
    checked = 1
    nfev = 0
    steps = 0
    unstable = False
    for i in range(1, n_steps + 1):
        if kind == RK:
            for s in range(stages):
                for p in range(n):
                    for c in range(3):
                        xi[p, c] = x[p, c]
                        vi[p, c] = v[p, c]
                for j in range(s):
                    w = h * rk_a[s, j]
                    if rk_a[s, j] != 0.0:
                        for p in range(n):
                            for c in range(3):
                                xi[p, c] = xi[p, c] + w * kx[j, p, c]
                                vi[p, c] = vi[p, c] + w * kv[j, p, c]
                _acceleration(a, f, xi, vi, t + rk_c[s] * h, contact, any_contact, mass,
                              inv_mass, gravity, drag, si, sj, sk, sc, sr, ai, ap, ak, ac, ar,
                              grav_g, grav_eps, imp_i, imp_f, imp_on, imp_off, pn, pmu)
                nfev += 1
                for p in range(n):
                    for c in range(3):
                        kx[s, p, c] = vi[p, c]
                        kv[s, p, c] = a[p, c]
            for p in range(n):
                for c in range(3):
                    dx = 0.0
                    dv = 0.0
                    for s in range(stages):
                        dx += rk_b[s] * kx[s, p, c]
                        dv += rk_b[s] * kv[s, p, c]
                    x[p, c] = x[p, c] + h * dx
                    v[p, c] = v[p, c] + h * dv
        elif kind == VERLET:
            if not have_last:
                _acceleration(a_last, f, x, v, t, contact, any_contact, mass, inv_mass, gravity,
                              drag, si, sj, sk, sc, sr, ai, ap, ak, ac, ar, grav_g, grav_eps,
                              imp_i, imp_f, imp_on, imp_off, pn, pmu)
                nfev += 1
            for p in range(n):
                for c in range(3):
                    vi[p, c] = v[p, c] + 0.5 * h * a_last[p, c]
                    x[p, c] = x[p, c] + h * vi[p, c]
            _acceleration(a_last, f, x, vi, t + h, contact, any_contact, mass, inv_mass, gravity,
                          drag, si, sj, sk, sc, sr, ai, ap, ak, ac, ar, grav_g, grav_eps, imp_i,
                          imp_f, imp_on, imp_off, pn, pmu)
            nfev += 1
            for p in range(n):
                for c in range(3):
                    v[p, c] = vi[p, c] + 0.5 * h * a_last[p, c]
            have_last = True
        else:
            _acceleration(a, f, x, v, t, contact, any_contact, mass, inv_mass, gravity, drag,
                          si, sj, sk, sc, sr, ai, ap, ak, ac, ar, grav_g, grav_eps, imp_i,
                          imp_f, imp_on, imp_off, pn, pmu)
            nfev += 1
            for p in range(n):
                for c in range(3):
                    vn = v[p, c] + h * a[p, c]
                    if kind == SYMPLECTIC_EULER:
                        x[p, c] = x[p, c] + h * vn
                    else:
                        x[p, c] = x[p, c] + 0.5 * h * (v[p, c] + vn)
                    v[p, c] = vn
        t = t + h
        if n_planes > 0:
            if kind == VERLET:
                x_new[:] = x
                v_new[:] = v
            any_contact = _collide(x, v, t, h, contact, f, radius, movable, inv_mass, mass,
                                   gravity, drag, si, sj, sk, sc, sr, ai, ap, ak, ac, ar, grav_g,
                                   grav_eps, imp_i, imp_f, imp_on, imp_off, pp, pn, pe, pmu, pth)
            if kind == VERLET and not (_same_bits(x, x_new) and _same_bits(v, v_new)):
                have_last = False  # the pass moved or stopped a particle: evaluate afresh
        steps = i
        if record[i]:
            xs[kept] = x
            vs[kept] = v
            ts[kept] = t
            kept += 1
        if i % check_every == 0 or i == n_steps:
            if _finite(x, v):
                checked = kept
                continue
            bad = -1
            for r in range(checked, kept):
                if not _finite(xs[r], vs[r]):
                    bad = r
                    break
            if bad < 0:
                if not record[i]:
                    xs[kept] = x
                    vs[kept] = v
                    ts[kept] = t
                    kept += 1
            else:
                kept = bad + 1
            unstable = True
            break
    return kept, steps, nfev, unstable


@njit(cache=True, error_model="numpy")
def _collide_p(p, X, V, t, dt, contact, radius, movable, inv_mass, mass, gravity, drag, imp_ptr,
               imp_f, imp_on, imp_off, pp, pn, pe, pmu, pth):
    """The collision and contact pass for particle ``p`` alone (its force depends on no
    other particle): :func:`_collide` restricted to one particle, on the state held by
    component (``X``, ``V`` of shape (3, n)). Returns whether it is in contact now."""
    any_on = False
    have_force = False
    f0 = f1 = f2 = 0.0
    for k in range(pp.shape[0]):
        contact[k, p] = False
    if not movable[p]:
        return False
    for k in range(pp.shape[0]):
        n0, n1, n2 = pn[k, 0], pn[k, 1], pn[k, 2]
        d = ((X[0, p] - pp[k, 0]) * n0 + (X[1, p] - pp[k, 1]) * n1
             + (X[2, p] - pp[k, 2]) * n2) - radius[p]
        if not d < EPS_DISTANCE:
            continue
        if pth[k] > 0.0 and not d > -(pth[k] + 2.0 * radius[p]):
            continue
        if not have_force:  # the applied force at the end of the step, once per pass
            f0 = mass[p] * gravity[0] - drag * V[0, p]
            f1 = mass[p] * gravity[1] - drag * V[1, p]
            f2 = mass[p] * gravity[2] - drag * V[2, p]
            if imp_ptr[p + 1] > imp_ptr[p]:
                f0, f1, f2 = _impulses_p(p, t, f0, f1, f2, imp_ptr, imp_f, imp_on, imp_off)
            have_force = True
        fn = f0 * n0 + f1 * n1 + f2 * n2
        vn = V[0, p] * n0 + V[1, p] * n1 + V[2, p] * n2
        an = fn * inv_mass[p]
        vn_new = vn
        if d < 0.0:
            sgn = 1.0 if vn > 0.0 else (-1.0 if vn < 0.0 else 0.0)
            vn_new = sgn * math.sqrt(max(vn * vn - 2.0 * an * d, 0.0))
            X[0, p] -= d * n0
            X[1, p] -= d * n1
            X[2, p] -= d * n2
            d = 0.0
        if vn_new < 0.0:
            vn_new = -pe[k] * vn_new
        on = abs(d) < EPS_DISTANCE and an < 0.0 and abs(vn_new) <= EPS_SPEED - an * dt
        if on:
            vn_new = 0.0
            X[0, p] -= d * n0
            X[1, p] -= d * n1
            X[2, p] -= d * n2
            any_on = True
        w0 = V[0, p] + (vn_new - vn) * n0
        w1 = V[1, p] + (vn_new - vn) * n1
        w2 = V[2, p] + (vn_new - vn) * n2
        if pmu[k] > 0.0 and on:
            mu = pmu[k]
            un = w0 * n0 + w1 * n1 + w2 * n2
            t0, t1, t2 = w0 - un * n0, w1 - un * n1, w2 - un * n2
            speed = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
            s0, s1, s2 = f0 - fn * n0, f1 - fn * n1, f2 - fn * n2
            ft = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
            if speed <= EPS_SPEED - mu * an * dt and ft <= -mu * fn:
                w0 -= w0 - vn_new * n0
                w1 -= w1 - vn_new * n1
                w2 -= w2 - vn_new * n2
        V[0, p] = w0
        V[1, p] = w1
        V[2, p] = w2
        contact[k, p] = on
    return any_on


@njit(cache=True, error_model="numpy")
def _impulses_p(p, t, f0, f1, f2, imp_ptr, imp_f, imp_on, imp_off):
    """Add the impulses on particle ``p`` active at ``t`` (its entries ``imp_ptr[p]`` to
    ``imp_ptr[p + 1]`` of the impulses sorted by particle, in their order in the case)."""
    eps = TIME_ROUNDOFF * max(1.0, abs(t))
    for k in range(imp_ptr[p], imp_ptr[p + 1]):
        if imp_on[k] - eps <= t < imp_off[k] - eps:
            f0 += imp_f[k, 0]
            f1 += imp_f[k, 1]
            f2 += imp_f[k, 2]
    return f0, f1, f2


@njit(cache=True, error_model="numpy")
def _contact_p(p, f0, f1, f2, v0, v1, v2, contact, pn, pmu):
    """The contact force of every plane particle ``p`` rests on, added to its applied
    force ``f`` (:func:`_add_contact_forces` for one particle)."""
    for k in range(pn.shape[0]):
        if contact[k, p]:
            f0, f1, f2 = _plane_contact(f0, f1, f2, v0, v1, v2, pn[k, 0], pn[k, 1], pn[k, 2],
                                        pmu[k])
    return f0, f1, f2


BLOCK = 256
"""Particles stepped together: a block's scratch arrays stay in the L1 cache, so a step
reads and writes each particle's state once however many stages it has."""


@njit(cache=True, error_model="numpy", inline="always")
def _accel_block(A, a0, U, u0, m, lo, t, special, q_lo, q_hi, mass, inv_mass, heavy, gravity,
                 drag, kicked, resting, imp_ptr, imp_f, imp_on, imp_off, contact, pn, pmu):
    """Accelerations (m/s^2) of the ``m`` particles ``lo`` to ``lo + m`` into columns
    ``a0 ...`` of ``A`` (3, .), at the velocities in columns ``u0 ...`` of ``U`` (3, .), at
    time ``t``: the lecture's derivative for independent particles. Gravity and drag for
    every particle in loops the compiler vectorises (rows of C arrays); then, for the
    block's ``special`` particles only (``special[q_lo:q_hi]``, global numbers: an impulse
    on them, or resting on a plane), the whole force again with those parts added."""
    mb = mass[lo:lo + m]
    wb = inv_mass[lo:lo + m]
    for c in range(3):
        g = gravity[c]
        Ac = A[c, a0:a0 + m]
        Uc = U[c, u0:u0 + m]
        if heavy and drag != 0.0:
            for j in range(m):
                Ac[j] = (mb[j] * g - drag * Uc[j]) * wb[j]
        elif heavy:
            for j in range(m):
                Ac[j] = (mb[j] * g) * wb[j]
        elif drag != 0.0:
            for j in range(m):
                Ac[j] = (0.0 - drag * Uc[j]) * wb[j]
        else:
            for j in range(m):
                Ac[j] = 0.0 * wb[j]
    for q in range(q_lo, q_hi):
        p = special[q]
        j = p - lo
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        if heavy:
            f0 += mass[p] * gravity[0]
            f1 += mass[p] * gravity[1]
            f2 += mass[p] * gravity[2]
        if drag != 0.0:
            f0 -= drag * U[0, u0 + j]
            f1 -= drag * U[1, u0 + j]
            f2 -= drag * U[2, u0 + j]
        if kicked[p]:
            f0, f1, f2 = _impulses_p(p, t, f0, f1, f2, imp_ptr, imp_f, imp_on, imp_off)
        if resting[p]:
            f0, f1, f2 = _contact_p(p, f0, f1, f2, U[0, u0 + j], U[1, u0 + j], U[2, u0 + j],
                                    contact, pn, pmu)
        A[0, a0 + j] = f0 * inv_mass[p]
        A[1, a0 + j] = f1 * inv_mass[p]
        A[2, a0 + j] = f2 * inv_mass[p]


@njit(cache=True, error_model="numpy")
def _run_independent(kind, rk_a, rk_b, rk_c, x, v, t0, h, n_steps, record, check_every, xs,
                      vs, ts, mass, inv_mass, radius, movable, gravity, drag, imp_ptr, imp_f,
                      imp_on, imp_off, pp, pn, pe, pmu, pth):
    """:func:`_run` for a scene whose particles do not act on one another (no springs,
    anchors or gravitation). The state is held by component (``X``, ``V`` of shape
    (3, n)); each step goes through the particles a :data:`BLOCK` at a time, and a block
    takes the whole step, every stage and the collision pass, in loops the compiler
    vectorises, its scratch in the cache: the state is read and written once a step.
    The forces of independent particles do not read positions, so a stage needs only
    its velocities. The rare parts (impulses, contact forces, the collision response) run
    for the particles they concern only."""
    n = x.shape[0]
    n_planes = pp.shape[0]
    X = np.ascontiguousarray(x.T)
    V = np.ascontiguousarray(v.T)
    contact = np.zeros((n_planes, n), dtype=np.bool_)
    resting = np.zeros(n, dtype=np.bool_)
    kicked = np.zeros(n, dtype=np.bool_)
    for p in range(n):
        kicked[p] = imp_ptr[p + 1] > imp_ptr[p]
    special = np.zeros(n, dtype=np.int64)  # kicked or resting particles, in order
    special_next = np.zeros(n, dtype=np.int64)
    stages = rk_b.shape[0]
    KX = np.zeros((max(stages, 1), 3, BLOCK))
    KV = np.zeros((max(stages, 1), 3, BLOCK))
    A = np.zeros((3, BLOCK))
    U = np.zeros((3, BLOCK))
    DX = np.zeros((3, BLOCK))
    DV = np.zeros((3, BLOCK))
    D = np.zeros((max(n_planes, 1), BLOCK))
    a_last = np.zeros((3, n)) if kind == VERLET else np.zeros((3, 1))
    have_last = False
    heavy = gravity[0] != 0.0 or gravity[1] != 0.0 or gravity[2] != 0.0
    t = t0
    for p in range(n):
        resting[p] = _collide_p(p, X, V, t, 0.0, contact, radius, movable, inv_mass, mass,
                                gravity, drag, imp_ptr, imp_f, imp_on, imp_off, pp, pn, pe, pmu,
                                pth)
    n_special = 0
    for p in range(n):
        if kicked[p] or resting[p]:
            special[n_special] = p
            n_special += 1
    xs[0] = x
    vs[0] = v
    ts[0] = t
    kept = 1
    checked = 1
    nfev = 0
    steps = 0
    unstable = False
    for i in range(1, n_steps + 1):
        fresh = kind == VERLET and not have_last
        changed = False
        q_lo = 0
        n_next = 0  # the special list of the next step, built as the pass goes
        for lo in range(0, n, BLOCK):
            hi = min(lo + BLOCK, n)
            m = hi - lo
            q_hi = q_lo
            while q_hi < n_special and special[q_hi] < hi:
                q_hi += 1
            if kind == RK:
                for s in range(stages):
                    Ks = KX[s]
                    first = s  # the first stage this one adds, copied in with the state
                    for r in range(s):
                        if rk_a[s, r] != 0.0:
                            first = r
                            break
                    for c in range(3):
                        Kc, Vc = Ks[c, :m], V[c, lo:hi]
                        if first < s:
                            w = h * rk_a[s, first]
                            Lc = KV[first, c, :m]
                            for j in range(m):
                                Kc[j] = Vc[j] + w * Lc[j]
                        else:
                            for j in range(m):
                                Kc[j] = Vc[j]
                    for r in range(first + 1, s):
                        if rk_a[s, r] != 0.0:
                            w = h * rk_a[s, r]
                            Lr = KV[r]
                            for c in range(3):
                                Kc, Lc = Ks[c, :m], Lr[c, :m]
                                for j in range(m):
                                    Kc[j] = Kc[j] + w * Lc[j]
                    _accel_block(KV[s], 0, Ks, 0, m, lo, t + rk_c[s] * h, special, q_lo, q_hi,
                                 mass, inv_mass, heavy, gravity, drag, kicked, resting, imp_ptr,
                                 imp_f, imp_on, imp_off, contact, pn, pmu)
                for c in range(3):
                    Dx, Dv = DX[c, :m], DV[c, :m]
                    for j in range(m):
                        Dx[j] = 0.0
                        Dv[j] = 0.0
                    for s in range(stages):
                        b = rk_b[s]
                        Kc, Lc = KX[s, c, :m], KV[s, c, :m]
                        for j in range(m):
                            Dx[j] += b * Kc[j]
                            Dv[j] += b * Lc[j]
                    Xc, Vc = X[c, lo:hi], V[c, lo:hi]
                    for j in range(m):
                        Xc[j] = Xc[j] + h * Dx[j]
                        Vc[j] = Vc[j] + h * Dv[j]
            elif kind == VERLET:
                if fresh:
                    _accel_block(a_last, lo, V, lo, m, lo, t, special, q_lo, q_hi, mass,
                                 inv_mass, heavy, gravity, drag, kicked, resting, imp_ptr, imp_f,
                                 imp_on, imp_off, contact, pn, pmu)
                for c in range(3):
                    Uc, Vc, Xc, Lc = U[c, :m], V[c, lo:hi], X[c, lo:hi], a_last[c, lo:hi]
                    for j in range(m):
                        Uc[j] = Vc[j] + 0.5 * h * Lc[j]
                        Xc[j] = Xc[j] + h * Uc[j]
                _accel_block(a_last, lo, U, 0, m, lo, t + h, special, q_lo, q_hi, mass,
                             inv_mass, heavy, gravity, drag, kicked, resting, imp_ptr, imp_f,
                             imp_on, imp_off, contact, pn, pmu)
                for c in range(3):
                    Uc, Vc, Lc = U[c, :m], V[c, lo:hi], a_last[c, lo:hi]
                    for j in range(m):
                        Vc[j] = Uc[j] + 0.5 * h * Lc[j]
            else:
                _accel_block(A, 0, V, lo, m, lo, t, special, q_lo, q_hi, mass, inv_mass, heavy,
                             gravity, drag, kicked, resting, imp_ptr, imp_f, imp_on, imp_off,
                             contact, pn, pmu)
                for c in range(3):
                    Ac, Vc, Xc = A[c, :m], V[c, lo:hi], X[c, lo:hi]
                    if kind == SYMPLECTIC_EULER:
                        for j in range(m):
                            q = Vc[j] + h * Ac[j]
                            Xc[j] = Xc[j] + h * q
                            Vc[j] = q
                    else:
                        for j in range(m):
                            q = Vc[j] + h * Ac[j]
                            Xc[j] = Xc[j] + 0.5 * h * (Vc[j] + q)
                            Vc[j] = q
            block_special = q_hi > q_lo
            q_lo = q_hi
            if n_planes > 0:  # the collision pass for the block, at the end of the step
                rb, X0, X1, X2 = radius[lo:hi], X[0, lo:hi], X[1, lo:hi], X[2, lo:hi]
                near_any = 0  # how many particle-planes of the block are within eps
                for k in range(n_planes):
                    c0, c1, c2 = pp[k, 0], pp[k, 1], pp[k, 2]
                    n0, n1, n2 = pn[k, 0], pn[k, 1], pn[k, 2]
                    Dk = D[k, :m]
                    for j in range(m):
                        d = ((X0[j] - c0) * n0 + (X1[j] - c1) * n1 + (X2[j] - c2) * n2) - rb[j]
                        Dk[j] = d
                        near_any += not d >= EPS_DISTANCE  # NaN counts as near, as before
                if not block_special and near_any == 0:
                    continue  # nothing in this block touches a plane, rests or is kicked
                for j in range(m):
                    p = lo + j
                    near = resting[p]
                    if movable[p] and not near:
                        for k in range(n_planes):
                            if D[k, j] < EPS_DISTANCE:
                                near = True
                                break
                    if near:
                        y0, y1, y2 = X[0, p], X[1, p], X[2, p]
                        u0, u1, u2 = V[0, p], V[1, p], V[2, p]
                        resting[p] = _collide_p(p, X, V, t + h, h, contact, radius, movable,
                                                inv_mass, mass, gravity, drag, imp_ptr, imp_f,
                                                imp_on, imp_off, pp, pn, pe, pmu, pth)
                        if kind == VERLET and not changed:
                            changed = not (_same_bit(X[0, p], y0) and _same_bit(X[1, p], y1)
                                           and _same_bit(X[2, p], y2) and _same_bit(V[0, p], u0)
                                           and _same_bit(V[1, p], u1) and _same_bit(V[2, p], u2))
                    if kicked[p] or resting[p]:
                        special_next[n_next] = p
                        n_next += 1
        if n_planes > 0:
            special, special_next = special_next, special
            n_special = n_next
        if kind == RK:
            nfev += stages
        elif kind == VERLET:
            nfev += 2 if fresh else 1
            have_last = not changed
        else:
            nfev += 1
        t = t + h
        steps = i
        if record[i]:
            for p in range(n):
                for c in range(3):
                    xs[kept, p, c] = X[c, p]
                    vs[kept, p, c] = V[c, p]
            ts[kept] = t
            kept += 1
        if i % check_every == 0 or i == n_steps:
            if _finite_soa(X, V):
                checked = kept
                continue
            bad = -1
            for r in range(checked, kept):
                if not _finite(xs[r], vs[r]):
                    bad = r
                    break
            if bad < 0:
                if not record[i]:
                    for p in range(n):
                        for c in range(3):
                            xs[kept, p, c] = X[c, p]
                            vs[kept, p, c] = V[c, p]
                    ts[kept] = t
                    kept += 1
            else:
                kept = bad + 1
            unstable = True
            break
    return kept, steps, nfev, unstable


@njit(cache=True, error_model="numpy")
def _finite_soa(X, V):
    """:func:`_finite` on states held by component (3, n)."""
    for c in range(3):
        for p in range(X.shape[1]):
            if not (-BLOWUP < X[c, p] < BLOWUP and -BLOWUP < V[c, p] < BLOWUP):
                return False
    return True


@njit(cache=True, error_model="numpy")
def _same_bit(a, b):
    """Whether two floats have the same bits (``-0.0`` and ``0.0`` differ, as bytes do)."""
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


@dataclass
class CompiledRun:
    """What :func:`run_compiled` returns: the records and the counts of
    :class:`~truestep.reference_impl.integrate.Run` (t (T,) s; x, v (T, n, 3))."""

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    nfev: int
    steps: int
    status: str
    t_fail: float | None


def run_compiled(model: ParticleModel, method: str, duration: float, h: float, *,
                 max_records: int = 2000) -> tuple[CompiledRun, float]:
    """Run ``method`` on ``model`` for ``round(duration / h)`` steps of ``h`` s; return the
    run and the wall time of the stepping (s, the compiled loop only: packing the scene,
    allocating the records and compiling happen before it)."""
    import time

    from truestep.reference_impl.solvers import METHODS

    reason = compiled_reason(model, method)
    if reason is not None:
        raise ValueError(f"the compiled path cannot run {method} here: {reason}")
    cls = METHODS[method]
    if method in SPLITTING:
        kind = SPLITTING[method]
        rk_a, rk_b, rk_c = np.zeros((0, 0)), np.zeros(0), np.zeros(0)
    else:
        kind = RK
        rk_a = np.ascontiguousarray(cls.A, dtype=np.float64)
        rk_b = np.ascontiguousarray(cls.B, dtype=np.float64)
        rk_c = np.ascontiguousarray(cls.A.sum(axis=1), dtype=np.float64)
    n_steps = round(duration / h)
    marks = record_indices(n_steps, max_records)
    record = np.zeros(n_steps + 1, dtype=np.bool_)
    record[marks] = True
    slots = len(marks) + 1  # the state a failed check finds between records
    n = model.n
    xs, vs, ts = np.empty((slots, n, 3)), np.empty((slots, n, 3)), np.empty(slots)
    x, v = np.array(model.x0, dtype=np.float64), np.array(model.v0, dtype=np.float64)
    packed = PackedScene.of(model)
    common = (rk_a, rk_b, rk_c, x, v, 0.0, h, n_steps, record, CHECK_EVERY, xs, vs, ts)
    if independent(model):
        loop = _run_independent
        args = (kind, *common, packed.mass, packed.inv_mass, packed.radius, packed.movable,
                packed.gravity, packed.drag, *packed.impulses_by_particle(), *packed.planes)
    else:
        loop, args = _run, (kind, *common, *packed.args())
    start = time.perf_counter()
    kept, steps, nfev, unstable = loop(*args)
    wall = time.perf_counter() - start
    run = CompiledRun(ts[:kept].copy(), xs[:kept].copy(), vs[:kept].copy(), int(nfev), int(steps),
                      "unstable" if unstable else "ok", float(ts[kept - 1]) if unstable else None)
    return run, wall


def compile_all() -> None:
    """Compile (or load from numba's cache) the loop for every kind of step, on a tiny
    scene with every force, so forked runs find it ready."""
    from truestep.reference_impl.model import Anchors, Gravitation, Plane, Springs

    one = np.ones(2)
    model = ParticleModel(
        mass=one, x0=np.array([[0.0, 1.0, 0.0], [1.0, 1.0, 0.0]]), v0=np.zeros((2, 3)),
        radius=np.zeros(2), fixed=np.zeros(2, bool), gravity=np.array([0.0, -1.0, 0.0]),
        drag=0.1, springs=Springs(np.array([0]), np.array([1]), one[:1], one[:1], one[:1]),
        anchors=Anchors(np.array([0]), np.zeros((1, 3)), one[:1], one[:1], one[:1]),
        gravitation=Gravitation(G=1.0, softening=0.1),
        planes=[Plane(np.zeros(3), np.array([0.0, 1.0, 0.0]), 0.5, 0.1, 0.0)],
        impulses=[(0, np.array([1.0, 0.0, 0.0]), 0.0, 0.01)])
    loose = ParticleModel(mass=one, x0=model.x0, v0=model.v0, radius=model.radius,
                          fixed=model.fixed, gravity=model.gravity, drag=0.1, planes=model.planes,
                          impulses=model.impulses)
    for scene in (model, loose):
        for method in ("rk4", "verlet", "symplectic-euler"):
            run_compiled(scene, method, 0.02, 0.01)
