"""Methods that step positions and velocities separately (second-order systems only).

Each needs ``system.acceleration(q, v, t)`` and the state layout ``x = [q, v]``.
"""

from __future__ import annotations

import numpy as np

from truestep.reference_impl.solvers.base import Solver


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
        self._last: tuple[float, bytes, np.ndarray] | None = None

    def step(self, dt: float) -> float:
        x, t = self.system.get_state(), self.system.get_time()
        n = self.system.half  # type: ignore[attr-defined]
        q, v = x[:n], x[n:]
        a = self._cached_accel(x, t)
        v_half = v + 0.5 * dt * a
        q_new = q + dt * v_half
        a_new = self.accel(q_new, v_half, t + dt)
        v_new = v_half + 0.5 * dt * a_new
        x_new = np.concatenate([q_new, v_new])
        self.system.set_state(x_new, t + dt)
        self._last = (t + dt, x_new.tobytes(), a_new)
        return dt

    def _cached_accel(self, x: np.ndarray, t: float) -> np.ndarray:
        """Reuse the last step's closing acceleration unless the state changed since
        (a collision pass between steps may have moved or stopped particles)."""
        if self._last is not None:
            t_last, x_last, a_last = self._last
            if t_last == t and x_last == x.tobytes():
                return a_last
        n = self.system.half  # type: ignore[attr-defined]
        return self.accel(x[:n], x[n:], t)


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
