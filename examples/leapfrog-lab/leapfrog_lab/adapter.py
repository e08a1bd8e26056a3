"""leapfrog-lab behind truestep's adapter protocol: the whole adapter."""

from typing import ClassVar

import numpy as np

import truestep
from leapfrog_lab.world import World


def drift_kick_drift(a: float, b: float) -> np.ndarray:
    """One step of this leapfrog on ``q'' = -omega^2 q - 2 zeta omega q'``, as a matrix on
    ``(q, h v)`` (``a = (omega h)^2``, ``b = 2 zeta omega h``): ``q_half = q + h v / 2``,
    ``h v' = h v - a q_half - b h v`` (the damper read at the step's start), ``q' = q_half
    + h v' / 2``. Undamped, its trace is ``2 - a`` and its determinant 1: stable for
    ``omega h < 2``, as Verlet."""
    return np.array([[1.0 - a / 2, 1.0 - a / 4 - b / 2], [-a, 1.0 - a / 2 - b]])


class LeapfrogAdapter(truestep.FixedStepAdapter):
    name = "leapfrog"
    methods = ("leapfrog",)
    capabilities = frozenset(
        {
            truestep.Feature.POINT_MASSES,
            truestep.Feature.PLANAR,
            truestep.Feature.SPATIAL,
            truestep.Feature.UNIFORM_GRAVITY,
            truestep.Feature.DRAG,
            truestep.Feature.SPRINGS,
            truestep.Feature.SPRING_DAMPING,
            truestep.Feature.ANCHORED_SPRINGS,
            truestep.Feature.PLANES,
            truestep.Feature.PINNED_PARTICLES,
        }
    )
    # Verlet's facts (order 2, first order with dampers, symplectic, omega h < 2), with this
    # scheme's own step: Verlet's carries its last acceleration, this one does not
    method_facts: ClassVar = {
        "leapfrog": truestep.MethodFacts.like(
            "verlet", stability=truestep.Stability(imaginary=2.0, real=2.0, step_matrix=drift_kick_drift)
        )
    }

    def build(self, case, method, h):
        m = case.particles
        s, a = m.springs, m.anchors
        return World(
            m.x0.copy(),
            m.v0.copy(),
            m.mass,
            m.fixed,
            m.radius,
            m.gravity,
            m.drag,
            springs=(s.i, s.j, s.stiffness, s.damping, s.rest) if len(s) else (),
            anchors=(a.i, a.point, a.stiffness, a.damping, a.rest) if len(a) else (),
            planes=tuple((p.point, p.normal, p.restitution) for p in m.planes),
        )

    def advance(self, world, k, steps, h):
        for _ in range(steps):
            world.step(h)

    def read(self, world):
        return world.x, world.v
