"""Independent routes to truestep's published numbers, for the property audit (tests/audit/test_audit_*.py).

Everything here is written from the physics and from the documented definitions of the
quantities, not from the code that computes them: nothing of ``truestep.measures.metrics``,
``truestep.measures.properties``, ``truestep.measures.restitution``, ``truestep.measures.stability``,
``truestep.cases.exact*`` or ``truestep.reference_impl`` is imported. The inputs are a
case's scene parameters (masses, springs, planes ...) and a run's raw arrays
(``t`` (T,), ``x`` and ``v`` (T, n, 3), ``alive`` (T, n)), in SI units.
"""

from __future__ import annotations

import functools
import itertools
import math

import numpy as np
from scipy.integrate import solve_ivp

# -- energy ---------------------------------------------------------------------------------


def energy(model, x: np.ndarray, v: np.ndarray, alive: np.ndarray | None = None) -> np.ndarray:
    """Kinetic + potential energy (J) of states ``x``, ``v`` (T, n, 3), shape (T,).

    The convention the tables document (README, ``total_energy``): gravity's potential is
    ``-m g . x`` (zero at the origin); pinned and dead particles carry no kinetic or
    gravitational energy; springs (pairs and anchors) store ``k (L - r)^2 / 2``;
    gravitation ``-G m_i m_j / sqrt(r^2 + eps^2)`` per pair. A relative drift
    ``|E - E(0)| / |E(0)|`` depends on these zeros, so the same ones are used.
    """
    x, v = np.asarray(x, float), np.asarray(v, float)
    weight = np.where(model.fixed, 0.0, model.mass)[None, :] * np.ones(x.shape[:2])
    if alive is not None:
        weight = weight * alive
    total = np.zeros(len(x))
    for rows in _chunks(len(x), x.shape[1] * max(len(model.springs.i), len(model.anchors.i), 1)):
        xs, vs = x[rows], v[rows]
        total[rows] = np.sum(weight[rows] * (0.5 * np.sum(vs**2, axis=2) - xs @ model.gravity), axis=1)
        s = model.springs
        if len(s.i):
            length = np.sqrt(np.sum((xs[:, s.i] - xs[:, s.j]) ** 2, axis=2))
            total[rows] += np.sum(0.5 * s.stiffness * (length - s.rest) ** 2, axis=1)
        a = model.anchors
        if len(a.i):
            length = np.sqrt(np.sum((xs[:, a.i] - a.point) ** 2, axis=2))
            total[rows] += np.sum(0.5 * a.stiffness * (length - a.rest) ** 2, axis=1)
        if model.gravitation is not None:
            G, eps = model.gravitation.G, model.gravitation.softening
            i, j = np.triu_indices(x.shape[1], k=1)
            r2 = np.sum((xs[:, i] - xs[:, j]) ** 2, axis=2)
            total[rows] -= np.sum(G * model.mass[i] * model.mass[j] / np.sqrt(r2 + eps**2), axis=1)
    return total


