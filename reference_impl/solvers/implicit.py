"""Implicit (backward) Euler with Newton iterations."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from truestep.reference_impl.solvers.base import Solver, SolverFailed
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
    norm scaled by ``1 + |y|``.

    A step whose fast Newton iteration does not converge (large steps on stiff,
    nonlinear scenes: the explicit predictor lands far away) is solved again from the
    current state by damped Newton: a fresh Jacobian at every iterate and a backtracking
    line search on the residual ``|y - x - h f(y)|``, which converges wherever the
    step's equation has a solution the iteration can reach. Only when that fails too
    does the step raise :class:`~truestep.reference_impl.solvers.base.SolverFailed`
    (status ``solver-failed``, never ``unstable``).

    Order 1, A-stable and L-stable: on an undamped oscillator it loses energy at every
    step size. Its evaluations per step vary with the Newton iterations (the solver
    counts them).
    """

    name = "implicit-euler"
    facts = MethodFacts(
        order=1,
        evaluations_per_step=None,
        symplectic=False,
        stability=Stability(
            imaginary=float("inf"), real=float("inf"), a_stable=True, step_matrix=implicit_euler_step
        ),
    )

    def __init__(
        self, system: System, *, tol: float = 1e-10, max_iter: int = 20, max_damped_iter: int = 200
    ) -> None:
        super().__init__(system)
        self.tol, self.max_iter, self.max_damped_iter = tol, max_iter, max_damped_iter
        self.n_jac = 0
        self.damped_steps = 0
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

    def _factorise(
        self, y: np.ndarray, t: float, fy: np.ndarray, dt: float
    ) -> Callable[[np.ndarray], np.ndarray]:
        """Factorise ``I - dt J`` at ``y``; keep and return its solve."""
        import scipy.linalg as la  # here, not at import: scipy's linear algebra costs every
        import scipy.sparse as sp  # process that imports truestep a tenth of a second, and
        import scipy.sparse.linalg as spla  # only an implicit step needs it

        jac = self._jacobian(y, t, fy)
        solve: Callable[[np.ndarray], np.ndarray]
        if sp.issparse(jac) and y.size > DENSE_UP_TO:
            solve = spla.splu(sp.csc_matrix(sp.identity(y.size) - dt * jac)).solve
        else:
            dense = jac.toarray() if sp.issparse(jac) else jac
            lu, piv = la.lu_factor(np.eye(y.size) - dt * dense)
            (getrs,) = la.get_lapack_funcs(("getrs",), (lu, y))

            def solve(b: np.ndarray) -> np.ndarray:
                # scipy's lu_solve, less its per-call checks and LAPACK lookup (a finite
                # right-hand side is checked by every caller): the same LAPACK getrs
                x, info = getrs(lu, piv, b)
                if info != 0:
                    raise ValueError(f"implicit-euler: illegal value in argument {-info} of LAPACK getrs")
                return x

        self._solve, self._solve_dt = solve, dt
        return solve

    def _size(self, delta: np.ndarray, y: np.ndarray) -> float:
        """The RMS of ``delta / (1 + |y|)``: ``np.mean``'s own pairwise sum and division,
        the same number to the last bit, without its per-call overhead."""
        scaled = delta / (1.0 + np.abs(y))
        return math.sqrt(np.add.reduce(scaled * scaled) / scaled.size)

    def _fast_newton(self, x: np.ndarray, fx: np.ndarray, t: float, dt: float) -> np.ndarray | None:
        """Newton from the explicit predictor ``x + h f(x)`` with the kept matrix (rebuilt
        once at an iterate when it converges slowly); ``None`` when it does not converge."""
        t1 = t + dt
        y = x + dt * fx
        fy = self.fun(y, t1)
        if not (np.isfinite(y).all() and np.isfinite(fy).all()):
            return None
        solve = self._solve
        if solve is None or self._solve_dt != dt:
            solve = self._factorise(y, t1, fy, dt)
        rebuilt = False  # at an iterate of this step (a matrix of the predictor does not count)
        prev = np.inf
        for _ in range(self.max_iter):
            residual = y - x - dt * fy
            if not np.isfinite(residual).all():
                return None
            delta = solve(-residual)
            y = y + delta
            fy = self.fun(y, t1)
            size = self._size(delta, y)
            if size < self.tol:
                return y if np.isfinite(fy).all() else None
            if not np.isfinite(size):
                return None
            if size > 0.5 * prev and not rebuilt:
                solve = self._factorise(y, t1, fy, dt)
                rebuilt = True
            prev = size
        return None

    def _damped_newton(self, x: np.ndarray, t: float, dt: float) -> np.ndarray:
        """Newton from the current state with a fresh Jacobian at every iterate and a
        backtracking line search on the residual norm; raises
        :class:`~truestep.reference_impl.solvers.base.SolverFailed` when it finds no
        solution."""
        t1 = t + dt
        y = x.copy()
        fy = self.fun(y, t1)
        residual = y - x - dt * fy
        norm = float(np.linalg.norm(residual))
        for _ in range(self.max_damped_iter):
            if not np.isfinite(norm):
                break
            delta = self._factorise(y, t1, fy, dt)(-residual)
            if self._size(delta, y) < self.tol:  # converged: the residual is round-off
                y = y + delta
                if np.isfinite(self.fun(y, t1)).all():
                    self._solve_dt = None
                    return y
                break
            lam = 1.0
            while lam >= 1e-6:
                trial = y + lam * delta
                f_trial = self.fun(trial, t1)
                r_trial = trial - x - dt * f_trial
                n_trial = float(np.linalg.norm(r_trial))
                if np.isfinite(n_trial) and n_trial <= (1.0 - 1e-4 * lam) * norm:
                    break
                lam *= 0.5
            else:
                break
            y, fy, residual, norm = trial, f_trial, r_trial, n_trial
            if self._size(lam * delta, y) < self.tol:
                self._solve_dt = None  # the matrix of this iterate is not the fast path's
                return y
        self._solve_dt = None
        raise SolverFailed(
            f"implicit-euler: Newton found no solution of the step's equation "
            f"at t = {t:.6g} s with h = {dt:.4g} s (residual {norm:.3g}, damped "
            "and with a fresh Jacobian at every iterate)"
        )

    def step(self, dt: float) -> float:
        x, t = self.system.get_state(), self.system.get_time()
        fx = self.fun(x, t)
        if not np.isfinite(fx).all():
            raise FloatingPointError(f"implicit-euler: non-finite state or derivative at t={t:.6g}")
        y = self._fast_newton(x, fx, t, dt)
        if y is None:
            self.damped_steps += 1
            y = self._damped_newton(x, t, dt)
        self.system.set_state(y, t + dt)
        return dt
