"""Exact solutions the cases are measured against.

Each solution is a function ``exact(case, t) -> Exact`` of the case and the times
``t`` (s, shape ``(T,)``) at which a run was recorded. Positions come back in the same
layout as a trajectory's: particle scenes ``(T, n, 3)``, ODE scenes the whole state as
``(T, 1, dim)``. A solution known only at some times (a periodic orbit's period) returns
those times alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from truestep.cases import exact_particles
from truestep.cases.case import Case, OdeSpec
from truestep.cases.closed_forms import kepler_state, oscillator
from truestep.cases.exact_registry import EXACT, Exact, ExactFn, exact_solution
from truestep.cases.plugins import EXACT_GROUP, find_entry, names_with_entries
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.solvers import MethodFacts, get_solver
from truestep.reference_impl.system import System

__all__ = [
    "EXACT",
    "Exact",
    "ExactFn",
    "exact_named",
    "exact_names",
    "exact_particles",
    "exact_solution",
    "kepler_state",
    "oscillator",
]


@exact_solution("circle", params={}, kind="ode")
def circle(case: Case, t: np.ndarray) -> Exact:
    """``x' = (-y, x)``: the start rotated by angle ``t``; half the squared radius is kept."""
    y0 = case.ode_spec.y0
    c, s = np.cos(t), np.sin(t)
    x = np.stack([c * y0[0] - s * y0[1], s * y0[0] + c * y0[1]], axis=1)
    return Exact.of_ode(t, x, np.full(t.shape, 0.5 * float(y0 @ y0)))


@exact_solution("anchored-oscillator", params={}, kind="particles")
def anchored_oscillator(case: Case, t: np.ndarray) -> Exact:
    """One particle on one anchored spring-damper, moving along the spring's line.

    With the start on the spring's axis and the velocity along it, the motion stays on
    that line: ``u`` (extension beyond rest) obeys ``m u'' + k_d u' + k_s u = 0``.
    Energy: ``m v^2 / 2 + k_s u^2 / 2`` (gravity must be zero).
    """
    m = case.particles
    a = m.anchors
    d0 = m.x0[0] - a.point[0]
    axis = d0 / np.linalg.norm(d0)
    u0 = float(np.linalg.norm(d0) - a.rest[0])
    w0 = float(m.v0[0] @ axis)
    u, du = oscillator(float(m.mass[0]), float(a.stiffness[0]), float(a.damping[0]), u0, w0, t)
    x = a.point[0] + (a.rest[0] + u)[:, None] * axis
    v = du[:, None] * axis
    energy = 0.5 * m.mass[0] * du**2 + 0.5 * a.stiffness[0] * u**2
    return Exact(t, x[:, None, :], v[:, None, :], energy)


@exact_solution("kepler", params={}, kind="ode")
def kepler(case: Case, t: np.ndarray) -> Exact:
    """The Kepler orbit from pericentre ``(a (1 - e), 0)``; energy ``-mu / (2 a)``."""
    mu = case.ode_spec.params.get("mu", 1.0)
    q0, v0 = case.ode_spec.y0[:2], case.ode_spec.y0[2:]
    r0 = float(np.linalg.norm(q0))
    energy = 0.5 * float(v0 @ v0) - mu / r0
    a = -mu / (2 * energy)
    e = 1 - r0 / a
    state = kepler_state(e, mu, a, t)
    return Exact.of_ode(t, state, np.full(t.shape, energy))


def _check_period(case: Case) -> None:
    if not isinstance(case.scene, OdeSpec):
        raise ValueError("'periodic' is for ODE cases")
    period = case.exact_params.get("period")
    if isinstance(period, bool) or not isinstance(period, int | float) or not 0 < period < np.inf:
        raise ValueError(f"needs [reference] period, a positive number of seconds, got {period!r}")


