"""Explicit Runge-Kutta methods as data (Butcher tableaux) and one stepper.

Euler, midpoint, Heun and classical RK4 are fixed-step tableaux; Dormand-Prince 5(4)
adds an embedded error estimate and a step-size controller. Every method is stepped by
:func:`rk_stages`, so a new method is a new tableau, not new code; its stability follows
from the tableau too (:func:`tableau_stability`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.polynomial import Polynomial

from truestep.reference_impl.solvers.base import Solver, SolverFailed
from truestep.reference_impl.solvers.facts import MethodFacts, Stability, StepMatrix
from truestep.reference_impl.system import System

Feed = tuple[slice | int, np.ndarray | float]
"""Later stages that weigh a stage ``j``, and their weights: a slice of consecutive stages
``i`` with their ``a_ij`` as a column, shape ``(len, 1)``, or one stage and its weight."""


class Stages(NamedTuple):
    """A tableau's stages as :func:`stages_of` gives them and :func:`rk_stages` steps them.

    ``rows``: for each stage ``i`` its node ``c_i`` (the row sum of ``a``) and its
    non-zero weights ``((j, a_ij), ...)`` in order of ``j`` (most of a tableau is zero).
    ``columns``: for each stage ``j`` its node and the :data:`Feed` runs of later stages
    that weigh it; ``None`` if no stage is weighed by more than one other (as in Euler,
    midpoint, Heun and RK4).
    """

    rows: tuple[tuple[float, tuple[tuple[int, float], ...]], ...]
    columns: tuple[tuple[float, tuple[Feed, ...]], ...] | None


def stages_of(a: np.ndarray) -> Stages:
    """The :class:`Stages` of a strictly lower triangular ``a`` (s, s)."""
    a = np.asarray(a, float)
    rows = tuple(
        (float(row.sum()), tuple((int(j), float(row[j])) for j in np.flatnonzero(row[:i])))
        for i, row in enumerate(a)
    )
    columns = []
    for j, (c, _) in enumerate(rows):
        feeds: list[Feed] = []
        weighing = np.flatnonzero(a[j + 1 :, j]) + j + 1
        for run in np.split(weighing, np.flatnonzero(np.diff(weighing) > 1) + 1):
            if len(run) == 1:
                feeds.append((int(run[0]), float(a[run[0], j])))
            elif len(run) > 1:
                lo, hi = int(run[0]), int(run[-1]) + 1
                feeds.append((slice(lo, hi), a[lo:hi, j].reshape(-1, 1).copy()))
        columns.append((c, tuple(feeds)))
    by_column = any(np.count_nonzero(a[j + 1 :, j]) > 1 for j in range(len(a)))
    return Stages(rows, tuple(columns) if by_column else None)


def rk_stages(
    fun: Callable[[np.ndarray, float], np.ndarray],
    x: np.ndarray,
    t: float,
    h: float,
    stages: Stages,
    k: np.ndarray,
    k0: np.ndarray | None = None,
) -> np.ndarray:
    """Fill ``k`` (shape ``(s, dim)``) with the stage derivatives of an explicit RK step.

    Stage ``i`` is ``f(x_i, t + c[i] h)`` with ``x_i = x + h * sum_j a[i, j] k[j]`` and
    ``stages`` from :func:`stages_of`. If ``k0`` is given it is used as the first stage
    (first-same-as-last methods) without an evaluation.

    Each ``x_i`` is summed from ``x`` with its terms ``(h a_ij) k_j`` one at a time, in
    the order of ``j``. Where every stage is weighed by at most one other, ``x_i`` is
    summed when stage ``i`` comes. Otherwise (Dormand-Prince) each ``k_j``, once
    evaluated, is added into all the later ``x_i`` that weigh it with one numpy product
    and one add per run of them, since on small systems a numpy call costs more than its
    arithmetic: the same sums in the same order, so the same to the last bit.
    """
    if stages.columns is None:
        for i, (c, row) in enumerate(stages.rows):
            if i == 0 and k0 is not None:
                k[0] = k0
                continue
            xi = x
            for j, a_ij in row:
                xi = xi + (h * a_ij) * k[j]
            k[i] = fun(xi, t + c * h)
        return k
    xs = np.empty_like(k)  # the x_i, summed as the stages become known
    xs[:] = x
    for j, (c, feeds) in enumerate(stages.columns):
        if j == 0 and k0 is not None:
            k[0] = k0
        else:
            k[j] = fun(xs[j], t + c * h)
        for later, a in feeds:
            rows = xs[later]  # added in place (``xs[later] += ...`` would copy them back)
            rows += (h * a) * k[j]
    return k


def stability_polynomial(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Coefficients ``gamma_k``, ``k = 0..s``, of the stability function of an explicit
    tableau (``a`` strictly lower triangular ``(s, s)``, weights ``b`` ``(s,)``):
    ``R(z) = 1 + z b^T (I - z a)^-1 1 = sum_k gamma_k z^k`` with ``gamma_0 = 1`` and
    ``gamma_k = b^T a^(k-1) 1`` (``a`` is nilpotent, so the series ends at ``z^s``).
    One step on ``y' = lambda y`` multiplies ``y`` by ``R(lambda h)``."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    gamma, ones = [1.0], np.ones(len(b))
    for _ in range(len(b)):
        gamma.append(float(b @ ones))
        ones = a @ ones
    return np.array(gamma)


def polynomial_step_matrix(gamma: np.ndarray) -> StepMatrix:
    """The step matrix ``R(Z)`` of a method with stability polynomial ``gamma`` on the
    linear test system: ``Z = [[0, 1], [-a, -b]]`` is ``h`` times its right-hand side on
    ``(q, h v)``."""
    coefficients = tuple(float(g) for g in gamma)

    def step(a: float, b: float) -> np.ndarray:
        z = np.array([[0.0, 1.0], [-a, -b]])
        m, power = np.zeros((2, 2)), np.eye(2)
        for g in coefficients:
            m += g * power
            power = power @ z
        return m

    return step


def _first_crossing(f: Polynomial, candidates: np.ndarray) -> float:
    """The smallest positive real candidate root past which ``f`` is positive, or inf."""
    real = np.sort(
        candidates.real[(np.abs(candidates.imag) <= 1e-9 * np.abs(candidates)) & (candidates.real > 0)]
    )
    for r in real:
        if f(r * (1 + 1e-7)) > 0:
            return float(r)
    return float("inf")


def tableau_stability(a: np.ndarray, b: np.ndarray, order: int) -> Stability:
    """The stability data of an explicit tableau of the given order, from ``R(z)``.

    ``imaginary``: the first ``y > 0`` where ``|R(i y)|^2 - 1`` turns positive (``0.0``
    when it is positive for small ``y``). By the order conditions ``R(z) = e^z +
    O(z^(order+1))``, so that polynomial in ``y`` has no terms of degree up to ``order``;
    those coefficients are the tableau's round-off and are dropped before its roots are
    taken. ``real``: the first ``x > 0`` where ``|R(-x)|`` exceeds 1, a root of
    ``R(-x) - 1`` (divided by ``x``) or of ``R(-x) + 1``.
    """
    gamma = stability_polynomial(a, b)
    k = np.arange(len(gamma))
    on_imaginary = Polynomial(gamma * (1j) ** k)
    f = Polynomial(on_imaginary.coef.real) ** 2 + Polynomial(on_imaginary.coef.imag) ** 2 - 1
    coef = f.coef.copy()
    coef[: order + 1] = 0.0
    low = int(np.flatnonzero(coef)[0])
    if coef[low] > 0:
        imaginary = 0.0
    else:
        imaginary = _first_crossing(Polynomial(coef), Polynomial(coef[low:]).roots())
    on_real = Polynomial(gamma * (-1.0) ** k)
    grows = Polynomial((on_real**2 - 1).coef)
    candidates = np.concatenate([Polynomial(on_real.coef[1:]).roots(), (on_real + 1).roots()])
    real = _first_crossing(grows, candidates)
    return Stability(imaginary=imaginary, real=real, step_matrix=polynomial_step_matrix(gamma))


class ExplicitRungeKutta(Solver):
    """A fixed-step explicit Runge-Kutta method given by its tableau.

    Subclasses set ``A`` (``(s, s)``, strictly lower triangular), ``B`` (``(s,)``) and
    ``facts`` (the order, ``s`` evaluations per step, and the stability the tableau
    gives, :func:`tableau_stability`); ``C`` is derived as the row sums of ``A``.
    """

    A: np.ndarray
    B: np.ndarray

    @classmethod
    def nodes(cls) -> np.ndarray:
        """The tableau's ``C``: row sums of ``A``."""
        return cls.A.sum(axis=1)

    def __init__(self, system: System) -> None:
        super().__init__(system)
        self._stages = stages_of(self.A)
        self._k = np.empty((len(self.B), system.dim))

    def step(self, dt: float) -> float:
        x, t = self.system.get_state(), self.system.get_time()
        k = rk_stages(self.fun, x, t, dt, self._stages, self._k)
        self.system.set_state(x + dt * (self.B @ k), t + dt)
        return dt


