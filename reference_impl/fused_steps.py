"""The fused layout's step (:class:`~truestep.reference_impl.tiles.Fused`): every method's
step of one particle, in one loop over a tile.

A fused loop holds the step of every method that runs in it, picked once a step by the
:class:`~truestep.reference_impl.solvers.any_method.AnyMethod` it is called with: for each
pattern of non-zero tableau entries among its methods (the record's ``patterns``), the
tableau's step of one particle with its stages unrolled
(:func:`~truestep.reference_impl.solvers.explicit_rk_kernels.unrolled_step`), and the
kick and drift and velocity Verlet's. Each is one loop over the tile's particles
(:func:`fused_particles_for`) that the compiler vectorises; the rare special particles
are stepped again alone (:func:`special_step`), then the collision pass visits the marked
ones (:func:`fused_step_for`). Python makes the step for a loop's patterns once, as
closures over the parts (compiled into the loop that calls them); no code is written as
text.
"""

from __future__ import annotations

import functools

from numba import njit

from truestep.reference_impl.forces_kernels import COLD
from truestep.reference_impl.solvers.any_method import KICK_DRIFT, KICK_DRIFT_KICK, TABLEAU
from truestep.reference_impl.solvers.explicit_rk_kernels import tableau_point_loop, unrolled_step
from truestep.reference_impl.solvers.splitting_kernels import (
    kick_drift_kick_point_step,
    kick_drift_kick_special_step,
    kick_drift_point_step,
)
from truestep.reference_impl.tiles import (
    FRESH,
    SPECIAL,
    fused_collide,
    list_special,
    load,
    mark_special,
    near_planes,
    store,
)

INLINE: dict = {"error_model": "numpy", "inline": "always"}
"""How the parts Python makes for a loop are compiled: into the loop (not cached on their
own: the loop is)."""


@functools.cache
def fused_particles_for(point_step):
    """Each particle's whole step by ``point_step`` (a step of one particle: the unrolled
    step of a tableau's pattern, or a splitting's) in one loop that also marks those near
    a plane: ``particles(method, scene, tile, t, h)``."""

    def particles(method, scene, tile, t, h):
        X, V = tile.X, tile.V
        radius = scene.particles.radius
        for j in range(X.shape[1]):
            x, v = point_step(method, False, scene, tile, load(X, j), load(V, j), t, h, j)
            store(X, j, x)
            store(V, j, v)
            tile.flags[j] = near_planes(scene, x, radius[j])

    return njit(**INLINE)(particles)


def _then_pattern(i: int, pattern: tuple, rest):
    """The steps of a loop whose ``i``-th tableau pattern is ``pattern``, before ``rest``."""
    particles = fused_particles_for(unrolled_step(pattern))

    def steps(method, scene, tile, t, h):
        if method.shape == TABLEAU and method.pattern == i:
            n = method.tableau.evaluations
            particles(method.tableau, scene, tile, t, h)
            return n
        return rest(method, scene, tile, t, h)

    return njit(**INLINE)(steps)


def _splittings():
    """The steps of the two splittings, the last of a loop's steps (-1 for any other)."""
    kick_drift = fused_particles_for(kick_drift_point_step)
    kick_drift_kick = fused_particles_for(kick_drift_kick_point_step)

    def steps(method, scene, tile, t, h):
        if method.shape == KICK_DRIFT:
            n = method.kick_drift.evaluations
            kick_drift(method.kick_drift, scene, tile, t, h)
            return n
        if method.shape == KICK_DRIFT_KICK:
            n = 2 if tile.count[FRESH] else 1
            kick_drift_kick(method.kick_drift_kick, scene, tile, t, h)
            return n
        return -1

    return njit(**INLINE)(steps)


@functools.cache
def step_particles_for(patterns: tuple):
    """Every particle of a tile through one step of ``method`` (an ``AnyMethod``), for a
    loop that holds the tableau ``patterns``: the loop's particles for the method's step,
    picked once a step; ``steps(method, scene, tile, t, h)`` returns the evaluations."""
    steps = _splittings()
    for i in reversed(range(len(patterns))):
        steps = _then_pattern(i, patterns[i], steps)
    return steps


@njit(**COLD)
def special_step(method, scene, tile, x, v, t, h, p):
    """A special particle's step from ``x``, ``v`` alone, its whole acceleration: a
    tableau's with its stages in a loop, or a splitting's."""
    if method.shape == TABLEAU:
        return tableau_point_loop(method.tableau, True, scene, tile, x, v, t, h, p)
    if method.shape == KICK_DRIFT:
        return kick_drift_point_step(method.kick_drift, True, scene, tile, x, v, t, h, p)
    return kick_drift_kick_special_step(method.kick_drift_kick, True, scene, tile, x, v, t, h, p)


@functools.cache
def fused_step_for(patterns: tuple):
    """One step of ``method`` over a tile of independent particles, for a loop that holds
    the tableau ``patterns``: each particle's whole step (:func:`step_particles_for`); the
    special particles' again (:func:`special_step`) from their state at the step's start,
    saved first (with the acceleration a method that carries it keeps, into ``F``); then
    the collision pass on the marked ones, which says whether the next step evaluates
    afresh, and the special ones listed anew. ``step(method, scene, tile, t, h)`` returns
    the evaluations the step made."""
    step_particles = step_particles_for(patterns)

    def step(method, scene, tile, t, h):
        X, V, XS, VS = tile.X, tile.V, tile.XS, tile.VS
        special = tile.special
        for q in range(tile.count[SPECIAL]):
            p = special[q]
            store(XS, p, load(X, p))
            store(VS, p, load(V, p))
            store(tile.F, p, load(tile.A, p))
        evaluations = step_particles(method, scene, tile, t, h)
        for q in range(tile.count[SPECIAL]):
            p = special[q]
            x, v = special_step(method, scene, tile, load(XS, p), load(VS, p), t, h, p)
            store(X, p, x)
            store(V, p, v)
        mark_special(scene, tile)
        tile.count[FRESH] = fused_collide(scene, tile, t + h, h)
        list_special(scene, tile)
        return evaluations

    return njit(**INLINE)(step)
