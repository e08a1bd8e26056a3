"""Methods that step positions and velocities separately (second-order systems only).

Each needs ``system.acceleration(q, v, t)`` and the state layout ``x = [q, v]``. Their
step matrices on the linear test system (:mod:`truestep.reference_impl.solvers.facts`)
follow from their update formulas with ``h a = -a q - b (h v)`` in the units of
``(q, h v)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from truestep.reference_impl.solvers.base import Solver
from truestep.reference_impl.solvers.facts import MethodFacts, Stability


def symplectic_euler_step(a: float, b: float) -> np.ndarray:
    """Symplectic Euler on the test system: ``h v' = -a q + (1 - b) h v``, ``q' = q + h v'``."""
    return np.array([[1.0 - a, 1.0 - b], [-a, 1.0 - b]])


def verlet_step(a: float, b: float) -> np.ndarray:
    """Velocity Verlet as :class:`VelocityVerlet` steps it, on ``(q, h v, s)`` with ``s``
    ``h^2`` times the acceleration it reuses (the last closing kick's, read at the
    half-step velocity): ``h v_half = h v + s / 2``, ``q' = q + h v_half``,
    ``s' = -a q' - b h v_half``, ``h v' = h v_half + s' / 2``."""
    half = np.array([0.0, 1.0, 0.5])
    q = np.array([1.0, 0.0, 0.0]) + half
    s = -a * q - b * half
    return np.array([q, half + 0.5 * s, s])


def lecture_step(a: float, b: float) -> np.ndarray:
    """The lecture's update: ``h v' = -a q + (1 - b) h v``, ``q' = q + (h v + h v') / 2``."""
    return np.array([[1.0 - a / 2, 1.0 - b / 2], [-a, 1.0 - b]])


@dataclass(frozen=True)
class Splitting:
    """A splitting method's step as data, as a compiled step runs it
    (:mod:`~truestep.reference_impl.solvers.splitting_kernels`).

    kick : float
        The opening kick ``v' = v + kick h a(q, v, t)``. ``1``: the whole kick, at the
        step's start. ``1/2``: half a kick, the drift, then the other half at the new
        positions and the half-step velocities, whose acceleration the next step reuses.
    old, new : float
        The drift ``q' = q + h (old v + new v')`` by the velocities before and after the
        (opening) kick.
    """

    kick: float
    old: float
    new: float


class _SplitSolver(Solver):
    needs_second_order = True
    splitting: Splitting

    def _split(self) -> tuple[np.ndarray, np.ndarray, float]:
        x, t = self.system.get_state(), self.system.get_time()
        n = self.system.half  # type: ignore[attr-defined]
        return x[:n], x[n:], t

    def _store(self, q: np.ndarray, v: np.ndarray, t: float) -> None:
        self.system.set_state(np.concatenate([q, v]), t)


class SymplecticEuler(_SplitSolver):
    """Semi-implicit (symplectic) Euler: ``v' = v + a(q, v) h``, then ``q' = q + v' h``.

    Order 1; on an undamped oscillator its energy error stays bounded for
    ``omega h < 2`` (the trace of its step matrix, ``2 - (omega h)^2``, stays above -2);
    a damper, read at the step's start, decays for ``c h <= 2``.
    """

    name = "symplectic-euler"
    facts = MethodFacts(
        order=1,
        evaluations_per_step=1,
        symplectic=True,
        stability=Stability(imaginary=2.0, real=2.0, step_matrix=symplectic_euler_step),
    )
    splitting = Splitting(kick=1.0, old=0.0, new=1.0)

    def step(self, dt: float) -> float:
        q, v, t = self._split()
        v_new = v + dt * self.accel(q, v, t)
        self._store(q + dt * v_new, v_new, t + dt)
        return dt


class VelocityVerlet(_SplitSolver):
    """Velocity Verlet (kick-drift-kick), order 2 and symplectic for ``a = a(q)``.

    The acceleration at the end of a step is reused as the start of the next, so a step
    costs one evaluation after the first. For velocity-dependent forces the closing
    kick uses the half-step velocity, which keeps it explicit and makes it first order;
    the reused acceleration carries that half-step velocity into the next step, so a
    damper decays only for ``c h <= 2`` (:func:`verlet_step`). Undamped: stable for
    ``omega h < 2`` (trace ``2 - (omega h)^2``, determinant 1).
    """

    name = "verlet"
    facts = MethodFacts(
        order=2,
        evaluations_per_step=1,
        symplectic=True,
        velocity_order=1,
        stability=Stability(imaginary=2.0, real=2.0, step_matrix=verlet_step),
    )
    splitting = Splitting(kick=0.5, old=0.0, new=1.0)

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
    method in general (the velocity update is explicit Euler). On an undamped
    oscillator the determinant of its step matrix is ``1 + (omega h)^2 / 2``: unstable
    at every step.
    """

    name = "lecture"
    facts = MethodFacts(
        order=1,
        evaluations_per_step=1,
        symplectic=False,
        exact_constant_acceleration=True,
        stability=Stability(imaginary=0.0, real=2.0, step_matrix=lecture_step),
    )
    splitting = Splitting(kick=1.0, old=0.5, new=0.5)

    def step(self, dt: float) -> float:
        q, v, t = self._split()
        v_new = v + dt * self.accel(q, v, t)
        self._store(q + 0.5 * dt * (v + v_new), v_new, t + dt)
        return dt