class Euler(ExplicitRungeKutta):
    """Explicit Euler, ``x' = x + h f(x, t)``: the lecture's first method, order 1."""

    name = "euler"
    A = np.array([[0.0]])
    B = np.array([1.0])
    facts = MethodFacts(
        order=1, evaluations_per_step=1, symplectic=False, stability=tableau_stability(A, B, order=1)
    )


class Midpoint(ExplicitRungeKutta):
    """The lecture's midpoint method: an Euler half step, then the midpoint slope; order 2."""

    name = "midpoint"
    A = np.array([[0.0, 0.0], [0.5, 0.0]])
    B = np.array([0.0, 1.0])
    facts = MethodFacts(
        order=2, evaluations_per_step=2, symplectic=False, stability=tableau_stability(A, B, order=2)
    )


class Heun(ExplicitRungeKutta):
    """Heun's method (explicit trapezoid): average of the slopes at both ends; order 2."""

    name = "heun"
    A = np.array([[0.0, 0.0], [1.0, 0.0]])
    B = np.array([0.5, 0.5])
    facts = MethodFacts(
        order=2, evaluations_per_step=2, symplectic=False, stability=tableau_stability(A, B, order=2)
    )


class RK4(ExplicitRungeKutta):
    """The classical fourth-order Runge-Kutta method."""

    name = "rk4"
    A = np.array(
        [
            [0.0, 0.0, 0.0, 0.0],
            [0.5, 0.0, 0.0, 0.0],
            [0.0, 0.5, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ]
    )
    B = np.array([1.0, 2.0, 2.0, 1.0]) / 6.0
    facts = MethodFacts(
        order=4, evaluations_per_step=4, symplectic=False, stability=tableau_stability(A, B, order=4)
    )


class DormandPrince54(Solver):
    """Dormand-Prince 5(4) with error control: the lecture's "do use adaptive step size".

    The fifth-order solution is propagated; the embedded fourth-order one estimates the
    local error. A step is accepted when the RMS norm of
    ``err / (atol + rtol * max(|x|, |x_new|))`` is at most 1; the next step is scaled by
    ``safety * norm**(-1/5)``, bounded to ``[min_factor, max_factor]`` (no growth right
    after a rejection). The last stage is the first of the next step (FSAL), so an
    accepted step costs six evaluations. The first step is chosen from the derivative's
    size (Hairer, Norsett & Wanner, Solving ODEs I, II.4). Its facts: order 5, six
    evaluations per accepted step, and the stability of its fifth-order step (the six
    stages before the FSAL one), which matters only to fixed steps.
    """

    name = "dopri5"
    error_order = 4
    adaptive = True
    safety = 0.9
    min_factor = 0.2
    max_factor = 10.0
    A = np.array(
        [
            [0, 0, 0, 0, 0, 0, 0],
            [1 / 5, 0, 0, 0, 0, 0, 0],
            [3 / 40, 9 / 40, 0, 0, 0, 0, 0],
            [44 / 45, -56 / 15, 32 / 9, 0, 0, 0, 0],
            [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0, 0, 0],
            [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0, 0],
            [35 / 384, 0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0],
        ]
    )
    B = np.array([35 / 384, 0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0])
    # B minus the embedded fourth-order weights: the local error estimate per unit h.
    E = np.array([71 / 57600, 0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40])
    facts = MethodFacts(
        order=5,
        evaluations_per_step=6,
        symplectic=False,
        stability=tableau_stability(A[:6, :6], B[:6], order=5),
    )
    # The continuous extension of order 4 (Hairer, Norsett & Wanner, II.6, "dense output
    # of DOPRI5"): the last term's weights on the seven stages.
    D = np.array(
        [
            -12715105075 / 11282082432,
            0,
            87487479700 / 32700410799,
            -10690763975 / 1880347072,
            701980252875 / 199316789632,
            -1453857185 / 822651844,
            69997945 / 29380423,
        ]
    )

    def dense(self) -> DenseStep:
        """The last accepted step's continuous extension: the state at any time within it
        (order 4, exact at both ends, matching the derivative there)."""
        if self._step is None:
            raise ValueError("dopri5: no step taken yet")
        t0, h, x0, x1, k = self._step
        return DenseStep(t0, h, x0, x1, h * k[0], h * k[6], h * (self.D @ k))

    def __init__(self, system: System, *, rtol: float = 1e-6, atol: float = 1e-6) -> None:
        super().__init__(system)
        if rtol <= 0 or atol <= 0:
            raise ValueError(f"dopri5: rtol={rtol} and atol={atol} must both be positive")
        self.rtol, self.atol = rtol, atol
        self._stages = stages_of(self.A[:6])
        self._k = np.empty((len(self.B), system.dim))
        self._f0: np.ndarray | None = None
        self._x_end: np.ndarray | None = None  # the state the last step ended at
        self._h: float | None = None
        self._step: tuple[float, float, np.ndarray, np.ndarray, np.ndarray] | None = None
        self.n_rejected = 0

    def _initial_step(self, x: np.ndarray, t: float, f0: np.ndarray, h_max: float) -> float:
        scale = self.atol + np.abs(x) * self.rtol
        d0 = _rms(x / scale)
        d1 = _rms(f0 / scale)
        if not (math.isfinite(d0) and math.isfinite(d1)):
            raise FloatingPointError(f"dopri5: non-finite state or derivative at t={t:.6g}")
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, h_max)
        f1 = self.fun(x + h0 * f0, t + h0)
        d2 = _rms((f1 - f0) / scale) / h0
        if d1 <= 1e-15 and d2 <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1 / (self.error_order + 1))
        return min(100 * h0, h1, h_max)

    def step(self, dt: float) -> float:
        """Take one accepted step of at most ``dt`` seconds; return its length.

        Each try fills the stage derivatives ``k`` (7, dim) in place: the six stages of
        the fifth-order step, the first of them the previous step's last, and the
        derivative at the new state, which is the error estimate's seventh stage and, if
        the step is accepted, the next step's first, unless something between the steps
        (a collision, an emitter) changed the state: then the derivative is evaluated
        afresh at the state as it is.
        """
        x, t = self.system.get_state(), self.system.get_time()
        if self._f0 is None or self._x_end is None or not np.array_equal(x, self._x_end):
            self._f0 = self.fun(x, t)
        if self._h is None:
            self._h = self._initial_step(x, t, self._f0, dt)
        if not 0.0 < self._h < math.inf:
            raise SolverFailed(f"dopri5: no usable step size at t={t:.6g}")
        h = min(self._h, dt)
        k = self._k
        abs_x = np.abs(x)
        rejected = False
        while True:
            rk_stages(self.fun, x, t, h, self._stages, k[:6], self._f0)
            x_new = x + h * (self.B[:6] @ k[:6])
            f_new = self.fun(x_new, t + h)
            k[6] = f_new
            scale = self.atol + np.maximum(abs_x, np.abs(x_new)) * self.rtol
            err = _rms(h * (self.E @ k) / scale)
            if err <= 1.0:
                factor = self.max_factor if err == 0 else self.safety * err**-0.2
                factor = min(self.max_factor, factor)
                if rejected:
                    factor = min(1.0, factor)
                self._h = h * factor
                break
            if not np.isfinite(err):
                factor = self.min_factor
            else:
                factor = max(self.min_factor, self.safety * err**-0.2)
            h *= factor
            rejected = True
            self.n_rejected += 1
            if h < 1e-14 * max(1.0, abs(t)):
                if not np.isfinite(err):
                    raise FloatingPointError(f"dopri5: non-finite state or derivative at t={t:.6g}")
                raise SolverFailed(
                    f"dopri5: step size underflow at t={t:.6g}: the error "
                    "estimate stays above the tolerance at every step size"
                )
        self._f0 = f_new  # a new array (System.derivative's contract): kept, not copied
        self._x_end = x_new
        self._step = (t, h, x, x_new, k.copy())
        self.system.set_state(x_new, t + h)
        return h


