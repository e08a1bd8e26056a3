"""Methods that step positions and velocities separately (second-order systems only).

Each needs ``system.acceleration(q, v, t)`` and the state layout ``x = [q, v]``.
"""

from __future__ import annotations

import numpy as np

from reference_impl.solvers.base import Solver


class _SplitSolver(Solver):
    needs_second_order = True

    def _split(self) -> tuple[np.ndarray, np.ndarray, float]:
        x, t = self.system.get_state(), self.system.get_time()
        n = self.system.half  # type: ignore[attr-defined]
        return x[:n], x[n:], t

    def _store(self, q: np.ndarray, v: np.ndarray, t: float) -> None:
        self.system.set_state(np.concatenate([q, v]), t)


class SymplecticEuler(_SplitSolver):
    """Semi-implicit (symplectic) Euler: ``v' = v + a(q, v) h``, then ``q' = q + v' h``.

    Order 1; on an undamped oscillator its energy error stays bounded for
    ``omega h < 2``.
    """

    name = "symplectic-euler"
    order = 1

    def step(self, dt: float) -> float:
        q, v, t = self._split()
        v_new = v + dt * self.accel(q, v, t)
        self._store(q + dt * v_new, v_new, t + dt)
        return dt


class VelocityVerlet(_SplitSolver):
    """Velocity Verlet (kick-drift-kick), order 2 and symplectic for ``a = a(q)``.

    The acceleration at the end of a step is reused as the start of the next, so a step
    costs one evaluation after the first. For velocity-dependent forces the closing
    kick uses the half-step velocity, which keeps it explicit.
    """

    name = "verlet"
    order = 2

    def __init__(self, system) -> None:
        super().__init__(system)
        self._last: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None

    def step(self, dt: float) -> float:
        q, v, t = self._split()
        a = self._cached_accel(q, v, t)
        v_half = v + 0.5 * dt * a
        q_new = q + dt * v_half
        a_new = self.accel(q_new, v_half, t + dt)
        v_new = v_half + 0.5 * dt * a_new
        self._store(q_new, v_new, t + dt)
        self._last = (t + dt, q_new, v_new, a_new)
        return dt

    def _cached_accel(self, q: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
        """Reuse the last step's closing acceleration unless the state changed since."""
        if self._last is not None:
            t_last, q_last, v_last, a_last = self._last
            if t_last == t and np.array_equal(q_last, q) and np.array_equal(v_last, v):
                return a_last
        return self.accel(q, v, t)


class LectureUpdate(_SplitSolver):
    """The lecture's update: ``v' = v + a h``, ``p' = p + (v + v') h / 2``.

    With ``a`` evaluated once at the start of the step this equals
    ``p' = p + v h + a h^2 / 2``: exact under constant acceleration, and a first-order
    method in general (the velocity update is explicit Euler).
    """

    name = "lecture"
    order = 1

    def step(self, dt: float) -> float:
        q, v, t = self._split()
        v_new = v + dt * self.accel(q, v, t)
        self._store(q + 0.5 * dt * (v + v_new), v_new, t + dt)
        return dt