def _chunks(count: int, per_row: int, budget: int = 1 << 21) -> list[slice]:
    """Slices of ``count`` rows holding at most about ``budget`` items of ``per_row`` each
    (the pair arrays above stay a few tens of MB however long a run)."""
    size = max(1, budget // max(per_row, 1))
    return [slice(k, min(k + size, count)) for k in range(0, count, size)]


def relative_drift(e: np.ndarray) -> tuple[float, float]:
    """``max |E - E(0)| / |E(0)|`` and its last value."""
    dev = np.abs(e - e[0]) / abs(e[0])
    return float(dev.max()), float(dev[-1])


# -- closed forms ---------------------------------------------------------------------------


def free_flight(x0, v0, g, t):
    """``x0 + v0 t + g t^2 / 2`` and its velocity, (T, n, 3) each."""
    tt = np.asarray(t, float)[:, None, None]
    return x0 + v0 * tt + 0.5 * g * tt**2, v0 + g * tt + 0.0 * tt


def drag_flight(x0, v0, g, k, m, t):
    """``m x'' = m g - k x'`` from ``x0``, ``v0`` (n, 3): terminal velocity ``m g / k``."""
    tt = np.asarray(t, float)[:, None, None]
    tau = (np.asarray(m, float) / k)[None, :, None]
    v_inf = tau * g
    decay = np.exp(-tt / tau)
    return x0 + v_inf * tt + (v0 - v_inf) * tau * (1.0 - decay), v_inf + (v0 - v_inf) * decay


def oscillator(m: float, k: float, c: float, u0: float, w0: float, t):
    """``m u'' + c u' + k u = 0`` from ``u0``, ``w0``: ``u = A e^(l1 t) + B e^(l2 t)``.

    The roots ``l`` of ``m l^2 + c l + k`` in complex arithmetic (one formula for every
    damping ratio but the critical one, which gets ``(u0 + (w0 - l u0) t) e^(l t)``).
    Returns ``u``, ``u'`` (T,).
    """
    t = np.asarray(t, float)
    disc = complex(c * c - 4.0 * m * k)
    l1, l2 = (-c + np.sqrt(disc)) / (2 * m), (-c - np.sqrt(disc)) / (2 * m)
    if abs(l1 - l2) < 1e-12 * max(abs(l1), 1.0):
        lam = l1.real
        u = (u0 + (w0 - lam * u0) * t) * np.exp(lam * t)
        du = (w0 - lam * u0) * np.exp(lam * t) + lam * u
        return u, du
    b = (w0 - l1 * u0) / (l2 - l1)
    a = u0 - b
    e1, e2 = np.exp(l1 * t), np.exp(l2 * t)
    return (a * e1 + b * e2).real, (a * l1 * e1 + b * l2 * e2).real


def kepler_orbit(mu: float, r0: np.ndarray, w0: np.ndarray, t):
    """Relative position and velocity (T, 2) of a bound two-body orbit in its plane.

    Orbital elements from the start (``r0``, ``w0`` (2,)); Kepler's equation
    ``E - e sin E = M`` solved by bisection on ``[M - e, M + e]`` (where its root lies),
    70 halvings: to the last bit.
    """
    t = np.asarray(t, float)
    r, speed2 = float(np.hypot(*r0)), float(w0 @ w0)
    a = 1.0 / (2.0 / r - speed2 / mu)
    h = float(r0[0] * w0[1] - r0[1] * w0[0])
    rv = float(r0 @ w0)
    e_vec = ((speed2 - mu / r) * r0 - rv * w0) / mu
    e = float(np.hypot(*e_vec))
    p = e_vec / e if e > 1e-10 else r0 / r
    q = np.sign(h) * np.array([-p[1], p[0]])
    n = math.sqrt(mu / a**3)
    # start: eccentric anomaly of r0
    cos_nu, sin_nu = float(r0 @ p) / r, float(r0 @ q) / r
    e0 = math.atan2(math.sqrt(1 - e * e) * sin_nu, e + cos_nu)
    m_anom = e0 - e * math.sin(e0) + n * t
    lo, hi = m_anom - e - 1e-12, m_anom + e + 1e-12
    for _ in range(70):
        mid = 0.5 * (lo + hi)
        above = mid - e * np.sin(mid) - m_anom > 0
        hi, lo = np.where(above, mid, hi), np.where(above, lo, mid)
    big_e = 0.5 * (lo + hi)
    b = a * math.sqrt(1 - e * e)
    denom = 1 - e * np.cos(big_e)
    pos = (a * (np.cos(big_e) - e))[:, None] * p + (b * np.sin(big_e))[:, None] * q
    vel = (-a * n * np.sin(big_e) / denom)[:, None] * p + (b * n * np.cos(big_e) / denom)[:, None] * q
    return pos, vel


def linear_springs(model, t):
    """Zero-rest-length springs and anchors, no damping or gravity: a sum of normal modes.

    ``M x'' = -K x + b`` per axis; ``x_eq = K^-1 b``; the modes of ``M^(-1/2) K M^(-1/2)``
    (an eigendecomposition, not a matrix exponential). Returns x, v (T, n, 3).
    """
    n = len(model.mass)
    K = np.zeros((n, n))
    b = np.zeros((n, 3))
    s, a = model.springs, model.anchors
    for i, j, k in zip(s.i, s.j, s.stiffness, strict=True):
        K[i, i] += k
        K[j, j] += k
        K[i, j] -= k
        K[j, i] -= k
    for i, point, k in zip(a.i, a.point, a.stiffness, strict=True):
        K[i, i] += k
        b[i] += k * point
    inv_sqrt_m = 1.0 / np.sqrt(model.mass)
    omega2, modes = np.linalg.eigh(K * inv_sqrt_m[:, None] * inv_sqrt_m[None, :])
    omega = np.sqrt(omega2)
    x_eq = np.linalg.solve(K, b)
    t = np.asarray(t, float)
    x = np.empty((len(t), n, 3))
    v = np.empty((len(t), n, 3))
    for d in range(3):
        q0 = modes.T @ ((model.x0[:, d] - x_eq[:, d]) / inv_sqrt_m)
        p0 = modes.T @ (model.v0[:, d] / inv_sqrt_m)
        q = q0 * np.cos(np.outer(t, omega)) + p0 / omega * np.sin(np.outer(t, omega))
        p = -q0 * omega * np.sin(np.outer(t, omega)) + p0 * np.cos(np.outer(t, omega))
        x[:, :, d] = x_eq[:, d] + (q @ modes.T) * inv_sqrt_m
        v[:, :, d] = (p @ modes.T) * inv_sqrt_m
    return x, v


def gravitation_reference(model, t_end: float):
    """Final positions and velocities (n, 3) of point masses under gravitation alone:
    ``solve_ivp`` (DOP853, rtol = atol = 1e-12) on a right-hand side written here."""
    n = len(model.mass)
    G, eps = model.gravitation.G, model.gravitation.softening
    mass = np.asarray(model.mass, float)

    def rhs(_t, y):
        x = y[: 3 * n].reshape(n, 3)
        d = x[None, :, :] - x[:, None, :]
        r2 = np.sum(d * d, axis=2) + eps**2
        np.fill_diagonal(r2, np.inf)
        acc = G * np.sum(mass[None, :, None] * d / r2[:, :, None] ** 1.5, axis=1)
        return np.concatenate([y[3 * n :], acc.ravel()])

    y0 = np.concatenate([model.x0.ravel(), model.v0.ravel()])
    sol = solve_ivp(rhs, (0.0, t_end), y0, method="DOP853", rtol=1e-12, atol=1e-12)
    return sol.y[: 3 * n, -1].reshape(n, 3), sol.y[3 * n :, -1].reshape(n, 3)


@functools.cache
def bounce_times(h0: float, g: float, e: float, count: int) -> tuple[np.ndarray, np.ndarray]:
    """A point dropped from rest ``h0`` above a rigid floor: the first ``count`` bounce
    times (s) and launch speeds (m/s): ``T_1 = sqrt(2 h0 / g)``, flights of ``2 e^k V / g``."""
    speed = math.sqrt(2 * g * h0)
    times, launches = [math.sqrt(2 * h0 / g)], [e * speed]
    for _ in range(count - 1):
        times.append(times[-1] + 2 * launches[-1] / g)
        launches.append(e * launches[-1])
    times_a, launches_a = np.array(times), np.array(launches)
    times_a.flags.writeable = launches_a.flags.writeable = False  # shared by every caller (cached)
    return times_a, launches_a


def bounce_height(h0: float, g: float, e: float, t):
    """Height above the floor and normal velocity of that point, (T,) each: a chain of
    parabolas, at rest after the last bounce (``e < 1``) at ``T_1 (1 + 2 e / (1 - e))``.
    Each time lies in the flight begun by the last bounce before it (``searchsorted`` on
    the bounce times; before the first, the drop)."""
    t = np.asarray(t, float)
    times, launches = bounce_times(h0, g, e, 400)
    k = np.searchsorted(times, t, side="right")  # bounces at or before t
    s = t - times[np.maximum(k - 1, 0)]
    speed = launches[np.maximum(k - 1, 0)]
    u = np.where(k == 0, h0 - 0.5 * g * t**2, speed * s - 0.5 * g * s**2)
    w = np.where(k == 0, -g * t, speed - g * s)
    beyond = k >= len(times)
    u, w = np.where(beyond, 0.0, u), np.where(beyond, 0.0, w)
    if e < 1:
        rest = t >= times[0] * (1 + 2 * e / (1 - e))
        u, w = np.where(rest, 0.0, u), np.where(rest, 0.0, w)
    return u, w


# -- flights and contacts, detected from samples ----------------------------------------------


def flights(t, u, w, g: float, noise: float = 0.0) -> list[np.ndarray]:
    """Runs of consecutive samples in free flight: both ends above the plane (``u > 0``)
    and the normal velocity changed by exactly gravity's ``-g dt`` between them (to 1e-6
    of a step's kick, plus ``noise`` m/s, the samples' own rounding: nothing else
    pushed). Returns the sample indices of each run."""
    t, u, w = map(np.asarray, (t, u, w))
    dt = np.diff(t)
    kick = np.abs(np.diff(w) + g * dt) <= 1e-6 * g * dt + 1e-12 + noise
    free = kick & (u[:-1] > 0) & (u[1:] > 0)
    runs, k = [], 0
    while k < len(free):
        if not free[k]:
            k += 1
            continue
        j = k
        while j < len(free) and free[j]:
            j += 1
        runs.append(np.arange(k, j + 1))
        k = j
    return runs


def ballistic_fit(t, u, idx, g: float) -> dict[str, float]:
    """The parabola of curvature ``-g`` through a flight's heights (least squares on
    ``u + g s^2 / 2 = a + b s``, ``s`` the time from its first sample).

    Every engine here moves a free body on such a parabola (exact schemes, and the
    first-order ones too: their positions lie on it with a slope offset by ``+- g h / 2``
    from their sampled velocities). Returns its vertex ``apex`` (m), the time it left
    the plane (its earlier root, ``launch``, s), its slope at the first sample ``slope``
    (m/s) and the largest residual (m), which says whether the flight is that parabola.
    """
    idx = np.asarray(idx)
    s = t[idx] - t[idx[0]]
    design = np.stack([np.ones_like(s), s], axis=1)
    (a, b), *_ = np.linalg.lstsq(design, u[idx] + 0.5 * g * s**2, rcond=None)
    residual = float(np.max(np.abs(design @ np.array([a, b]) - 0.5 * g * s**2 - u[idx])))
    apex = a + b * b / (2 * g)
    launch = float(t[idx[0]]) + (b - math.sqrt(max(b * b + 2 * g * a, 0.0))) / g
    return {"apex": float(apex), "launch": launch, "slope": float(b), "residual": residual}


# -- meshes -----------------------------------------------------------------------------------


def closed_and_outward(faces: np.ndarray) -> bool:
    """Every directed edge of the triangles appears once and its reverse once: a closed,
    consistently oriented surface."""
    directed = [(int(f[a]), int(f[(a + 1) % 3])) for f in faces for a in range(3)]
    return len(set(directed)) == len(directed) and all((b, a) in set(directed) for a, b in directed)


def enclosed_volume(x: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Volume (m^3) enclosed by triangles ``faces`` at positions ``x`` (T, n, 3): the cones
    from the surface's own centroid, ``sum (a - c) . ((b - c) x (d - c)) / 6``."""
    c = x.mean(axis=1, keepdims=True)
    a, b, d = (x[:, faces[:, k]] - c for k in range(3))
    return np.einsum("tki,tki->t", a, np.cross(b, d)) / 6.0


# -- stability of one oscillator --------------------------------------------------------------


def _one_step(scheme: str, m: float, k: float, c: float, h: float, y: np.ndarray) -> np.ndarray:
    """One step of ``scheme`` on ``m x'' = -k x - c v`` from the state ``y``.

    ``y = [x, v]``, or ``[x, v, a]`` for ``verlet``, whose step starts from the
    acceleration its previous step ended with (``a`` at the new position and the
    half-step velocity: the reuse its docstring describes).
    """

    def acc(x, v):
        return (-k * x - c * v) / m

    x, v = y[0], y[1]
    if scheme in ("euler", "midpoint", "heun", "rk4"):
        # on a linear system an explicit RK method of s = p <= 4 stages is the Taylor
        # polynomial of order p of the exact flow exp(h A)
        order = {"euler": 1, "midpoint": 2, "heun": 2, "rk4": 4}[scheme]
        out, term = np.array([x, v]), np.array([x, v])
        for j in range(1, order + 1):
            term = h * np.array([term[1], acc(term[0], term[1])]) / j
            out = out + term
        return out
    if scheme == "implicit-euler":  # [x', v'] = [x, v] + h f(x', v')
        lhs = np.array([[1.0, -h], [h * k / m, 1.0 + h * c / m]])
        return np.linalg.solve(lhs, np.array([x, v]))
    if scheme == "symplectic-euler":  # velocity first; pybullet, MuJoCo Euler
        v1 = v + h * acc(x, v)
        return np.array([x + h * v1, v1])
    if scheme == "lecture":
        v1 = v + h * acc(x, v)
        return np.array([x + 0.5 * h * (v + v1), v1])
    if scheme == "verlet":
        v_half = v + 0.5 * h * y[2]
        x1 = x + h * v_half
        a1 = acc(x1, v_half)
        return np.array([x1, v_half + 0.5 * h * a1, a1])
    if scheme == "pymunk":  # position first, spring kick, then the damper exactly
        x1 = x + h * v
        return np.array([x1, math.exp(-c * h / m) * (v - h * k * x1 / m)])
    if scheme == "mujoco-implicit":  # (m + h c) (v' - v) = h (-k x - c v); x' = x + h v'
        v1 = v + h * (-k * x - c * v) / (m + h * c)
        return np.array([x + h * v1, v1])
    raise KeyError(scheme)


def step_matrix(scheme: str, m: float, k: float, c: float, h: float) -> np.ndarray:
    """The linear map of one step of ``scheme`` (see :func:`_one_step`), column by column:
    each engine's documented update applied to the unit states."""
    n = 3 if scheme == "verlet" else 2
    return np.stack([_one_step(scheme, m, k, c, h, e) for e in np.eye(n)], axis=1)


def stable_limit(scheme: str, m: float, k: float, c: float) -> float:
    """The largest step (s) at which ``scheme`` does not grow on ``m x'' = -k x - c v``:
    spectral radius of :func:`step_matrix` at most 1 (to 1e-14).

    Steps are searched in ``omega h`` from 1e-3 to 1e3 (``omega = sqrt(k / m)``): a log
    grid of 400 finds the first growing step, bisection (60 halvings) its edge. Returns 0
    when even ``omega h = 1e-3`` grows (explicit Euler, midpoint and the lecture's update
    on an undamped oscillator grow by ``1 + O((omega h)^2)`` or ``1 + O((omega h)^4)``
    at every step: at 1e-3 that is 1e-7 or 1e-13, above the round-off of a 2 x 2
    eigenvalue), ``inf`` when none grows.
    """
    omega = math.sqrt(k / m)

    def grows(h: float) -> bool:
        return float(np.max(np.abs(np.linalg.eigvals(step_matrix(scheme, m, k, c, h))))) > 1 + 1e-14

    grid = np.geomspace(1e-3, 1e3, 400) / omega
    first = next((i for i, h in enumerate(grid) if grows(h)), None)
    if first is None:
        return math.inf
    if first == 0:
        return 0.0
    a, b = grid[first - 1], grid[first]
    for _ in range(60):
        mid = 0.5 * (a + b)
        a, b = (a, mid) if grows(mid) else (mid, b)
    return float(a)


def highest_frequency(model) -> float:
    """``omega_max`` (rad/s) of springs and anchors of zero rest length, or of rest length
    met at the start along their line (stiffness ``k u u^T``): the largest eigenvalue of
    ``M^(-1/2) K M^(-1/2)`` over the free particles' coordinates."""
    n = len(model.mass)
    K = np.zeros((3 * n, 3 * n))

    def add(i, j, k, d, rest):
        u = d / np.linalg.norm(d)
        block = k * (np.eye(3) if rest == 0 else np.outer(u, u))
        K[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] += block
        if j is not None:
            K[3 * j : 3 * j + 3, 3 * j : 3 * j + 3] += block
            K[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] -= block
            K[3 * j : 3 * j + 3, 3 * i : 3 * i + 3] -= block

    s, a = model.springs, model.anchors
    for i, j, k, r in zip(s.i, s.j, s.stiffness, s.rest, strict=True):
        add(i, j, k, model.x0[i] - model.x0[j], r)
    for i, p, k, r in zip(a.i, a.point, a.stiffness, a.rest, strict=True):
        add(i, None, k, model.x0[i] - p, r)
    free = np.repeat(~np.asarray(model.fixed), 3)
    if model.dimension == 2:
        free &= np.tile([True, True, False], n)
    w = 1.0 / np.sqrt(np.repeat(model.mass, 3)[free])
    Kf = K[np.ix_(free, free)] * w[:, None] * w[None, :]
    return float(np.sqrt(np.max(np.linalg.eigvalsh(Kf))))


# -- emitters ---------------------------------------------------------------------------------


def lives(alive: np.ndarray) -> list[tuple[int, int, int]]:
    """Every particle life as (slot, first record, last record): a maximal run of records
    in which one slot is alive."""
    out = []
    for slot in range(alive.shape[1]):
        col = alive[:, slot]
        k = 0
        while k < len(col):
            if col[k]:
                j = k
                while j + 1 < len(col) and col[j + 1]:
                    j += 1
                out.append((slot, k, j))
                k = j + 1
            else:
                k += 1
    return out


def spawn_moments(n: float, r: float, samples: int = 400_000) -> tuple[float, float]:
    """Mean and variance of ``floor(X + U')`` with ``X = n + U r`` (``U``, ``U'`` uniform on
    [0, 1)): given ``X`` the count is ``floor(X)`` plus a coin of probability ``frac(X)``,
    so ``E = E[X]`` and ``Var = Var X + E[frac (1 - frac)]``, integrated here by the
    midpoint rule over ``U`` (``samples`` points)."""
    u = (np.arange(samples) + 0.5) / samples
    xs = n + u * r
    frac = xs - np.floor(xs)
    return float(xs.mean()), float(xs.var() + np.mean(frac * (1 - frac)))


def population_null(
    sampled_frames: np.ndarray, n: float, r: float, lifetimes: np.ndarray, reps: int, seed: int
) -> np.ndarray:
    """Monte Carlo of the summed live population at ``sampled_frames``: every frame ``i``
    spawns ``floor(n + U r + U')`` particles, each living ``L`` frames (uniform over
    ``lifetimes``) and counted at the sampled frames in ``i .. i + L - 1``. Returns the
    ``reps`` sums."""
    rng = np.random.default_rng(seed)
    last = int(sampled_frames.max())
    frames = np.arange(last + 1)
    counts = np.floor(n + rng.random((reps, len(frames))) * r + rng.random((reps, len(frames))))
    counts = counts.astype(int)
    sampled = np.zeros(last + 1 + int(lifetimes.max()) + 1, int)
    sampled[sampled_frames] = 1
    cum = np.concatenate([[0], np.cumsum(sampled)])
    totals = np.zeros(reps)
    for i in frames:
        k = counts[:, i]
        draws = rng.choice(lifetimes, size=(reps, int(k.max()) if k.max() > 0 else 0))
        mask = np.arange(draws.shape[1])[None, :] < k[:, None]
        seen = cum[np.minimum(i + draws, len(cum) - 1)] - cum[i]  # frames i .. i + L - 1
        totals += np.sum(np.where(mask, seen, 0), axis=1)
    return totals


# -- the energy scale and the motion's verdicts -----------------------------------------------


def kinetic_energy(model, v: np.ndarray, alive: np.ndarray | None = None) -> np.ndarray:
    """``sum m |v|^2 / 2`` over free (and alive) particles, (T,) for ``v`` (T, n, 3)."""
    weight = np.where(model.fixed, 0.0, model.mass)[None, :] * np.ones(v.shape[:2])
    if alive is not None:
        weight = weight * alive
    return 0.5 * np.sum(weight * np.sum(np.asarray(v, float) ** 2, axis=2), axis=1)


def exchanged(kinetic: np.ndarray, potential: np.ndarray) -> float:
    """The energy a motion exchanges: ``max(KE_max, PE_max - PE_min)`` along it (J). A
    shift of the potential's zero (translating the scene, lifting it) changes neither."""
    ok = np.isfinite(kinetic) & np.isfinite(potential)
    return max(float(np.max(kinetic[ok])), float(np.max(potential[ok]) - np.min(potential[ok])))


def energy_behaviour(model) -> str:
    """What a scene's exact energy may do, from its features: ``source`` (force fields,
    emitters, impulses may put energy in), ``dissipative`` (damping, drag, inelastic or
    frictional planes take it out, nothing puts it in) or ``conservative``."""
    if model is None:
        return "conservative"
    if len(model.fields) or len(model.emitters) or len(model.impulses):
        return "source"
    lossy = (
        model.drag > 0
        or np.any(model.springs.damping > 0)
        or np.any(model.anchors.damping > 0)
        or any(p.restitution < 1 or p.friction > 0 for p in model.planes)
    )
    return "dissipative" if lossy else "conservative"


GAIN = 0.1
"""A dissipative scene may stay at most this fraction of its energy scale above its start
through the late half of a run (the median there)."""
LEFT = 0.5
"""A conservative scene above its start by more than this fraction of its scale through the
whole late half of the run has left its energy for good."""
BAND = 0.25
"""Growth: a peak above the band before it by more than a quarter of the band's width."""
FLOOR = 1e-9
"""Rises below this fraction of the energy scale are round-off, not growth."""


def _halves(t: np.ndarray) -> int:
    """Index of the first record of the late half (time at or after the run's middle)."""
    return max(int(np.searchsorted(t, t[0] + 0.5 * (t[-1] - t[0]))), 1)


def rises_past_its_band(t, e, scale) -> bool:
    """The late half's highest energy above the early half's band of ``E - E(0)`` (0
    included) by more than a quarter of the band's width and round-off: a run whose
    energy grows exponentially from its start doubles its rise from the middle on."""
    e = np.asarray(e, float)
    if not np.all(np.isfinite(e)):
        return True
    d = e - e[0]
    k = _halves(np.asarray(t, float))
    early, late = d[:k], d[k:]
    if not len(late):
        return False
    return float(late.max()) > early.max() + BAND * (early.max() - early.min()) + FLOOR * scale


def grows_every_quarter(t, e, scale) -> bool:
    """Each quarter's highest ``E - E(0)`` above the band of the quarter before it (0
    included) by a quarter of its width and round-off: growth that does not stop."""
    t, e = np.asarray(t, float), np.asarray(e, float)
    if not np.all(np.isfinite(e)):
        return True
    cuts = np.searchsorted(t, t[0] + (t[-1] - t[0]) * np.array([0.25, 0.5, 0.75]))
    parts = [p for p in np.split(e - e[0], cuts) if len(p)]
    if len(parts) < 4:
        return rises_past_its_band(t, e, scale)
    for before, now in itertools.pairwise(parts):
        hi, lo = max(float(before.max()), 0.0), min(float(before.min()), 0.0)
        if not float(now.max()) > hi + BAND * (hi - lo) + FLOOR * scale:
            return False
    return True


def motion_verdict(
    t, e, scale: float, behaviour: str, escape: float | None = None, t_all=None, e_all=None
) -> tuple[str, float | None]:
    """``("ok", None)`` or ``("unstable", when)`` for a finite run, from its energy at every
    step it took (``t_all``, ``e_all``; its records ``t``, ``e`` when those are not given).
    Unstable: the escape energy reached and kept to the end (a spike through a close
    encounter that comes back below it is no escape; ``when``: the step after the last one
    below it); a passive scene's energy more than ``scale`` from its start and still
    growing in every quarter; a dissipative scene more than :data:`GAIN` of its scale
    above its start through the late half (its median: an overshoot that a stable method
    then gives off is no gain); a conservative one more than :data:`LEFT` of it above its
    start at every step of the late half. ``when``: the first step that shows it."""
    t_all = np.asarray(t if t_all is None else t_all, float)
    e_all = np.asarray(e if e_all is None else e_all, float)
    if escape is not None and e_all[-1] >= escape:
        below = np.flatnonzero(e_all < escape)
        return "unstable", float(t_all[below[-1] + 1 if len(below) else 0])
    if behaviour == "source":
        return "ok", None
    rise = e_all - e_all[0]
    far = np.abs(rise) > scale
    if far.any() and grows_every_quarter(t_all, e_all, scale):
        return "unstable", float(t_all[np.argmax(far)])
    late = rise[_halves(t_all) :]
    if behaviour == "dissipative":
        if len(late) and float(np.median(late)) > GAIN * scale:
            return "unstable", float(t_all[np.argmax(rise > GAIN * scale)])
        return "ok", None
    if len(late) and late.min() > LEFT * scale:
        return "unstable", float(t_all[np.argmax(rise > LEFT * scale)])
    return "ok", None


# -- references of my own, known along the whole run -------------------------------------------


def particle_rhs(model):
    """``y' = f(y)`` of point masses (``y = [x, v]``, (6n,)) under uniform gravity, drag,
    springs and anchors (Hooke along the line, dampers on the relative velocity along it)
    and universal gravitation; pinned particles stay where they are."""
    n = len(model.mass)
    mass = np.asarray(model.mass, float)
    free = ~np.asarray(model.fixed)
    s, a = model.springs, model.anchors
    grav = model.gravitation

    def rhs(_t, y):
        x, v = y[: 3 * n].reshape(n, 3), y[3 * n :].reshape(n, 3)
        f = mass[:, None] * model.gravity - model.drag * v
        if len(s.i):
            d = x[s.j] - x[s.i]
            length = np.sqrt(np.sum(d * d, axis=1))
            u = d / length[:, None]
            pull = s.stiffness * (length - s.rest) + s.damping * np.sum((v[s.j] - v[s.i]) * u, axis=1)
            np.add.at(f, s.i, pull[:, None] * u)
            np.add.at(f, s.j, -pull[:, None] * u)
        if len(a.i):
            d = x[a.i] - a.point
            length = np.sqrt(np.sum(d * d, axis=1))
            u = d / np.where(length > 0, length, 1.0)[:, None]
            pull = a.stiffness * (length - a.rest) + a.damping * np.sum(v[a.i] * u, axis=1)
            np.add.at(f, a.i, -pull[:, None] * u)
        if grav is not None:
            d = x[None, :, :] - x[:, None, :]
            r2 = np.sum(d * d, axis=2) + grav.softening**2
            np.fill_diagonal(r2, np.inf)
            f += grav.G * mass[:, None] * np.sum(mass[None, :, None] * d / r2[:, :, None] ** 1.5, axis=1)
        acc = np.where(free[:, None], f / mass[:, None], 0.0)
        return np.concatenate([np.where(free[:, None], v, 0.0).ravel(), acc.ravel()])

    return rhs


def particle_reference(model, t_end: float, tol: float = 1e-12):
    """``t -> (x, v)`` (T, n, 3) each: ``solve_ivp`` (DOP853, rtol = atol = ``tol``) on
    :func:`particle_rhs`, read between its steps by its own continuous extension."""
    n = len(model.mass)
    y0 = np.concatenate([model.x0.ravel(), model.v0.ravel()])
    sol = solve_ivp(
        particle_rhs(model), (0.0, t_end), y0, method="DOP853", rtol=tol, atol=tol, dense_output=True
    )
    assert sol.success, sol.message

    def at(t):
        y = sol.sol(np.asarray(t, float)).T
        return y[:, : 3 * n].reshape(-1, n, 3), y[:, 3 * n :].reshape(-1, n, 3)

    return at


def rk4_states(rhs, y0: np.ndarray, h: float, steps: int) -> np.ndarray:
    """Classical RK4 at fixed step ``h``: the state after every step, (steps + 1, dim)."""
    out = np.empty((steps + 1, len(y0)))
    out[0] = y = np.asarray(y0, float)
    for k in range(steps):
        t = k * h
        k1 = rhs(t, y)
        k2 = rhs(t + h / 2, y + h / 2 * k1)
        k3 = rhs(t + h / 2, y + h / 2 * k2)
        k4 = rhs(t + h, y + h * k3)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out[k + 1] = y
    return out


# -- contacts and flights read from the samples alone -------------------------------------------


def arcs(t, u, w, g: float, noise: float = 0.0):
    """The flights of a ball over a plane and the contacts between them, read from its
    samples: height ``u`` of its lowest point (m), normal velocity ``w`` (m/s), gravity
    ``g`` toward the plane.

    Flights are the runs of :func:`flights` (free-fall kicks, above the plane, to
    ``noise`` m/s). Returns
    ``(drop, found)``: ``drop`` the highest sample before the first contact (m), and per
    contact after a flight a dict: ``before`` and ``after`` (the last flight sample
    before it, the first after it; ``after`` None when no flight follows), ``low`` (the
    contact's lowest sample), ``apex`` (the highest sample of the flight after it, NaN
    when the run ends while that flight still rises).
    """
    t, u, w = map(np.asarray, (t, u, w))
    runs = flights(t, u, w, g, noise)
    if not runs:
        return float(np.max(u)), []
    drop = float(np.max(u[: runs[0][-1] + 1]))
    found = []
    for k, run in enumerate(runs):
        before = int(run[-1])
        if before >= len(t) - 1:
            break  # the run ends in flight
        nxt = runs[k + 1] if k + 1 < len(runs) else None
        after = None if nxt is None else int(nxt[0])
        end = len(t) - 1 if after is None else after
        low = before + int(np.argmin(u[before : end + 1]))
        apex = np.nan
        if nxt is not None:
            top = int(nxt[0]) + int(np.argmax(u[nxt]))
            still_rising = top == len(t) - 1 and w[top] > 0
            apex = np.nan if still_rising else float(u[top])
        found.append({"before": before, "after": after, "low": low, "apex": apex})
    return drop, found


def oscillator_run(
    scheme: str, m: float, k: float, c: float, h: float, u0: float, w0: float, steps: int
) -> tuple[np.ndarray, np.ndarray]:
    """``steps`` steps of ``scheme`` (see :func:`_one_step`) on ``m u'' = -k u - c u'`` from
    ``u0``, ``w0``: displacements and velocities after every step, (steps + 1,) each
    (NaN from the first step beyond 1e12: a blow-up)."""
    matrix = step_matrix(scheme, m, k, c, h)
    y = np.array([u0, w0] if scheme != "verlet" else [u0, w0, (-k * u0 - c * w0) / m], float)
    out = np.full((steps + 1, len(y)), np.nan)
    out[0] = y
    for i in range(1, steps + 1):
        y = matrix @ y
        if not np.all(np.abs(y) < 1e12):
            break
        out[i] = y
    return out[:, 0], out[:, 1]


def backward_euler_has_no_solution(model, x: np.ndarray, v: np.ndarray, h: float) -> tuple[bool, str]:
    """Whether backward Euler's step ``x' = x + h v'``, ``v' = v + h a(x')`` from ``x``, ``v``
    (n, 3) has no solution, for point masses under unsoftened gravitation alone.

    The closest pair's separation ``r' = x'_j - x'_i`` solves
    ``r' (1 + h^2 mu / |r'|^3) = c + h^2 d`` with ``mu = G (m_i + m_j)``, ``c = r + h w``
    (``w`` their relative velocity) and ``d`` the other bodies' pull on the pair's
    separation: ``r'`` is parallel to the right-hand side, and ``s + h^2 mu / s^2`` has
    its least value ``1.5 (2 h^2 mu)^(1/3)`` over ``s > 0``. So there is no solution when
    ``|c| + h^2 |d|_max`` is below that value; ``|d|_max`` from the other bodies at no less
    than half their present distance from the pair (each step moves a body by ``h |v'|``,
    a small part of it, which the caller checks). For two bodies ``d = 0``: exact.
    Returns the verdict and the numbers."""
    G = model.gravitation.G
    n = len(model.mass)
    d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2) + np.diag(np.full(n, np.inf))
    i, j = np.unravel_index(np.argmin(d), d.shape)
    mu = G * (model.mass[i] + model.mass[j])
    c = float(np.linalg.norm(x[j] - x[i] + h * (v[j] - v[i])))
    pull = 0.0
    for k in range(n):
        if k not in (i, j):
            near = 0.5 * min(d[i, k], d[j, k])
            pull += 2 * G * model.mass[k] / near**2
    least = 1.5 * (2 * h * h * mu) ** (1 / 3)
    return c + h * h * pull < least, (
        f"pair {i}-{j}: |r + h w| = {c:.6g}, other bodies' pull "
        f"h^2 |d| <= {h * h * pull:.3g}, least reachable {least:.6g}"
    )


def kepler_backward_euler(mu: float, q0, w0, h: float, t_end: float):
    """Backward Euler on ``q'' = -mu q / |q|^3`` from ``q0``, ``w0`` (2,), solved here in
    closed form: ``q' (1 + h^2 mu / |q'|^3) = c = q + h w`` makes ``q' = s c / |c|`` with
    ``s + h^2 mu / s^2 = |c|``, whose larger root (the one that tends to ``|c|`` as
    ``h -> 0``) is found by bisection above the least point ``(2 h^2 mu)^(1/3)``, and
    ``w' = (q' - q) / h``. Stops at the first step whose ``|c|`` is below the least value
    ``1.5 (2 h^2 mu)^(1/3)``: there the step has no solution. Returns the states after
    each step taken, (k + 1, 4), and the index of that step (None if none)."""
    q, w = np.array(q0, float), np.array(w0, float)
    floor = (2 * h * h * mu) ** (1 / 3)
    states = [np.concatenate([q, w])]
    for k in range(round(t_end / h)):
        c = q + h * w
        size = float(np.linalg.norm(c))
        if size < 1.5 * floor:
            return np.array(states), k
        lo, hi = floor, size
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if mid + h * h * mu / mid**2 > size else (mid, hi)
        q1 = 0.5 * (lo + hi) * c / size
        w, q = (q1 - q) / h, q1
        states.append(np.concatenate([q, w]))
    return np.array(states), None
