"""One solver step on a 6-dimensional system, for every reference method.

Run: ``python -m pytest benchmarks/test_solver_step.py --benchmark-enable``. Compare
methods as ratios within one run: the machine is shared and its clock is noisy.
"""

from __future__ import annotations

import numpy as np
import pytest

from truestep.reference_impl.solvers import METHODS
from truestep.reference_impl.system import SecondOrderSystem


class ThreeOscillators(SecondOrderSystem):
    """Three uncoupled oscillators (omega = 1, 2, 3 rad/s): state (q1..q3, v1..v3)."""

    OMEGA2 = np.array([1.0, 4.0, 9.0])

    def __init__(self) -> None:
        super().__init__(np.array([1.0, 0.5, 0.25, 0.0, 0.0, 0.0]))

    def acceleration(self, q, v, t):
        return -self.OMEGA2 * q

    def jacobian(self, x, t):
        jac = np.zeros((6, 6))
        jac[:3, 3:] = np.eye(3)
        jac[3:, :3] = -np.diag(self.OMEGA2)
        return jac


@pytest.mark.parametrize("method", list(METHODS))
def test_one_step(benchmark, method):
    system = ThreeOscillators()
    cls = METHODS[method]
    solver = cls(system, rtol=1e-8, atol=1e-8) if cls.adaptive else cls(system)
    benchmark.group = "one solver step, 6-dimensional system"
    benchmark(solver.step, 1e-3)
    assert np.all(np.isfinite(system.get_state()))
