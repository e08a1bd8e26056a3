"""The Warp kernel of :mod:`~truestep.reference_impl.warp_particles`, in Warp's kernel language.

Each function is the compiled path's of the same name (:mod:`~truestep.reference_impl.collisions_kernels`,
:mod:`~truestep.reference_impl.tiles`, :mod:`~truestep.reference_impl.solvers.splitting_kernels`), term for
term and in its order, on float64 scalars (a particle's state is six of them, in registers).
Importing it imports Warp (configured by :func:`truestep.numerics.configure_warp`) and
starts nothing. The module is compiled without floating-point contraction (Warp's
``fuse_fp`` off: no ``a * b + c`` fused into one rounding, on a GPU as on the CPU, whose
generic target has no FMA) and without adjoints (nothing here is differentiated), so
that a GPU can give the compiled path's bits too: IEEE double division and square root
round correctly on both. mypy does not check this module (``pyproject.toml``): Warp's stubs type its
arrays as read-only and its integer types apart from Python's.
"""

import warp as wp

from truestep.numerics import configure_warp
from truestep.reference_impl.collisions import EPS_DISTANCE, EPS_SPEED
from truestep.reference_impl.integrate import BLOWUP, CHECK_EVERY

configure_warp(wp)
wp.set_module_options({"fuse_fp": False, "enable_backward": False})
f64 = wp.float64
F64 = wp.array[wp.float64]
eps_d = wp.constant(f64(EPS_DISTANCE))
eps_v = wp.constant(f64(EPS_SPEED))
blowup = wp.constant(f64(BLOWUP))
every = wp.constant(CHECK_EVERY)


@wp.func
def force(m: f64, g: wp.vec3d, k: f64, has_g: int, has_drag: int, v0: f64, v1: f64, v2: f64):
    """The applied force (N) of one particle, each kind from zero, gravity then drag
    (:func:`~truestep.reference_impl.compiled.forces_of`, ``point_force``)."""
    f0, f1, f2 = f64(0.0), f64(0.0), f64(0.0)
    if has_g != 0:
        f0, f1, f2 = f0 + m * g[0], f1 + m * g[1], f2 + m * g[2]
    if has_drag != 0:
        f0, f1, f2 = f0 - k * v0, f1 - k * v1, f2 - k * v2
    return f0, f1, f2


@wp.func
def contact_force(f0: f64, f1: f64, f2: f64, v0: f64, v1: f64, v2: f64, n: wp.vec3d, mu: f64):
    """The force with one plane's contact force added: ``collisions_kernels.contact_force``."""
    n0, n1, n2 = n[0], n[1], n[2]
    press = wp.min(f0 * n0 + f1 * n1 + f2 * n2, f64(0.0))
    f0 = f0 - press * n0
    f1 = f1 - press * n1
    f2 = f2 - press * n2
    r0, r1, r2 = f0, f1, f2
    if mu > f64(0.0):
        limit = -mu * press
        vn = v0 * n0 + v1 * n1 + v2 * n2
        t0, t1, t2 = v0 - vn * n0, v1 - vn * n1, v2 - vn * n2
        speed = wp.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        ffn = f0 * n0 + f1 * n1 + f2 * n2
        s0, s1, s2 = f0 - ffn * n0, f1 - ffn * n1, f2 - ffn * n2
        ft = wp.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        if speed > f64(0.0):
            kinetic = limit / speed
            r0, r1, r2 = f0 - kinetic * t0, f1 - kinetic * t1, f2 - kinetic * t2
        elif ft <= limit:
            r0, r1, r2 = f0 - s0, f1 - s1, f2 - s2
        else:
            static = limit / ft
            r0, r1, r2 = f0 - static * s0, f1 - static * s1, f2 - static * s2
    return r0, r1, r2


