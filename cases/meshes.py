"""Scene parts that expand into many particles: mass-spring meshes and emitter pools."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cases.fields import Fields
from reference_impl.model import EmitterSpec, Springs


@dataclass
class MeshPart:
    """Particles and springs with local numbering (0..n-1), before offsetting.

    mass (n,) kg, x0 and v0 (n, 3), radius (n,) m, fixed (n,) bool, springs local.
    """

    mass: np.ndarray
    x0: np.ndarray
    v0: np.ndarray
    radius: np.ndarray
    fixed: np.ndarray
    springs: Springs

    @classmethod
    def pool(cls, capacity: int, mass: float) -> MeshPart:
        """An emitter's pool: ``capacity`` particles, all dead until spawned."""
        z = np.zeros((capacity, 3))
        return cls(np.full(capacity, mass), z, z.copy(), np.zeros(capacity),
                   np.zeros(capacity, bool), Springs.empty())


MESH_KINDS: set[str] = set()


def read_mesh(f: Fields) -> MeshPart:
    """Build a mass-spring mesh from a ``[[scene.meshes]]`` table."""
    raise f.error("kind", "mass-spring meshes are not available yet")


def read_emitter(f: Fields) -> EmitterSpec:
    """Read a ``[[scene.emitters]]`` table."""
    raise f.error("shape", "emitters are not available yet")
