"""Plain ODE systems of the lecture and the classic test problems, in canonical form."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from truestep.reference_impl import odes_kernels
from truestep.reference_impl.system import SecondOrderSystem, System


class CircleField(System):
    """The lecture's vector field ``x' = (-y, x)``: integral curves are circles.

    State ``(x, y)``, dimensionless. Explicit Euler turns the circle into an outward
    spiral ("the spiral of your choice").
    """

    _J = np.array([[0.0, -1.0], [1.0, 0.0]])

    def derivative(self, x: np.ndarray, t: float) -> np.ndarray:
        return np.array([-x[1], x[0]])

    def jacobian(self, x: np.ndarray, t: float) -> np.ndarray:
        return self._J

    def compiled_derivative(self) -> None:
        """None: a compiled call costs more than this numpy one (as
        ``benchmarks/compiled_derivative.py`` times them): two components, no loop to
        compile away."""
        return None

    def rhs_kernel(self) -> tuple[int, tuple[float, ...]]:
        """The compiled loop's right-hand side (:mod:`~truestep.reference_impl.odes_loop`)."""
        return odes_kernels.CIRCLE, ()

    def energy(self, x: np.ndarray, t: float) -> float:
        """Half the squared radius: conserved along the exact flow."""
        return 0.5 * float(x @ x)


class KeplerProblem(SecondOrderSystem):
    """A point in the plane around a fixed centre of gravitational parameter ``mu``.

    ``q'' = -mu q / |q|^3``; state ``(qx, qy, vx, vy)``. Energy
    ``|v|^2 / 2 - mu / |q|`` and angular momentum ``qx vy - qy vx`` are conserved.
    """

    def __init__(self, x0: np.ndarray, t0: float = 0.0, *, mu: float = 1.0) -> None:
        super().__init__(x0, t0)
        self.mu = mu

    def acceleration(self, q: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
        r2 = float(q @ q)
        return q * (-self.mu / (r2 * math.sqrt(r2)))

    def rhs_kernel(self) -> tuple[int, tuple[float, ...]]:
        """The compiled loop's right-hand side (:mod:`~truestep.reference_impl.odes_loop`)."""
        return odes_kernels.KEPLER, (float(self.mu),)

    def compiled_derivative(self) -> Callable[[np.ndarray, float], np.ndarray]:
        kernel, mu = odes_kernels.kepler, float(self.mu)
        return lambda x, t: kernel(x, t, np.empty(4), mu)

    def jacobian(self, x: np.ndarray, t: float) -> np.ndarray:
        """``d[v, a]/d[q, v]``; ``da/dq = -mu (I / r^3 - 3 q q^T / r^5)``."""
        q = x[:2]
        r2 = float(q @ q)
        r = np.sqrt(r2)
        jac = np.zeros((4, 4))
        jac[:2, 2:] = np.eye(2)
        jac[2:, :2] = -self.mu * (np.eye(2) / r**3 - 3.0 * np.outer(q, q) / (r**3 * r2))
        return jac

    def energy(self, x: np.ndarray, t: float) -> float:
        q, v = x[:2], x[2:]
        return 0.5 * float(v @ v) - self.mu / float(np.sqrt(q @ q))


class Arenstorf(SecondOrderSystem):
    """The restricted three-body problem in the rotating frame (Hairer et al., I.0).

    A light body moves under an Earth of mass ``1 - mu`` at ``(-mu, 0)`` and a Moon of
    mass ``mu`` at ``(1 - mu, 0)``; Coriolis terms make the acceleration depend on
    the velocity. State ``(x, y, vx, vy)``, dimensionless units.
    """

    def __init__(self, x0: np.ndarray, t0: float = 0.0, *, mu: float = 0.012277471) -> None:
        super().__init__(x0, t0)
        self.mu = mu

    def acceleration(self, q: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
        mu, nu = self.mu, 1.0 - self.mu
        x, y = float(q[0]), float(q[1])
        r1 = (x + mu) ** 2 + y * y
        r2 = (x - nu) ** 2 + y * y
        d1 = r1 * math.sqrt(r1)
        d2 = r2 * math.sqrt(r2)
        ax = x + 2 * float(v[1]) - nu * (x + mu) / d1 - mu * (x - nu) / d2
        ay = y - 2 * float(v[0]) - nu * y / d1 - mu * y / d2
        return np.array([ax, ay])

    def rhs_kernel(self) -> tuple[int, tuple[float, ...]]:
        """The compiled loop's right-hand side (:mod:`~truestep.reference_impl.odes_loop`)."""
        return odes_kernels.ARENSTORF, (float(self.mu), 2.0)

    def compiled_derivative(self) -> Callable[[np.ndarray, float], np.ndarray]:
        kernel, mu = odes_kernels.arenstorf, float(self.mu)
        return lambda x, t: kernel(x, t, np.empty(4), mu, 2.0)

    def jacobian(self, x: np.ndarray, t: float) -> np.ndarray:
        """``d[v, a]/d[q, v]``: the two point-mass pulls, the centrifugal and Coriolis terms."""
        mu, nu = self.mu, 1.0 - self.mu
        q = x[:2]
        jac = np.zeros((4, 4))
        jac[:2, 2:] = np.eye(2)
        da = np.eye(2)
        for m, centre in ((nu, np.array([-mu, 0.0])), (mu, np.array([nu, 0.0]))):
            d = q - centre
            r2 = float(d @ d)
            r = np.sqrt(r2)
            da -= m * (np.eye(2) / r**3 - 3.0 * np.outer(d, d) / (r**3 * r2))
        jac[2:, :2] = da
        jac[2:, 2:] = np.array([[0.0, 2.0], [-2.0, 0.0]])
        return jac