@wp.func
def distance(x0: f64, x1: f64, x2: f64, radius: f64, p: wp.vec3d, n: wp.vec3d):
    """``collisions_kernels.signed_distance``, m."""
    return ((x0 - p[0]) * n[0] + (x1 - p[1]) * n[1] + (x2 - p[2]) * n[2]) - radius


@wp.func
def within(d: f64, radius: f64, thickness: f64):
    """``collisions_kernels.within``."""
    inside = d < eps_d
    if inside and thickness > f64(0.0):
        inside = d > -(thickness + f64(2.0) * radius)
    return inside


@wp.func
def sticks(
    w0: f64, w1: f64, w2: f64, c0: f64, c1: f64, c2: f64, fn: f64, an: f64, n: wp.vec3d, mu: f64, dt: f64
):
    """``collisions_kernels.sticking``."""
    n0, n1, n2 = n[0], n[1], n[2]
    un = w0 * n0 + w1 * n1 + w2 * n2
    t0, t1, t2 = w0 - un * n0, w1 - un * n1, w2 - un * n2
    speed = wp.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    s0, s1, s2 = c0 - fn * n0, c1 - fn * n1, c2 - fn * n2
    ft = wp.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    return speed <= eps_v - mu * an * dt and ft <= -mu * fn


@wp.func
def collide(
    x0: f64,
    x1: f64,
    x2: f64,
    v0: f64,
    v1: f64,
    v2: f64,
    c0: f64,
    c1: f64,
    c2: f64,
    w: f64,
    d: f64,
    n: wp.vec3d,
    e: f64,
    mu: f64,
    dt: f64,
):
    """One particle against one plane it is within eps of: ``collisions_kernels.collide``
    (``c`` the applied force, N; ``w`` the inverse mass; ``e`` and ``mu`` the plane's
    restitution and friction). Returns the new state and whether it is in contact."""
    n0, n1, n2 = n[0], n[1], n[2]
    fn = c0 * n0 + c1 * n1 + c2 * n2
    vn = v0 * n0 + v1 * n1 + v2 * n2
    an = fn * w
    vn_new = vn
    if d < f64(0.0):  # lifted onto the plane, paying the work of its normal force
        sign = f64(0.0)
        if vn > f64(0.0):
            sign = f64(1.0)
        elif vn < f64(0.0):
            sign = f64(-1.0)
        vn_new = sign * wp.sqrt(wp.max(vn * vn - f64(2.0) * an * d, f64(0.0)))
        x0, x1, x2 = x0 - d * n0, x1 - d * n1, x2 - d * n2
        d = f64(0.0)
    if vn_new < f64(0.0):
        vn_new = -e * vn_new
    on = wp.abs(d) < eps_d and an < f64(0.0) and wp.abs(vn_new) <= eps_v - an * dt
    if on:
        vn_new = f64(0.0)
        x0, x1, x2 = x0 - d * n0, x1 - d * n1, x2 - d * n2
    w0 = v0 + (vn_new - vn) * n0
    w1 = v1 + (vn_new - vn) * n1
    w2 = v2 + (vn_new - vn) * n2
    if mu > f64(0.0) and on:
        if sticks(w0, w1, w2, c0, c1, c2, fn, an, n, mu, dt):
            w0 = w0 - (w0 - vn_new * n0)
            w1 = w1 - (w1 - vn_new * n1)
            w2 = w2 - (w2 - vn_new * n2)
    return x0, x1, x2, w0, w1, w2, on


@wp.func
def finite(x0: f64, x1: f64, x2: f64, v0: f64, v1: f64, v2: f64):
    """Every component finite and within ``BLOWUP`` (``integrate_kernels.finite``)."""
    fine = (-blowup < x0 and x0 < blowup) and (-blowup < x1 and x1 < blowup)
    fine = fine and (-blowup < x2 and x2 < blowup) and (-blowup < v0 and v0 < blowup)
    return fine and (-blowup < v1 and v1 < blowup) and (-blowup < v2 and v2 < blowup)


