"""Implicit (backward) Euler with Newton iterations."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from truestep.reference_impl.solvers.base import Solver
from truestep.reference_impl.solvers.facts import MethodFacts, Stability
from truestep.reference_impl.system import System

DENSE_UP_TO = 300
"""Systems up to this dimension factorise a dense Newton matrix even when the Jacobian
comes sparse: for small systems dense LU is far cheaper than sparse bookkeeping."""


def implicit_euler_step(a: float, b: float) -> np.ndarray:
    """Backward Euler on the test system: ``(I - Z)^-1`` with ``Z = [[0, 1], [-a, -b]]``."""
    return np.array([[1.0 + b, 1.0], [-a, 1.0]]) / (1.0 + a + b)


class ImplicitEuler(Solver):
    """Backward Euler: solve ``y = x + h f(y, t + h)`` for ``y`` by Newton's method.

    The Newton matrix is ``I - h J`` with ``J = df/dx`` from ``system.jacobian`` (dense
    or scipy-sparse) where the system gives one, and from forward finite differences
    (``dim`` extra evaluations) otherwise. As in Radau codes, the factorised matrix is
    kept from step to step while Newton converges fast with it (each update at most
    half the previous one) and rebuilt at the current iterate when it does not, or when
    the step size changes. Iterations stop when the update is below ``tol`` in the RMS
    norm scaled by ``1 + |y|``. Order 1, A-stable and L-stable: on an undamped
    oscillator it loses energy at every step size. Its evaluations per step vary with
    the Newton iterations (the solver counts them).
    """

    name = "implicit-euler"
    facts = MethodFacts(order=1, evaluations_per_step=None, symplectic=False,
                        stability=Stability(imaginary=float("inf"), real=float("inf"),
                                            a_stable=True, step_matrix=implicit_euler_step))

    def __init__(self, system: System, *, tol: float = 1e-10, max_iter: int = 20) -> None:
        super().__init__(system)
        self.tol, self.max_iter = tol, max_iter
        self.n_jac = 0
        self._solve: Callable[[np.ndarray], np.ndarray] | None = None
        self._solve_dt: float | None = None

    def _jacobian(self, y: np.ndarray, t: float, fy: np.ndarray):
        self.n_jac += 1
        jac = self.system.jacobian(y, t)
        if jac is not None:
            return jac
        eps = np.sqrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(y))
        jac = np.empty((y.size, y.size))
        for j in range(y.size):
            yj = y.copy()
            yj[j] += eps[j]
            jac[:, j] = (self.fun(yj, t) - fy) / eps[j]
        return jac

    def _factorise(self, y: np.ndarray, t: float, fy: np.ndarray, dt: float) -> None:
        jac = self._jacobian(y, t, fy)
        if sp.issparse(jac) and y.size > DENSE_UP_TO:
            self._solve = spla.splu(sp.csc_matrix(sp.identity(y.size) - dt * jac)).solve
        else:
            dense = jac.toarray() if sp.issparse(jac) else jac
            lu_piv = la.lu_factor(np.eye(y.size) - dt * dense)
            self._solve = lambda b: la.lu_solve(lu_piv, b)
        self._solve_dt = dt

    def step(self, dt: float) -> float:
        x, t = self.system.get_state(), self.system.get_time()
        t1 = t + dt
        y = x + dt * self.fun(x, t)
        fy = self.fun(y, t1)
        if not (np.isfinite(y).all() and np.isfinite(fy).all()):
            raise FloatingPointError(f"implicit-euler: non-finite state or derivative at t={t:.6g}")
        if self._solve is None or self._solve_dt != dt:
            self._factorise(y, t1, fy, dt)
        rebuilt = False  # at an iterate of this step (a matrix of the predictor does not count)
        prev = np.inf
        it = 0
        while True:
            residual = y - x - dt * fy
            if not np.isfinite(residual).all():
                raise FloatingPointError(f"implicit-euler: non-finite state or derivative at "
                                         f"t={t:.6g}")
            delta = self._solve(-residual)
            y = y + delta
            fy = self.fun(y, t1)
            it += 1
            size = float(np.sqrt(np.mean((delta / (1.0 + np.abs(y))) ** 2)))
            if size < self.tol:
                break
            if not np.isfinite(size) or it >= self.max_iter:
                raise FloatingPointError(f"implicit-euler: Newton failed at t={t:.6g}")
            if size > 0.5 * prev and not rebuilt:
                self._factorise(y, t1, fy, dt)
                rebuilt = True
            prev = size
        self.system.set_state(y, t1)
        return dt
