"""Exact solutions of the particle cases: free flight, drag, two bodies, springs, bounces.

Each is registered in :data:`truestep.cases.exact_registry.EXACT` and returns positions and velocities
``(T, n, 3)`` and the total energy ``(T,)`` (same formula as
:func:`truestep.reference_impl.particles.total_energy`) at the requested times. Each checks that
the scene is one it solves and raises ``ValueError`` naming what does not fit.
"""

from __future__ import annotations

import numpy as np

from truestep.cases.case import Case
from truestep.cases.closed_forms import kepler_state, oscillator
from truestep.cases.exact_registry import Exact, exact_solution
from truestep.reference_impl.model import ParticleModel


def _energy(m: ParticleModel, x: np.ndarray, v: np.ndarray, extra: np.ndarray | float = 0.0):
    """Kinetic plus uniform-gravity energy of trajectories (T, n, 3), plus ``extra``, J."""
    mass = np.where(m.fixed, 0.0, m.mass)
    kinetic = 0.5 * np.einsum("n,tni,tni->t", mass, v, v)
    return kinetic - np.einsum("n,tni,i->t", mass, x, m.gravity) + extra


def _require(ok: bool, case: Case, what: str) -> None:
    if not ok:
        raise ValueError(f"{case.name}: exact solution {case.exact!r} needs {what}")


def _free_forces(case: Case, *, drag: bool) -> ParticleModel:
    m = case.particles
    _require(
        not len(m.springs)
        and not len(m.anchors)
        and m.gravitation is None
        and not m.fields
        and not m.planes
        and not m.impulses
        and not m.emitters,
        case,
        "particles under gravity and drag only",
    )
    _require(drag or m.drag == 0, case, "no drag (drag = 0)")
    return m


@exact_solution("uniform-gravity", params={}, kind="particles")
def uniform_gravity(case: Case, t: np.ndarray) -> Exact:
    """Free flight ``x0 + v0 t + g t^2 / 2`` of every particle; energy conserved.

    The lecture's update ``p' = p + (v + v') dt / 2`` reproduces it exactly.
    """
    m = _free_forces(case, drag=False)
    tt = t[:, None, None]
    moving = ~m.fixed[None, :, None]
    x = m.x0 + moving * (m.v0 * tt + 0.5 * m.gravity * tt**2)
    v = moving * (m.v0 + m.gravity * tt) + 0 * tt
    return Exact(t, x, v, _energy(m, x, v))


@exact_solution("linear-drag", params={}, kind="particles")
def linear_drag(case: Case, t: np.ndarray) -> Exact:
    """Gravity and viscous drag ``m v' = m g - k v``: ``v = v_inf + (v0 - v_inf) e^(-t/tau)``.

    ``tau = m / k`` (s), terminal velocity ``v_inf = tau g``; positions
    ``x = x0 + v_inf t + (v0 - v_inf) tau (1 - e^(-t/tau))``. Energy (kinetic plus
    gravitational) of that state: drag dissipates it.
    """
    m = _free_forces(case, drag=True)
    _require(m.drag > 0 and not np.any(m.fixed), case, "drag > 0 and no pinned particles")
    tau = (m.mass / m.drag)[None, :, None]
    tt = t[:, None, None]
    v_inf = tau * m.gravity
    decay = np.exp(-tt / tau)
    v = v_inf + (m.v0 - v_inf) * decay
    x = m.x0 + v_inf * tt + (m.v0 - v_inf) * tau * (-np.expm1(-tt / tau))
    return Exact(t, x, v, _energy(m, x, v))