@exact_solution("periodic", check=_check_period, params={"period": "positive"}, kind="ode", energy=False)
def periodic(case: Case, t: np.ndarray) -> Exact:
    """A periodic orbit known only at its start and after whole periods (``period``, s)."""
    period = float(case.exact_params["period"])
    k = np.round(t / period)
    keep = np.abs(t - k * period) <= 1e-9 * max(1.0, period)
    y0 = case.ode_spec.y0
    return Exact.of_ode(t[keep], np.tile(y0, (int(keep.sum()), 1)))


LINEAR_MAX_PARTICLES = 1000
"""The most particles a dense linear solve (the ``linear`` exact solution, the modes of
:func:`linear_modes`) takes on: its matrices grow with the square of the particles and
its work with the cube (1000 particles: 2001 x 2001 exponentials, a 3000 x 3000
eigenproblem, seconds each). A bigger scene has no exact solution of this kind."""


def linear_modes(case: Case) -> tuple[float, float] | None:
    """Highest angular frequency (rad/s) and its damping ratio, if the scene is linear.

    Linear here: point masses joined by springs (and anchored springs) that start at rest
    length along straight lines or have zero rest length, no gravity, drag, fields,
    gravitation or planes. ``omega_max^2`` is the largest eigenvalue of
    ``M^(-1/2) K M^(-1/2)`` with ``K`` the stiffness matrix of the springs at the start;
    the damping ratio is reported for a single damped spring, and NaN otherwise. ``None``
    for a scene of more than :data:`LINEAR_MAX_PARTICLES` particles (not computed).
    """
    m = case.model
    if m is None or m.planes or m.fields or m.gravitation is not None or m.drag:
        return None
    if m.n > LINEAR_MAX_PARTICLES:
        return None
    if np.any(m.gravity) or m.emitters or m.impulses:
        return None
    n = m.n
    free = ~m.fixed
    K = np.zeros((3 * n, 3 * n))

    def block(i: int, j: int | None, k: float, d: np.ndarray, rest: float) -> bool:
        length = float(np.linalg.norm(d))
        if rest == 0.0:
            kk = k * np.eye(3)
        elif abs(length - rest) <= 1e-12 * max(rest, 1.0):
            u = d / length
            kk = k * np.outer(u, u)
        else:
            return False
        K[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] += kk
        if j is not None:
            K[3 * j : 3 * j + 3, 3 * j : 3 * j + 3] += kk
            K[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] -= kk
            K[3 * j : 3 * j + 3, 3 * i : 3 * i + 3] -= kk
        return True

    s, a = m.springs, m.anchors
    for i, j, k, r in zip(s.i, s.j, s.stiffness, s.rest, strict=True):
        if not block(int(i), int(j), float(k), m.x0[i] - m.x0[j], float(r)):
            return None
    for i, p, k, r in zip(a.i, a.point, a.stiffness, a.rest, strict=True):
        if not block(int(i), None, float(k), m.x0[i] - p, float(r)):
            return None
    dof = np.repeat(free, 3)
    inv_sqrt_m = 1.0 / np.sqrt(np.repeat(m.mass, 3)[dof])
    Kf = K[np.ix_(dof, dof)] * inv_sqrt_m[:, None] * inv_sqrt_m[None, :]
    omega_max = float(np.sqrt(max(np.max(np.linalg.eigvalsh(Kf)), 0.0)))
    damping = np.concatenate([s.damping, a.damping])
    if not np.any(damping):
        zeta = 0.0
    elif n == 1 and len(a) == 1 and not len(s):
        zeta = float(a.damping[0] / (2 * np.sqrt(a.stiffness[0] * m.mass[0])))
    else:
        zeta = float("nan")
    return omega_max, zeta