@wp.kernel
def steps(
    x_start: wp.array2d[wp.float64],
    v_start: wp.array2d[wp.float64],
    mass: F64,
    inv_mass: F64,
    radius: F64,
    g: wp.vec3d,
    k: f64,
    has_g: int,
    has_drag: int,
    weight_old: f64,
    weight_new: f64,
    point: wp.array[wp.vec3d],
    normal: wp.array[wp.vec3d],
    restitution: F64,
    friction: F64,
    thickness: F64,
    h: f64,
    n_steps: int,
    record: wp.array[wp.int32],
    xs: wp.array3d[wp.float64],
    vs: wp.array3d[wp.float64],
    bad: wp.array[wp.int32],
):
    """Particle ``tid`` through ``n_steps`` steps: the collision pass on the first state,
    then each step's kick and drift (a resting particle's with its contact force) and the
    collision pass where the particle is near a plane or rests on one; records where
    ``record`` says; the check every ``CHECK_EVERY`` steps (a failed one ends the thread,
    its step in ``bad``)."""
    p = wp.tid()
    m, w, r = f64(mass[p]), f64(inv_mass[p]), f64(radius[p])
    x0, x1, x2 = f64(x_start[p, 0]), f64(x_start[p, 1]), f64(x_start[p, 2])
    v0, v1, v2 = f64(v_start[p, 0]), f64(v_start[p, 1]), f64(v_start[p, 2])
    planes = point.shape[0]
    dt = f64(0.0)
    contact = wp.int32(0)
    visit = wp.int32(1)  # the pass on the first state visits every particle (fused_start)
    kept = wp.int32(0)
    for i in range(n_steps + 1):
        if i > 0:  # the step (KickDrift), a resting particle's with its contact force
            f0, f1, f2 = force(m, g, k, has_g, has_drag, v0, v1, v2)
            for q in range(planes):
                if (contact >> q) & 1 != 0:
                    f0, f1, f2 = contact_force(f0, f1, f2, v0, v1, v2, normal[q], friction[q])
            u0, u1, u2 = v0 + h * (f0 * w), v1 + h * (f1 * w), v2 + h * (f2 * w)
            x0 = x0 + h * (weight_old * v0 + weight_new * u0)
            x1 = x1 + h * (weight_old * v1 + weight_new * u1)
            x2 = x2 + h * (weight_old * v2 + weight_new * u2)
            v0, v1, v2 = u0, u1, u2
            dt = h
            visit = contact  # fused_particles' mark: resting (special), or near a plane (NaN is)
            for q in range(planes):
                if not (distance(x0, x1, x2, r, point[q], normal[q]) >= eps_d):
                    visit = 1
        if visit != 0:  # collide_particle: the planes in order, the applied force once
            contact = wp.int32(0)
            have_force = wp.int32(0)
            c0, c1, c2 = f64(0.0), f64(0.0), f64(0.0)
            for q in range(planes):
                d = distance(x0, x1, x2, r, point[q], normal[q])
                if within(d, r, thickness[q]):
                    if have_force == 0:
                        c0, c1, c2 = force(m, g, k, has_g, has_drag, v0, v1, v2)
                        have_force = 1
                    x0, x1, x2, v0, v1, v2, on = collide(
                        x0, x1, x2, v0, v1, v2, c0, c1, c2, w, d, normal[q], restitution[q], friction[q], dt
                    )
                    if on:
                        contact = contact | (1 << q)
        if record[i] != 0:
            xs[kept, p, 0] = x0
            xs[kept, p, 1] = x1
            xs[kept, p, 2] = x2
            vs[kept, p, 0] = v0
            vs[kept, p, 1] = v1
            vs[kept, p, 2] = v2
            kept += 1
        if i > 0 and (i % every == 0 or i == n_steps) and not finite(x0, x1, x2, v0, v1, v2):
            bad[p] = i
            return