@exact_solution("two-body", params={}, kind="particles")
def two_body(case: Case, t: np.ndarray) -> Exact:
    """Two bodies under universal gravitation (no softening): a Kepler orbit and a drift.

    The centre of mass moves uniformly; the relative coordinate ``r = x_1 - x_0`` follows
    the Kepler orbit of ``mu = G (m_0 + m_1)`` from its initial state (any bound orbit,
    circular included), solved by :func:`truestep.cases.exact.kepler_state` in the orbit's own
    frame. Energy ``m_0 v_0^2 / 2 + m_1 v_1^2 / 2 - G m_0 m_1 / r`` is conserved.
    """
    m = case.particles
    g = m.gravitation
    _require(
        m.n == 2
        and g is not None
        and g.softening == 0
        and not np.any(m.gravity)
        and not len(m.springs)
        and not m.planes
        and m.drag == 0
        and not np.any(m.fixed),
        case,
        "exactly two free bodies under unsoftened gravitation alone",
    )
    assert g is not None  # _require said so
    m0, m1 = m.mass
    total = m0 + m1
    mu = g.G * total
    r0, w0 = m.x0[1] - m.x0[0], m.v0[1] - m.v0[0]
    h = np.cross(r0, w0)
    _require(float(np.linalg.norm(h)) > 0, case, "a relative velocity across the line of centres")
    dist, speed2 = float(np.linalg.norm(r0)), float(w0 @ w0)
    energy = 0.5 * speed2 - mu / dist
    _require(energy < 0, case, "a bound (elliptic) orbit")
    a = -mu / (2 * energy)
    e_vec = np.cross(w0, h) / mu - r0 / dist
    e = float(np.linalg.norm(e_vec))
    p_hat = e_vec / e if e > 1e-12 else r0 / dist
    q_hat = np.cross(h / np.linalg.norm(h), p_hat)
    nu0 = np.arctan2(r0 @ q_hat, r0 @ p_hat)
    ecc_anom = 2 * np.arctan2(np.sqrt(1 - e) * np.sin(nu0 / 2), np.sqrt(1 + e) * np.cos(nu0 / 2))
    t_peri = (ecc_anom - e * np.sin(ecc_anom)) / np.sqrt(mu / a**3)  # time since pericentre
    s = kepler_state(e, mu, a, t + t_peri)
    r = s[:, :1] * p_hat + s[:, 1:2] * q_hat
    w = s[:, 2:3] * p_hat + s[:, 3:4] * q_hat
    cm_x = (m0 * m.x0[0] + m1 * m.x0[1]) / total
    cm_v = (m0 * m.v0[0] + m1 * m.v0[1]) / total
    cm = cm_x + cm_v * t[:, None]
    x = np.stack([cm - (m1 / total) * r, cm + (m0 / total) * r], axis=1)
    v = np.stack([cm_v - (m1 / total) * w, cm_v + (m0 / total) * w], axis=1)
    pot = -g.G * m0 * m1 / np.linalg.norm(r, axis=1)
    return Exact(t, x, v, _energy(m, x, v, pot))


@exact_solution("spring-pair", params={}, kind="particles")
def spring_pair(case: Case, t: np.ndarray) -> Exact:
    """Two free masses on one damped spring, moving along the spring's line.

    The centre of mass moves uniformly (falling under gravity, if any); the extension
    ``u = |x_j - x_i| - r`` obeys ``mu u'' + k_d u' + k_s u = 0`` with the reduced mass
    ``mu = m_i m_j / (m_i + m_j)``: the anchored oscillator of the relative coordinate.
    Needs the relative velocity along the spring. Energy: kinetic plus gravity plus
    ``k_s u^2 / 2``.
    """
    m = case.particles
    s = m.springs
    _require(
        m.n == 2
        and len(s) == 1
        and not len(m.anchors)
        and m.drag == 0
        and not m.planes
        and m.gravitation is None
        and not m.fields
        and not m.impulses
        and not np.any(m.fixed),
        case,
        "two free masses joined by one spring",
    )
    i, j = int(s.i[0]), int(s.j[0])
    mi, mj = m.mass[i], m.mass[j]
    total, reduced = mi + mj, mi * mj / (mi + mj)
    sep = m.x0[j] - m.x0[i]
    axis = sep / np.linalg.norm(sep)
    rel_v = m.v0[j] - m.v0[i]
    across = rel_v - (rel_v @ axis) * axis
    _require(
        float(np.linalg.norm(across)) <= 1e-12 * max(1.0, float(np.linalg.norm(rel_v))),
        case,
        "the relative velocity along the spring",
    )
    u0 = float(np.linalg.norm(sep) - s.rest[0])
    u, du = oscillator(reduced, float(s.stiffness[0]), float(s.damping[0]), u0, float(rel_v @ axis), t)
    tt = t[:, None]
    cm = (mi * m.x0[i] + mj * m.x0[j]) / total + (mi * m.v0[i] + mj * m.v0[j]) / total * tt
    cm = cm + 0.5 * m.gravity * tt**2
    cm_v = (mi * m.v0[i] + mj * m.v0[j]) / total + m.gravity * tt
    length = (s.rest[0] + u)[:, None] * axis
    x, v = np.empty((len(t), 2, 3)), np.empty((len(t), 2, 3))
    x[:, i], x[:, j] = cm - (mj / total) * length, cm + (mi / total) * length
    v[:, i], v[:, j] = cm_v - (mj / total) * du[:, None] * axis, cm_v + (mi / total) * du[:, None] * axis
    return Exact(t, x, v, _energy(m, x, v, 0.5 * s.stiffness[0] * u**2))


