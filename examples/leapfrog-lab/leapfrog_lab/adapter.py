"""leapfrog-lab behind truestep's adapter protocol: the whole adapter."""

from typing import ClassVar

import truestep
from leapfrog_lab.world import World


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
    method_facts: ClassVar = {"leapfrog": "verlet"}  # every fact of Verlet's: omega h < 2, order 2

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