def stability_limit(case: Case, method: MethodFacts | str | None) -> float | None:
    """The exact largest stable step (s) of a method on a linear scene.

    ``method`` is the method's :class:`~truestep.reference_impl.solvers.MethodFacts` (an
    engine's, :func:`truestep.adapters.base.facts_of`) or the name of a reference method.
    ``0.0`` means unstable at every step, ``inf`` stable at every step, ``None`` unknown
    (not a linear scene, several damped springs, or no stability data declared).

    From the scene's fastest mode (:func:`linear_modes`: ``omega_max`` and its damping
    ratio ``zeta``) and the method's stability data: the step is stable while
    ``omega_max h`` stays below the method's reach on a mode of that damping ratio,
    :meth:`~truestep.reference_impl.solvers.Stability.reach` (undamped: its interval on
    the imaginary axis, e.g. ``2 / omega`` for symplectic Euler and Verlet,
    ``2 sqrt(2) / omega`` for RK4, none for explicit Euler; damped: where its step
    matrix's spectral radius reaches 1, e.g. ``2 zeta / omega`` for explicit Euler).
    """
    modes = linear_modes(case)
    facts = get_solver(method).facts if isinstance(method, str) else method
    if modes is None or facts is None or facts.stability is None:
        return None
    omega, zeta = modes
    if omega == 0:
        return None
    reach = facts.stability.reach(zeta)
    return None if reach is None else reach / omega


def _check_linear(case: Case) -> None:
    """What ``linear`` needs, checked before any matrix is built: zero rest lengths, no
    planes or fields, at most :data:`LINEAR_MAX_PARTICLES` particles."""
    m = case.model
    if m is None:
        raise ValueError("'linear' is the exact solution of particle scenes")
    if np.any(m.springs.rest != 0) or np.any(m.anchors.rest != 0) or m.planes or m.fields:
        raise ValueError(
            f"{case.file}: reference.exact: 'linear' needs zero-rest-length springs and no planes or fields"
        )
    if m.n > LINEAR_MAX_PARTICLES:
        raise ValueError(
            f"'linear' solves at most {LINEAR_MAX_PARTICLES} particles densely "
            f"(its matrices grow with their square); this scene has {m.n}"
        )


@exact_solution("linear", check=_check_linear, params={}, kind="particles")
def linear(case: Case, t: np.ndarray) -> Exact:
    """Any scene of zero-rest-length springs, uniform gravity and drag: a linear ODE.

    With zero rest lengths every spring force is ``-k (x_i - x_j) - k_d (v_i - v_j)``
    (all directions at once), so ``M x'' + C x' + K x = M g`` with constant matrices and
    ``y(t) = expm(A t) y(0)`` for the first-order system augmented by a constant 1 that
    carries gravity. Pinned particles are held where they start. Energy: kinetic +
    spring + gravitational, exact along the solution.
    """
    from scipy.linalg import expm

    _check_linear(case)
    m = case.particles
    n = m.n
    free = ~m.fixed
    K = np.zeros((n, n))
    C = np.zeros((n, n))
    s, a = m.springs, m.anchors
    for i, j, k, c in zip(s.i, s.j, s.stiffness, s.damping, strict=True):
        for mat, val in ((K, k), (C, c)):
            mat[i, i] += val
            mat[j, j] += val
            mat[i, j] -= val
            mat[j, i] -= val
    anchor_force = np.zeros((n, 3))
    for i, p, k, c in zip(a.i, a.point, a.stiffness, a.damping, strict=True):
        K[i, i] += k
        C[i, i] += c
        anchor_force[i] += k * p
    C += m.drag * np.eye(n)
    # Pinned particles: their positions enter as constant forcing on the free ones.
    inv_m = np.where(free, 1.0 / m.mass, 0.0)
    forcing = inv_m[:, None] * (anchor_force - K[:, ~free] @ m.x0[~free]) + np.where(
        free[:, None], m.gravity, 0.0
    )
    Kf = inv_m[free, None] * K[np.ix_(free, free)]
    Cf = inv_m[free, None] * C[np.ix_(free, free)]
    nf = int(free.sum())
    A = np.zeros((2 * nf + 1, 2 * nf + 1))
    A[:nf, nf : 2 * nf] = np.eye(nf)
    A[nf : 2 * nf, :nf] = -Kf
    A[nf : 2 * nf, nf : 2 * nf] = -Cf
    x = np.repeat(m.x0[None], len(t), axis=0)
    v = np.zeros_like(x)
    for d in range(3):
        A[nf : 2 * nf, -1] = forcing[free, d]
        y0 = np.concatenate([m.x0[free, d], m.v0[free, d], [1.0]])
        ys = _expm_flow(expm, A, y0, t)
        x[:, free, d] = ys[:, :nf]
        v[:, free, d] = ys[:, nf : 2 * nf]
    from truestep.reference_impl.particles import total_energy

    energy = total_energy(m, x, v)
    return Exact(t, x, v, energy)


