"""An explicit Runge-Kutta step of :mod:`~truestep.reference_impl.solvers.explicit_rk`, compiled.

:class:`Tableau` is a method's tableau as a compiled step reads it. Its stages are stepped
as :func:`~truestep.reference_impl.solvers.explicit_rk.rk_stages` steps them (stage ``s``
at ``x + sum_r (h a_sr) k_r``, the terms added one at a time in the order of ``r``, zero
weights left out) and the step ends with ``x + h sum_s b_s k_s``, the sum from ``0.0`` in
the order of the stages. The tableau is data: every explicit method shares one compiled
step. Twin: :meth:`~truestep.reference_impl.solvers.explicit_rk.ExplicitRungeKutta.step`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from truestep.reference_impl.forces_kernels import KERNEL
from truestep.reference_impl.particles_kernels import (
    accelerations,
    particle_force,
    point_force,
    scaled,
)
from truestep.reference_impl.tiles import (
    CONTACT,
    SPECIAL,
    axpy,
    collisions,
    list_special,
    load,
    mark_special,
    near_planes,
    point_contact,
    store,
)


@njit(**KERNEL)
def add_terms(method, s, Y, K, out, h, last, V, starts_in_v):
    """``out = Y + sum_r (h a_sr) K[r]`` over the first ``last`` non-zero terms of row
    ``s``, one term at a time, over a tile ((3, m) arrays); with ``starts_in_v``, a stage
    ``r`` without terms reads ``V`` for ``K[r]`` (see :func:`weighted`)."""
    src = Y
    for q in range(last):
        r = method.cols[s, q]
        w = h * method.weights[s, q]
        Kr = V if starts_in_v and method.terms[r] == 0 else K[r]
        for j in range(Y.shape[1]):
            store(out, j, axpy(load(src, j), w, load(Kr, j)))
        src = out


@njit(**KERNEL)
def stage_passes(method, s, scene, tile, t, h):
    """Stage ``s`` over a tile in passes: its positions into ``XS`` and its velocities
    (the derivative of the positions) into ``KX[s]``, then its accelerations into
    ``KV[s]`` at ``t + c_s h``. A stage without terms is the step's start: its state is
    read where it is."""
    n = method.terms[s]
    X, V, XS, KX, KV = tile.X, tile.V, tile.XS, tile.KX, tile.KV
    ts = t + method.c[s] * h
    any_contact = tile.count[CONTACT] > 0
    if n == 0:
        accelerations(scene, KV[s], tile.F, X, V, ts, tile.contact, any_contact)
    else:
        add_terms(method, s, X, KX, XS, h, n, V, True)
        add_terms(method, s, V, KV, KX[s], h, n, V, False)
        accelerations(scene, KV[s], tile.F, XS, KX[s], ts, tile.contact, any_contact)


@njit(**KERNEL)
def last_term(method, s, h):
    """The column and ``h a_sr`` of the last non-zero term of row ``s`` (0, 0.0 if none)."""
    n = method.terms[s]
    if n == 0:
        return 0, 0.0
    return method.cols[s, n - 1], h * method.weights[s, n - 1]


@njit(**KERNEL)
def stage_point(X, V, KX, KV, r, a, n, p):
    """Particle ``p``'s stage state: its state in ``X``, ``V``, plus ``a`` times its
    ``KX[r]``, ``KV[r]`` when the stage has terms (``n > 0``); 3-tuples."""
    x, v = load(X, p), load(V, p)
    if n == 0:
        return x, v
    Kx, Kv = KX[r], KV[r]
    return ((x[0] + a * Kx[0, p], x[1] + a * Kx[1, p], x[2] + a * Kx[2, p]),
            (v[0] + a * Kv[0, p], v[1] + a * Kv[1, p], v[2] + a * Kv[2, p]))


@njit(**KERNEL)
def stage_fused(method, s, scene, tile, t, h):
    """Stage ``s`` over a tile of independent particles: the terms of its row but the last
    in passes, then, in one loop, each particle's stage state (the last term added), its
    acceleration, and both added into the step's weighted sums ``DX``, ``DV`` (cleared
    before the first stage); the special particles' accelerations then again with their
    impulses and contact, and their ``DV`` summed afresh."""
    n = method.terms[s]
    X, V, XS, VS, KX, KV = tile.X, tile.V, tile.XS, tile.VS, tile.KX, tile.KV
    DX, DV, b = tile.DX, tile.DV, method.b[s]
    w, ts = scene.particles.inv_mass, t + method.c[s] * h
    BX, BV = X, V
    if n > 1:
        add_terms(method, s, X, KX, XS, h, n - 1, V, False)
        add_terms(method, s, V, KV, VS, h, n - 1, V, False)
        BX, BV = XS, VS
    r, a = last_term(method, s, h)
    KXs, KVs, KXr, KVr = KX[s], KV[s], KX[r], KV[r]
    if n == 0:
        for j in range(X.shape[1]):
            v = load(BV, j)
            f = scaled(point_force(scene, load(BX, j), v, ts, j), w[j])
            store(KXs, j, v)
            store(KVs, j, f)
            store(DX, j, axpy(load(DX, j), b, v))
            store(DV, j, axpy(load(DV, j), b, f))
    else:
        for j in range(X.shape[1]):
            x = axpy(load(BX, j), a, load(KXr, j))
            v = axpy(load(BV, j), a, load(KVr, j))
            f = scaled(point_force(scene, x, v, ts, j), w[j])
            store(KXs, j, v)
            store(KVs, j, f)
            store(DX, j, axpy(load(DX, j), b, v))
            store(DV, j, axpy(load(DV, j), b, f))
    for q in range(tile.count[SPECIAL]):
        p = tile.special[q]
        x, v = stage_point(BX, BV, KX, KV, r, a, n, p)
        f = point_contact(scene, tile, particle_force(scene, x, v, ts, p), v, p)
        store(KVs, p, scaled(f, w[p]))
        dv = (0.0, 0.0, 0.0)
        for k in range(s + 1):
            dv = axpy(dv, method.b[k], load(KV[k], p))
        store(DV, p, dv)


@njit(**KERNEL)
def tableau_passes(method, scene, tile, t, h):
    """One step of the tableau over a tile in passes, then the collision pass; returns the
    evaluations it made (its stages)."""
    for s in range(method.b.shape[0]):
        stage_passes(method, s, scene, tile, t, h)
    X, V = tile.X, tile.V
    KX, KV, b, terms = tile.KX, tile.KV, method.b, method.terms
    for j in range(X.shape[1]):
        v = load(V, j)
        dx, dv = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        for s in range(b.shape[0]):
            dx = axpy(dx, b[s], v if terms[s] == 0 else load(KX[s], j))
            dv = axpy(dv, b[s], load(KV[s], j))
        store(X, j, axpy(load(X, j), h, dx))
        store(V, j, axpy(v, h, dv))
    collisions(scene, tile, t + h, h)
    return method.b.shape[0]


@njit(**KERNEL)
def tableau_fused(method, scene, tile, t, h):
    """:func:`tableau_passes` for a tile of independent particles (:func:`stage_fused`),
    the update in one loop that also marks the particles near a plane for the collision
    pass, which visits only those and the special ones."""
    X, V, DX, DV = tile.X, tile.V, tile.DX, tile.DV
    for j in range(X.shape[1]):
        store(DX, j, (0.0, 0.0, 0.0))
        store(DV, j, (0.0, 0.0, 0.0))
    for s in range(method.b.shape[0]):
        stage_fused(method, s, scene, tile, t, h)
    radius = scene.particles.radius
    for j in range(X.shape[1]):
        x = (X[0, j] + h * DX[0, j], X[1, j] + h * DX[1, j], X[2, j] + h * DX[2, j])
        store(X, j, x)
        store(V, j, (V[0, j] + h * DV[0, j], V[1, j] + h * DV[1, j], V[2, j] + h * DV[2, j]))
        tile.flags[j] = near_planes(scene, x, radius[j])
    mark_special(scene, tile)
    collisions(scene, tile, t + h, h)
    list_special(scene, tile)
    return method.b.shape[0]


class Tableau(NamedTuple):
    """An explicit tableau as a compiled step reads it: ``b`` and ``c`` ((s,) float64, the
    method's ``B`` and row sums of ``A``); for each row ``s`` of ``A``, its ``terms[s]``
    non-zero entries below the diagonal, their columns ``cols[s, :terms[s]]`` (int64) and
    values ``weights[s, :terms[s]]`` in order (each (s, s))."""

    b: np.ndarray
    c: np.ndarray
    terms: np.ndarray
    cols: np.ndarray
    weights: np.ndarray
    passes = tableau_passes
    fused = tableau_fused
    carries_state = False

    @classmethod
    def of(cls, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> Tableau:
        """The tableau ``a`` (s, s), ``b`` (s,), ``c`` (s,) of a method."""
        s = len(b)
        terms = np.zeros(s, dtype=np.int64)
        cols, weights = np.zeros((s, s), dtype=np.int64), np.zeros((s, s))
        for i in range(s):
            nonzero = np.flatnonzero(a[i, :i])
            terms[i] = len(nonzero)
            cols[i, :len(nonzero)] = nonzero
            weights[i, :len(nonzero)] = a[i, nonzero]
        return cls(np.array(b, dtype=float), np.array(c, dtype=float), terms, cols, weights)

    @property
    def stages(self) -> int:
        """Stages a step evaluates."""
        return len(self.b)
