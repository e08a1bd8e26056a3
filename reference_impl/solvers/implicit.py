"""Implicit (backward) Euler with Newton iterations."""

from __future__ import annotations

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from reference_impl.solvers.base import Solver
from reference_impl.system import System


class ImplicitEuler(Solver):
    """Backward Euler: solve ``y = x + h f(y, t + h)`` for ``y`` by Newton's method.

    The Newton matrix is ``I - h J`` with ``J = df/dx`` from ``system.jacobian`` (dense
    or scipy-sparse) where the system gives one, and from forward finite differences
    (``dim`` extra evaluations) otherwise. ``J`` is evaluated once per step at the
    Euler predictor (a simplified Newton method); iterations stop when the update is
    below ``tol`` in the RMS norm scaled by ``1 + |y|``. Order 1, A-stable and L-stable:
    on an undamped oscillator it loses energy at every step size.
    """

    name = "implicit-euler"
    order = 1

    def __init__(
        self, system: System, *, tol: float = 1e-10, max_iter: int = 20
    ) -> None:
        super().__init__(system)
        self.tol, self.max_iter = tol, max_iter
        self.n_jac = 0

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

    def step(self, dt: float) -> float:
        x, t = self.system.get_state(), self.system.get_time()
        t1 = t + dt
        f0 = self.fun(x, t)
        y = x + dt * f0
        fy = self.fun(y, t1)
        jac = self._jacobian(y, t1, fy)
        if sp.issparse(jac):
            lu = spla.splu(sp.csc_matrix(sp.identity(x.size) - dt * jac))
            solve = lu.solve
        else:
            lu_piv = la.lu_factor(np.eye(x.size) - dt * jac)

            def solve(b: np.ndarray) -> np.ndarray:
                return la.lu_solve(lu_piv, b)

        for _ in range(self.max_iter):
            residual = y - x - dt * fy
            delta = solve(-residual)
            y = y + delta
            fy = self.fun(y, t1)
            if np.sqrt(np.mean((delta / (1.0 + np.abs(y))) ** 2)) < self.tol:
                break
        else:
            if not np.all(np.isfinite(y)):
                raise FloatingPointError(f"implicit-euler: Newton diverged at t={t:.6g}")
        self.system.set_state(y, t1)
        return dt