def _expm_flow(expm, A: np.ndarray, y0: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``expm(A t_k) y0`` for increasing times ``t`` (T,), shape (T, len(y0)).

    Steps from each time to the next, ``y_k = expm(A (t_k - t_{k-1})) y_{k-1}``, with one
    matrix exponential per distinct gap (records are a few distinct multiples of the
    step apart): thousands of records cost a handful of exponentials, and the flow's
    round-off grows by about 1e-16 per record.
    """
    ys = np.empty((len(t), len(y0)))
    ys[0] = expm(A * t[0]) @ y0 if len(t) and t[0] != 0 else y0
    flows: dict[float, np.ndarray] = {}
    for k in range(1, len(t)):
        gap = float(t[k] - t[k - 1])
        key = float(f"{gap:.10e}")
        if key not in flows:
            flows[key] = expm(A * gap)
        ys[k] = flows[key] @ ys[k - 1]
    return ys


def _check_reference_run(case: Case) -> None:
    from truestep.reference_impl.solvers import METHODS

    method = case.exact_params.get("method", "dopri5")
    if method not in METHODS:
        raise ValueError(
            f"[reference] method must be a reference method ({', '.join(METHODS)}), got {method!r}"
        )
    m = case.model
    if METHODS[method].adaptive:
        if m is not None and (m.planes or m.emitters):
            raise ValueError(
                "an adaptive reference run needs a smooth scene (no planes, no "
                "emitters): name a fixed-step [reference] method and dt"
            )
        rtol = case.exact_params.get("rtol", 1e-12)
        if isinstance(rtol, bool) or not isinstance(rtol, int | float) or not 1e-14 <= rtol <= 1e-6:
            raise ValueError(f"[reference] rtol must be a number from 1e-14 to 1e-6, got {rtol!r}")
        return
    dt = case.exact_params.get("dt")
    finest = min(case.dts + case.quick_dts)
    if isinstance(dt, bool) or not isinstance(dt, int | float) or not 0 < dt <= finest / 4:
        raise ValueError(
            f"[reference] dt of a fixed-step reference run must be a number of "
            f"seconds at most a quarter of the finest step swept ({finest:g}), "
            f"got {dt!r}"
        )
    if case.duration / dt > 1e7:
        raise ValueError(f"[reference] dt {dt:g} s makes {case.duration / dt:.3g} steps (at most 1e7)")
    n = case.duration / dt
    if abs(n - round(n)) > 1e-9 * n:
        raise ValueError(f"[reference] dt {dt:g} s does not divide the duration {case.duration:g} s")
    for step in case.dts + case.quick_dts:
        ratio = step / dt
        if abs(ratio - round(ratio)) > 1e-9 * ratio:
            raise ValueError(
                f"[reference] dt {dt:g} s must divide every swept step (not "
                f"{step:g} s: {ratio:.6g} of it), so that the run is known at "
                "every time a row records"
            )


@exact_solution(
    "reference-run",
    check=_check_reference_run,
    params={"method": "string", "rtol": "positive", "dt": "positive"},
    energy=False,
)
def reference_run(case: Case, t: np.ndarray) -> Exact:
    """No closed form: a run of the reference implementation far finer than the sweep,
    known along the whole run. ``[reference] method`` names it: ``dopri5`` (the default)
    at ``rtol`` (default 1e-12), for smooth scenes, known at any time by its continuous
    extension; or a fixed-step method at ``dt`` (dividing every swept step, and at most a
    quarter of the finest), for scenes with contacts or emitters, known at each of its
    steps (positions between steps by cubic Hermite interpolation of positions and
    velocities, velocities linearly). Particles that are not alive have NaN positions
    (not compared). Made once per case and kept (:class:`ReferencePath`)."""
    return _reference(case).at(np.asarray(t, float))


def reference_path(case: Case) -> tuple[Exact, np.ndarray | None]:
    """The reference run of a ``reference-run`` case at up to :data:`PATH_RECORDS` + 1
    evenly spread times (an ODE's states as ``x``), and which particles are alive at each
    (``None`` without emitters)."""
    return reference_path_at(case, np.linspace(0.0, case.duration, PATH_RECORDS + 1))


def reference_path_at(case: Case, t: np.ndarray) -> tuple[Exact, np.ndarray | None]:
    """The reference run of a ``reference-run`` case at times ``t`` (s), and which particles
    are alive at each (``None`` without emitters)."""
    path = _reference(case)
    t = np.asarray(t, float)
    return path.at(t), path.alive_at(t)


_REFERENCE_RUNS: dict[tuple, tuple[object, ReferencePath]] = {}
"""Reference runs already made, by case file, name, duration, parameters and scene (the
entry keeps the scene, so its id cannot be reused): the run does not depend on the
times asked, and every row of a case asks again."""
PATH_RECORDS = 2000
"""Evenly spread records of a reference run (for the case's energy scale)."""
STORE_BYTES = 1 << 30
"""The most memory a fixed-step reference run's every step may take; beyond it only the
steps the case's rows record are kept."""


def _reference(case: Case) -> ReferencePath:
    key = (case.file, case.name, case.duration, repr(case.exact_params), repr(case.ode), id(case.scene))
    hit = _REFERENCE_RUNS.get(key)
    if hit is None or hit[0] is not case.scene:
        hit = _REFERENCE_RUNS[key] = (case.scene, ReferencePath.of(case))
    return hit[1]


@dataclass
class ReferencePath:
    """A fine reference run, kept so that its state can be asked at any time of the run.

    t : (K,) s, the stored steps;  states : (K, dim) flat states there;  h : the fixed
    step (s), or None for an adaptive run, whose ``dense`` steps give any time;
    alive : (K, n) or None;  n : particles (None for an ODE case)
    """

    t: np.ndarray
    states: np.ndarray
    h: float | None
    n: int | None
    alive: np.ndarray | None = None
    dense: list | None = None

    @classmethod
    def of(cls, case: Case) -> ReferencePath:
        """Make the case's reference run (``[reference] method``, ``rtol`` or ``dt``)."""
        from truestep.cases.plugins import ode_system
        from truestep.reference_impl.integrate import integrate, record_indices
        from truestep.reference_impl.particles import ParticleSystem
        from truestep.reference_impl.passes import passes_for
        from truestep.reference_impl.solvers import get_solver

        cls_ = get_solver(case.exact_params.get("method", "dopri5"))
        system: System
        match case.scene:
            case OdeSpec() as ode:
                system, n = cast(type[System], ode_system(ode.system))(ode.y0, **ode.params), None
            case ParticleModel() as model:
                system, n = ParticleSystem(model, passes_for(model)), model.n
        if cls_.adaptive:
            tol = float(case.exact_params.get("rtol", 1e-12))
            solver = cast(Any, cls_)(system, rtol=tol, atol=tol)  # an adaptive solver, with dense
            dense: list = []
            run = integrate(
                solver, case.duration, case.duration, on_step=lambda: dense.append(solver.dense())
            )
            path = cls(run.t, run.x, None, n, dense=dense)
        else:
            steps = max(1, round(case.duration / float(case.exact_params["dt"])))
            per_state = 8 * (system.dim + (n or 0))
            keep: int | np.ndarray | None = steps if steps * per_state <= STORE_BYTES else None
            if keep is None:  # only the steps the rows record, and the even grid
                marks = [record_indices(steps, PATH_RECORDS)]
                for dt in case.dts + case.quick_dts:
                    ratio = round(dt / (case.duration / steps))
                    rows = round(case.duration / dt)
                    marks.append(record_indices(rows, case.max_records) * ratio)
                keep = np.unique(np.concatenate(marks))
            run = integrate(
                cls_(system),
                case.duration,
                case.duration / steps,
                max_records=steps,
                record_at=None if isinstance(keep, int) else keep,
            )
            path = cls(run.t, run.x, case.duration / steps, n, alive=run.extra.get("alive"))
        if run.status != "ok":
            raise ValueError(f"{case.file}: the reference run went {run.status} at t = {run.t_fail}")
        return path

    def _grid(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Index of the stored step at or before each time, and whether it is that time."""
        k = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 1)
        near = np.clip(k + 1, 0, len(self.t) - 1)
        k = np.where(np.abs(self.t[near] - t) < np.abs(self.t[k] - t), near, k)
        on = np.abs(self.t[k] - t) <= 1e-9 * np.maximum(1.0, np.abs(t))
        return k, on

    def alive_at(self, t: np.ndarray) -> np.ndarray | None:
        """Which particles are alive at times ``t`` (the stored step at or nearest each)."""
        if self.alive is None:
            return None
        return self.alive[self._grid(t)[0]]

    def states_at(self, t: np.ndarray) -> np.ndarray:
        """Flat states (T, dim) at times ``t`` (s): stored where a step lies there; else by
        the continuous extension (adaptive) or Hermite interpolation (fixed steps, between
        two stored consecutive steps; NaN where the steps between were not stored)."""
        k, on = self._grid(t)
        out = self.states[k].copy()
        for i in np.flatnonzero(~on):
            out[i] = self._between(float(t[i]))
        return out

    def _between(self, t: float) -> np.ndarray:
        if self.dense is not None:
            j = int(np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.dense) - 1))
            return self.dense[j](t)
        j = int(np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 2))
        t0, t1 = self.t[j], self.t[j + 1]
        if self.n is None or not np.isclose(t1 - t0, cast(float, self.h), rtol=1e-9):  # fixed steps
            return np.full(self.states.shape[1], np.nan)
        a, b = self.states[j], self.states[j + 1]
        n3 = 3 * self.n
        s, h = (t - t0) / (t1 - t0), t1 - t0
        h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
        h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
        x = h00 * a[:n3] + h10 * h * a[n3:] + h01 * b[:n3] + h11 * h * b[n3:]
        v = (1 - s) * a[n3:] + s * b[n3:]
        return np.concatenate([x, v])

    def at(self, t: np.ndarray) -> Exact:
        """The run at times ``t`` (s) as an :class:`Exact`: particles' positions and
        velocities (NaN for particles not alive), or an ODE's states as ``y``."""
        states = self.states_at(t)
        if self.n is None:
            return Exact.of_ode(t, states)
        n = self.n
        x, v = states[:, : 3 * n].reshape(-1, n, 3), states[:, 3 * n :].reshape(-1, n, 3)
        alive = self.alive_at(t)
        if alive is not None:
            x, v = x.copy(), v.copy()
            x[~alive] = np.nan
            v[~alive] = np.nan
        return Exact(t, x, v)


def exact_named(name: str) -> ExactFn | None:
    """The exact solution registered as ``name`` (built in, or installed by the entry-point
    group ``truestep.exact``), or ``None``."""
    return find_entry(EXACT_GROUP, name, EXACT, callable, "callable")


def exact_names() -> list[str]:
    """Every exact solution's name: built-in ones, then installed ones."""
    return names_with_entries(EXACT_GROUP, dict(sorted(EXACT.items())))
