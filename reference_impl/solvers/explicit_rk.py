"""Explicit Runge-Kutta methods as data (Butcher tableaux) and one stepper.

Euler, midpoint, Heun and classical RK4 are fixed-step tableaux; Dormand-Prince 5(4)
adds an embedded error estimate and a step-size controller. Every method is stepped by
:func:`rk_stages`, so a new method is a new tableau, not new code.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from truestep.reference_impl.solvers.base import Solver
from truestep.reference_impl.system import System

Stages = tuple[tuple[float, tuple[tuple[int, float], ...]], ...]
"""A tableau's stages as :func:`stages_of` gives them: ``(c_i, ((j, a_ij), ...))``."""


def stages_of(a: np.ndarray) -> Stages:
    """The stages of a strictly lower triangular ``a`` (s, s): each node ``c_i`` (the row
    sum) with only the non-zero ``a_ij`` (most of a tableau is zero), as plain floats."""
    return tuple(
        (float(row.sum()), tuple((int(j), float(row[j])) for j in np.flatnonzero(row[:i])))
        for i, row in enumerate(np.asarray(a, float))
    )


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

    Stage ``i`` is ``f(x + h * sum_j a[i, j] k[j], t + c[i] h)`` with ``stages`` from
    :func:`stages_of`. If ``k0`` is given it is used as the first stage
    (first-same-as-last methods) without an evaluation.
    """
    for i, (c_i, row) in enumerate(stages):
        if i == 0 and k0 is not None:
            k[0] = k0
            continue
        xi = x
        for j, a_ij in row:
            xi = xi + (h * a_ij) * k[j]
        k[i] = fun(xi, t + c_i * h)
    return k


class ExplicitRungeKutta(Solver):
    """A fixed-step explicit Runge-Kutta method given by its tableau.

    Subclasses set ``A`` (``(s, s)``, strictly lower triangular), ``B`` (``(s,)``) and
    ``order``; ``C`` is derived as the row sums of ``A``.
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
    order = 1
    A = np.array([[0.0]])
    B = np.array([1.0])


class Midpoint(ExplicitRungeKutta):
    """The lecture's midpoint method: an Euler half step, then the midpoint slope; order 2."""

    name = "midpoint"
    order = 2
    A = np.array([[0.0, 0.0], [0.5, 0.0]])
    B = np.array([0.0, 1.0])


class Heun(ExplicitRungeKutta):
    """Heun's method (explicit trapezoid): average of the slopes at both ends; order 2."""

    name = "heun"
    order = 2
    A = np.array([[0.0, 0.0], [1.0, 0.0]])
    B = np.array([0.5, 0.5])


class RK4(ExplicitRungeKutta):
    """The classical fourth-order Runge-Kutta method."""

    name = "rk4"
    order = 4
    A = np.array(
        [
            [0.0, 0.0, 0.0, 0.0],
            [0.5, 0.0, 0.0, 0.0],
            [0.0, 0.5, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ]
    )
    B = np.array([1.0, 2.0, 2.0, 1.0]) / 6.0


class DormandPrince54(Solver):
    """Dormand-Prince 5(4) with error control: the lecture's "do use adaptive step size".

    The fifth-order solution is propagated; the embedded fourth-order one estimates the
    local error. A step is accepted when the RMS norm of
    ``err / (atol + rtol * max(|x|, |x_new|))`` is at most 1; the next step is scaled by
    ``safety * norm**(-1/5)``, bounded to ``[min_factor, max_factor]`` (no growth right
    after a rejection). The last stage is the first of the next step (FSAL), so an
    accepted step costs six evaluations. The first step is chosen from the derivative's
    size (Hairer, Norsett & Wanner, Solving ODEs I, II.4).
    """

    name = "dopri5"
    order = 5
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
    E = np.array(
        [71 / 57600, 0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40]
    )

    def __init__(self, system: System, *, rtol: float = 1e-6, atol: float = 1e-6) -> None:
        super().__init__(system)
        if rtol <= 0 or atol <= 0:
            raise ValueError(f"dopri5: rtol={rtol} and atol={atol} must both be positive")
        self.rtol, self.atol = rtol, atol
        self._stages = stages_of(self.A[:6])
        self._k = np.empty((len(self.B), system.dim))
        self._f0: np.ndarray | None = None
        self._h: float | None = None
        self.n_rejected = 0

    def _initial_step(self, x: np.ndarray, t: float, f0: np.ndarray, h_max: float) -> float:
        scale = self.atol + np.abs(x) * self.rtol
        d0 = _rms(x / scale)
        d1 = _rms(f0 / scale)
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
        """Take one accepted step of at most ``dt`` seconds; return its length."""
        x, t = self.system.get_state(), self.system.get_time()
        if self._f0 is None:
            self._f0 = self.fun(x, t)
        if self._h is None:
            self._h = self._initial_step(x, t, self._f0, dt)
        h = min(self._h, dt)
        rejected = False
        while True:
            k = rk_stages(self.fun, x, t, h, self._stages, self._k[:6], self._f0)
            x_new = x + h * (self.B[:6] @ k[:6])
            self._k[6] = self.fun(x_new, t + h)
            scale = self.atol + np.maximum(np.abs(x), np.abs(x_new)) * self.rtol
            err = _rms(h * (self.E @ self._k) / scale)
            if err <= 1.0:
                factor = self.max_factor if err == 0 else self.safety * err ** -0.2
                factor = min(self.max_factor, factor)
                if rejected:
                    factor = min(1.0, factor)
                self._h = h * factor
                break
            if not np.isfinite(err):
                factor = self.min_factor
            else:
                factor = max(self.min_factor, self.safety * err ** -0.2)
            h *= factor
            rejected = True
            self.n_rejected += 1
            if h < 1e-14 * max(1.0, abs(t)):
                raise FloatingPointError(f"dopri5: step size underflow at t={t:.6g}")
        self._f0 = self._k[6].copy()
        self.system.set_state(x_new, t + h)
        return h


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a))))
