"""The between-step passes a particle scene needs: collisions, emitters, lifetimes."""

from __future__ import annotations

from reference_impl.model import ParticleModel
from reference_impl.particles import Pass


def passes_for(model: ParticleModel) -> list[Pass]:
    """Only the passes the scene needs, in the lecture's order."""
    return []