def bounce_schedule(u0: float, w0: float, g: float, e: float, t_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Bounce times ``T_k`` (s) and launch speeds ``e^k V`` (m/s) up to ``t_max``, k = 1, 2, ...

    A point ``u0 >= 0`` above a plane, moving at ``w0`` along its normal, gravity ``g``
    (m/s^2) toward it, restitution ``e``: the first impact at ``T_1 = (w0 + V) / g`` with
    speed ``V = sqrt(w0^2 + 2 g u0)``, then flights of ``2 e^k V / g``. The apex after
    bounce k is ``(e^k V)^2 / (2 g) = e^(2k) h_0`` (``h_0 = V^2 / (2 g)``, the drop
    height when ``w0 = 0``). With ``e < 1`` the bounces end at ``T_1 + 2 e V / (g (1 - e))``.
    """
    speed = np.sqrt(w0**2 + 2 * g * u0)
    times, launches = [(w0 + speed) / g], [e * speed]
    while times[-1] <= t_max and launches[-1] > 1e-300 and len(times) < 100000:
        times.append(times[-1] + 2 * launches[-1] / g)
        launches.append(launches[-1] * e)
    return np.array(times), np.array(launches)


def _plane_motion(case: Case) -> tuple[ParticleModel, np.ndarray, float, float, float]:
    """Particle 0 above plane 0 with gravity along ``-N``: model, N, g, height, normal speed."""
    m = case.particles
    _require(
        m.n == 1
        and len(m.planes) == 1
        and m.drag == 0
        and not len(m.springs)
        and not len(m.anchors)
        and m.gravitation is None
        and not m.fields
        and not m.impulses,
        case,
        "one particle, one plane, gravity",
    )
    plane = m.planes[0]
    n = plane.normal
    g = float(-(m.gravity @ n))
    _require(
        g > 0 and np.allclose(m.gravity, -g * n, rtol=0, atol=1e-12 * g),
        case,
        "gravity along the plane's inward normal",
    )
    u0 = float((m.x0[0] - plane.point) @ n - m.radius[0])
    _require(u0 >= 0, case, "the particle to start on or above the plane")
    return m, n, g, u0, float(m.v0[0] @ n)


def bounce_path(
    x0: np.ndarray, v0: np.ndarray, radius: float, plane, g: float, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (T, 3) of one ball bouncing on a frictionless plane: the
    one-ball case of :func:`bounce_paths`."""
    x, v = bounce_paths(x0[None], v0[None], np.array([radius], float), plane, g, t)
    return x[:, 0], v[:, 0]


def bounce_paths(
    x0: np.ndarray, v0: np.ndarray, radius: np.ndarray, plane, g: float, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (T, N, 3) of N balls bouncing on one frictionless plane,
    each on its own: starts ``x0`` and ``v0`` (N, 3), radii (N,), at times ``t`` (T,).

    The height of a ball's contact point is a chain of parabolas between the bounce times
    of :func:`bounce_schedule`; after the last bounce (``e < 1``) the ball rests on the
    plane (its centre at height r). Tangential motion is uniform. ``g`` (m/s^2) is gravity
    along the plane's inward normal. Every ball's schedule is the recurrence of
    :func:`bounce_schedule`, run for all balls at once (bounce by bounce, each ball until
    its own stop or the last time read before it comes to rest, whichever is first:
    :func:`_last_time_in_flight`), so each number is the one that function gives; memory
    and work grow with T N and the bounces before the times read, not with a grid per ball.
    """
    n, e = plane.normal, plane.restitution
    t = np.asarray(t, float)
    u0 = (x0 - plane.point) @ n - radius
    w0 = v0 @ n
    speed = np.sqrt(w0**2 + 2 * g * u0)
    first = (w0 + speed) / g
    order = np.argsort(t, kind="stable")
    rest_at = first + 2 * e * speed / (g * (1 - e)) if e < 1 else None
    last = _last_time_in_flight(t[order], rest_at, len(u0))
    bounced = np.zeros((len(t), len(u0)), bool)  # a bounce at or before t[j]
    at = np.zeros((len(t), len(u0)))  # the time of the last such bounce (s)
    leave = np.zeros((len(t), len(u0)))  # and the normal speed it left with (m/s)
    alive, time, launch, count = np.arange(len(u0)), first, e * speed, 1
    while alive.size:
        go = (time <= last[alive]) & (launch > 1e-300) & (count < 100000)
        after = np.where(go, time + 2 * launch / g, np.inf)
        # the times from this bounce to the next: this bounce is the last before them
        lo, hi = np.searchsorted(t[order], time), np.searchsorted(t[order], after)
        rows, which = _ranges(lo, hi)
        cols = alive[which]
        bounced[order[rows], cols] = True
        at[order[rows], cols], leave[order[rows], cols] = time[which], launch[which]
        alive, time, launch = alive[go], after[go], launch[go] * e
        count += 1
    since = t[:, None] - np.where(bounced, at, 0.0)
    start_u = np.where(bounced, 0.0, u0)
    start_w = np.where(bounced, leave, w0)
    u = start_u + start_w * since - 0.5 * g * since**2
    w = start_w - g * since
    if rest_at is not None:
        rest = t[:, None] >= rest_at
        u, w = np.where(rest, 0.0, u), np.where(rest, 0.0, w)
    vt = v0 - w0[:, None] * n
    x = x0 + vt * t[:, None, None] + (u - u0)[..., None] * n
    return x, vt + w[..., None] * n


def _last_time_in_flight(t: np.ndarray, rest: np.ndarray | None, balls: int) -> np.ndarray:
    """Per ball (N,), the latest of the sorted times ``t`` (T,) s before it comes to rest
    at ``rest`` (N,) s, or ``-inf`` where every time is at or after it; with ``rest``
    ``None`` (e = 1, no rest) the latest time, at least 0, for every ball. A ball's
    bounces after that time change nothing read (a time at or after ``rest`` reads the
    ball at rest), so its schedule is followed no further: a ball that comes to rest inside
    the run bounces without end before it (about 1000 times, until its launch speed is
    under 1e-300), and the times read stop it after the few bounces before them."""
    if rest is None:
        return np.full(balls, float(np.max(t, initial=0.0)))
    k = np.searchsorted(t, rest, side="left")  # t[:k] < rest
    return np.where(k > 0, t[np.maximum(k - 1, 0)] if len(t) else -np.inf, -np.inf)


def _ranges(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The integers of every range ``[lo[i], hi[i])``, one after another, and the ``i`` of
    each."""
    counts = np.maximum(hi - lo, 0)
    which = np.repeat(np.arange(len(lo)), counts)
    starts = np.cumsum(counts) - counts
    return np.arange(int(counts.sum())) - np.repeat(starts - lo, counts), which


@exact_solution("bouncing-ball", params={}, kind="particles")
def bouncing_ball(case: Case, t: np.ndarray) -> Exact:
    """A ball of radius r bouncing on a frictionless plane with restitution ``e``
    (:func:`bounce_path`). No energy curve is given: it drops at every bounce, and a run
    that finds a bounce a step late would be charged the whole drop at that instant.
    """
    m, _, g, _, _ = _plane_motion(case)
    x, v = bounce_path(m.x0[0], m.v0[0], float(m.radius[0]), m.planes[0], g, t)
    return Exact(t, x[:, None, :], v[:, None, :], None)


@exact_solution("sliding-friction", params={}, kind="particles")
def sliding_friction(case: Case, t: np.ndarray) -> Exact:
    """A particle sliding on a plane with Coulomb friction ``mu`` after a push ``v0``.

    It stays on the plane (the contact force cancels gravity) and decelerates at
    ``mu g`` until it stops at ``t* = v0 / (mu g)``, after ``s* = v0^2 / (2 mu g)``;
    ``s(t) = v0 t - mu g t^2 / 2`` before. Without friction it slides on uniformly.
    """
    m, _, g, u0, w0 = _plane_motion(case)
    _require(u0 == 0 and w0 == 0, case, "the particle to start on the plane, moving along it")
    mu = m.planes[0].friction
    v0 = float(np.linalg.norm(m.v0[0]))
    along = m.v0[0] / v0 if v0 > 0 else np.zeros(3)
    if mu > 0:
        stop = v0 / (mu * g)
        tc = np.minimum(t, stop)
        s, speed = v0 * tc - 0.5 * mu * g * tc**2, v0 - mu * g * tc
    else:
        s, speed = v0 * t, np.full_like(t, v0)
    x = (m.x0[0] + s[:, None] * along)[:, None, :]
    v = (speed[:, None] * along)[:, None, :]
    return Exact(t, x, v, _energy(m, x, v))


@exact_solution("bouncing-rain", params={}, kind="particles")
def bouncing_rain(case: Case, t: np.ndarray) -> Exact:
    """Many independent balls above one frictionless plane, each a :func:`bouncing_ball`.

    Every particle starts above plane 0 with gravity along the plane's inward normal and no
    other force; each follows its own chain of parabolas (:func:`bounce_schedule`).
    """
    m = case.particles
    _require(
        len(m.planes) == 1
        and m.drag == 0
        and not len(m.springs)
        and not len(m.anchors)
        and m.gravitation is None
        and not m.fields
        and not m.impulses,
        case,
        "independent particles, one plane, gravity",
    )
    plane = m.planes[0]
    n = plane.normal
    g = float(-(m.gravity @ n))
    _require(
        g > 0 and np.allclose(m.gravity, -g * n, rtol=0, atol=1e-12 * g),
        case,
        "gravity along the plane's inward normal",
    )
    _require(
        bool(np.all((m.x0 - plane.point) @ n - m.radius >= 0)),
        case,
        "every particle to start on or above the plane",
    )
    x, v = bounce_paths(m.x0, m.v0, m.radius, plane, g, t)
    return Exact(t, x, v, None)
