"""The between-step passes a particle scene needs: collisions, emitters, lifetimes."""

from __future__ import annotations

import numpy as np

from truestep.reference_impl.collisions import PlaneCollisions
from truestep.reference_impl.emitters import Emitter, pool_starts
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.particles import Pass


def passes_for(model: ParticleModel) -> list[Pass]:
    """Only the passes the scene needs, in the lecture's order: collide, then emit and expire.

    Emitters measure height against gravity (along +y in a scene without gravity).
    """
    passes: list[Pass] = []
    if model.planes:
        passes.append(PlaneCollisions(model.planes, model.radius, model.fixed, model.mass))
    g = float(np.linalg.norm(model.gravity))
    up = -model.gravity / g if g > 0 else np.array([0.0, 1.0, 0.0])
    for spec, first in zip(model.emitters, pool_starts(model), strict=True):
        passes.append(Emitter(spec, first, up))
    return passes