@dataclass(frozen=True)
class DenseStep:
    """One accepted step's continuous extension (Hairer's ``CONTD5`` form): the state at
    ``t0 + theta h`` for ``0 <= theta <= 1`` is

    ``x0 + theta (r2 + (1 - theta) (r3 + theta (r4 + (1 - theta) r5)))``

    with ``r2 = x1 - x0``, ``r3 = h k1 - r2``, ``r4 = r2 - h k7 - r3`` and ``r5 = h D . k``.
    t0, h : s;  x0, x1, hk1, hk7, hdk : ndarray, shape (dim,)
    """

    t0: float
    h: float
    x0: np.ndarray
    x1: np.ndarray
    hk1: np.ndarray
    hk7: np.ndarray
    hdk: np.ndarray

    def __call__(self, t: float, index: np.ndarray | None = None) -> np.ndarray:
        """The state at time ``t`` (s) within the step, shape (dim,); or only its
        components ``index``."""
        theta = (t - self.t0) / self.h
        if index is None:
            x0, x1, hk1, hk7, hdk = self.x0, self.x1, self.hk1, self.hk7, self.hdk
        else:
            x0, x1, hk1, hk7, hdk = (a[index] for a in (self.x0, self.x1, self.hk1, self.hk7, self.hdk))
        r2 = x1 - x0
        r3 = hk1 - r2
        r4 = r2 - hk7 - r3
        return x0 + theta * (r2 + (1 - theta) * (r3 + theta * (r4 + (1 - theta) * hdk)))


def _rms(a: np.ndarray) -> float:
    """The root mean square of ``a`` (shape ``(dim,)``): the sum ``np.mean`` takes (numpy's
    pairwise one), so the same number to the last bit, without ``np.mean``'s overhead."""
    return math.sqrt(np.add.reduce(np.square(a)) / a.size)
