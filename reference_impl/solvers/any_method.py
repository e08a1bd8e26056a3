"""Every fixed-step method of a scene as one record, so that one compiled loop runs them all.

Compiling a loop costs seconds; stepping a small scene, microseconds. A loop is therefore
compiled once a scene (its force kinds, impulses and planes) and layout, and holds the
step of every method that runs in that layout, picked once a step by the record
:class:`AnyMethod` (a test or two a step, nothing beside a step):

- in passes (:class:`~truestep.reference_impl.tiles.Passes`), the three shapes of step:
  a tableau's stages in a loop, a kick and drift, velocity Verlet's kicks around a drift,
  each written as what comes before each evaluation and after the last, so that the
  evaluation, the scene's forces, is at one place in the loop (:func:`any_passes`);
- fused (:class:`~truestep.reference_impl.tiles.Fused`), a step for each *pattern* of
  non-zero tableau entries among the methods (its stages unrolled for speed:
  :func:`~.explicit_rk_kernels.unrolled_step`; Heun and the midpoint method share a
  pattern), the kick and drift, and velocity Verlet's (whose tile is the whole scene: it
  carries state over it).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from truestep.reference_impl.by_type import Tag
from truestep.reference_impl.class_kernels import carries
from truestep.reference_impl.forces_kernels import KERNEL
from truestep.reference_impl.particles_kernels import accelerations
from truestep.reference_impl.solvers.explicit_rk_kernels import (
    Tableau,
    stage_input,
    tableau_finish,
)
from truestep.reference_impl.solvers.splitting_kernels import (
    KickDrift,
    KickDriftKick,
    kick_drift_finish,
    kick_drift_kick_finish,
    kick_drift_kick_input,
)
from truestep.reference_impl.tiles import CONTACT, FRESH, passes_collide

TABLEAU, KICK_DRIFT, KICK_DRIFT_KICK = 0, 1, 2
"""The shapes of step (:attr:`AnyMethod.shape`)."""


@njit(**KERNEL)
def evaluations(method, tile):
    """The evaluations ``method``'s step makes now, and the index of its first (velocity
    Verlet's first is skipped when the last step's closing acceleration is kept)."""
    if method.shape == TABLEAU:
        return method.tableau.b.shape[0], 0
    if method.shape == KICK_DRIFT:
        return 1, 0
    first = 0 if tile.count[FRESH] else 1
    return 2 - first, first


@njit(**KERNEL)
def step_input(method, e, tile, t, h):
    """What evaluation ``e`` of ``method``'s step evaluates: (where its accelerations go,
    positions, velocities, time), the state it needs made first."""
    if method.shape == TABLEAU:
        return stage_input(method.tableau, e, tile, t, h)
    if method.shape == KICK_DRIFT:
        return tile.A, tile.X, tile.V, t
    return kick_drift_kick_input(method.kick_drift_kick, e, tile, t, h)


@njit(**KERNEL)
def step_finish(method, tile, h):
    """The end of ``method``'s step over a tile, its evaluations made."""
    if method.shape == TABLEAU:
        tableau_finish(method.tableau, tile, h)
    elif method.shape == KICK_DRIFT:
        kick_drift_finish(method.kick_drift, tile, h)
    else:
        kick_drift_kick_finish(method.kick_drift_kick, tile, h)


@njit(**KERNEL)
def any_passes(method, scene, tile, t, h):
    """One step of ``method`` over a tile in passes: each of its evaluations (the
    accelerations of the whole tile at the state :func:`step_input` makes) at one place
    in the code, so that a loop holds its scene's forces once; then the end of the step
    and the collision pass. Returns the evaluations it made."""
    n, first = evaluations(method, tile)
    for e in range(first, first + n):
        out, X, V, te = step_input(method, e, tile, t, h)
        accelerations(scene, out, tile.F, X, V, te, tile.contact, tile.count[CONTACT] > 0)
    step_finish(method, tile, h)
    changed = passes_collide(scene, tile, t + h, h)
    if method.shape == KICK_DRIFT_KICK:  # its closing acceleration is kept unless changed
        tile.count[FRESH] = changed
    return n


_NO_TABLEAU = Tableau.of(np.zeros((1, 1)), np.zeros(1), np.zeros(1))
_NO_KICK_DRIFT = KickDrift(0.0, 0.0, 1)
_NO_KICK_DRIFT_KICK = KickDriftKick(0.0, 0.0, 0.0)


def pattern(kind: Tableau) -> tuple:
    """A tableau's pattern of non-zero entries below the diagonal, row by row: what its
    unrolled step of one particle is made from."""
    return tuple(tuple(int(c) for c in kind.cols[s, : kind.terms[s]]) for s in range(len(kind.b)))


@carries(passes=any_passes)
class AnyMethod(NamedTuple):
    """A method of any ``shape`` (:data:`TABLEAU`, ...): its own step in the field of that
    shape, placeholders of the right types in the others; ``pattern``, fused, the index of
    its tableau's pattern among the loop's ``patterns`` (:func:`fused_kinds`; a
    :class:`~truestep.reference_impl.by_type.Tag` of them, so that a loop is compiled
    with a step of one particle unrolled for each: :mod:`~truestep.reference_impl.fused_steps`)."""

    shape: int
    pattern: int
    tableau: Tableau
    kick_drift: KickDrift
    kick_drift_kick: KickDriftKick
    patterns: Tag

    @classmethod
    def of(cls, kind, patterns: tuple = ()) -> AnyMethod:
        """The record of a method's compiled step (a :class:`Tableau`, :class:`KickDrift`
        or :class:`KickDriftKick`); ``patterns`` are the fused loop's tableau patterns."""
        held = Tag(tuple(patterns))
        if isinstance(kind, Tableau):
            index = patterns.index(pattern(kind)) if patterns else 0
            return cls(TABLEAU, index, kind, _NO_KICK_DRIFT, _NO_KICK_DRIFT_KICK, held)
        if isinstance(kind, KickDrift):
            return cls(KICK_DRIFT, 0, _NO_TABLEAU, kind, _NO_KICK_DRIFT_KICK, held)
        if isinstance(kind, KickDriftKick):
            return cls(KICK_DRIFT_KICK, 0, _NO_TABLEAU, _NO_KICK_DRIFT, kind, held)
        raise TypeError(f"no compiled step for {type(kind).__name__}")

    @property
    def stages(self) -> int:
        """The tableau's stages (the scratch a step needs), 0 for a splitting."""
        return self.tableau.stages if self.shape == TABLEAU else 0


def fused_kinds(kinds) -> tuple[tuple, tuple]:
    """The fused steps a loop holds for ``kinds`` (the compiled steps of the methods):
    one tableau for each pattern, in order of first appearance, then the kick and drift
    and velocity Verlet's step if any method has them. Returns (the tableaux' patterns,
    the steps: (field of :class:`AnyMethod`, a step of that shape) each)."""
    patterns: list = []
    tableaux: list = []
    splittings: dict = {}
    for kind in kinds:
        if isinstance(kind, Tableau) and pattern(kind) not in patterns:
            patterns.append(pattern(kind))
            tableaux.append(("tableau", kind))
        elif isinstance(kind, KickDrift):
            splittings.setdefault("kick_drift", kind)
        elif isinstance(kind, KickDriftKick):
            splittings.setdefault("kick_drift_kick", kind)
    return tuple(patterns), (*tableaux, *splittings.items())
