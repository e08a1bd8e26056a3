"""An explicit Runge-Kutta step of :mod:`~truestep.reference_impl.solvers.explicit_rk`, compiled.

:class:`Tableau` is a method's tableau as a compiled step reads it. Its stages are stepped
as :func:`~truestep.reference_impl.solvers.explicit_rk.rk_stages` steps them (stage ``s``
at ``x + sum_r (h a_sr) k_r``, the terms added one at a time in the order of ``r``, zero
weights left out) and the step ends with ``x + h sum_s b_s k_s``, the sum from ``0.0`` in
the order of the stages. The tableau is data: every explicit method shares one compiled
step in passes (:func:`stage_input` and :func:`tableau_finish` around each evaluation,
:func:`~truestep.reference_impl.solvers.any_method.any_passes`); a fused step
(:func:`tiles.fused_step`) takes the step of one particle unrolled for the tableau's
pattern of non-zero entries (:func:`unrolled_step`). Twin:
:meth:`~truestep.reference_impl.solvers.explicit_rk.ExplicitRungeKutta.step`.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np
from numba import njit

from truestep.reference_impl.class_kernels import carries
from truestep.reference_impl.forces_kernels import KERNEL
from truestep.reference_impl.tiles import axpy, load, point_accel, store


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
def stage_input(method, s, tile, t, h):
    """What stage ``s`` of a step in passes evaluates: (where its accelerations go,
    positions, velocities, time). Its positions go into ``XS`` and its velocities (the
    derivative of the positions) into ``KX[s]``, its accelerations into ``KV[s]``, at
    ``t + c_s h``; a stage without terms is the step's start, read where it is."""
    n = method.terms[s]
    X, V, XS, KX, KV = tile.X, tile.V, tile.XS, tile.KX, tile.KV
    if n > 0:
        add_terms(method, s, X, KX, XS, h, n, V, True)
        add_terms(method, s, V, KV, KX[s], h, n, V, False)
        return KV[s], XS, KX[s], t + method.c[s] * h
    return KV[s], X, V, t + method.c[s] * h


@njit(**KERNEL)
def tableau_finish(method, tile, h):
    """The end of a step in passes, its stages evaluated: ``x + h sum_s b_s k_s``."""
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


@njit(**KERNEL)
def tableau_point_loop(method, special, scene, tile, x, v, t, h, p):
    """One particle's step of the tableau with its stages in a loop, their values in
    column ``p`` of ``KX``, ``KV``, its acceleration a ``special`` particle's or not
    (:func:`tiles.point_accel`): the sums of :func:`unrolled_step` in the same order, for
    the rare particles a fused step takes again alone (a loop compiles faster than
    the stages unrolled; their speed does not matter)."""
    KX, KV, b = tile.KX, tile.KV, method.b
    for s in range(b.shape[0]):
        xs, vs = x, v
        for q in range(method.terms[s]):
            r = method.cols[s, q]
            w = h * method.weights[s, q]
            xs, vs = axpy(xs, w, load(KX[r], p)), axpy(vs, w, load(KV[r], p))
        store(KX[s], p, vs)
        store(KV[s], p, point_accel(special, scene, tile, xs, vs, t + method.c[s] * h, p))
    dx, dv = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    for s in range(b.shape[0]):
        dx, dv = axpy(dx, b[s], load(KX[s], p)), axpy(dv, b[s], load(KV[s], p))
    return axpy(x, h, dx), axpy(v, h, dv)


UNROLLED: dict = {"error_model": "numpy", "inline": "always"}
"""How the parts of an unrolled step are compiled: into the loop over a tile's particles
that calls them (which the compiler vectorises), made for each pattern by Python as
closures over its stages and terms (not cached on their own: the loop is)."""


def _no_terms(method, h, x, v, ks):
    return x, v


def _then_term(terms, s: int, q: int, r: int):
    """``terms`` followed by the term ``(h a_sr) k_r``, the ``q``-th of row ``s``."""

    def added(method, h, x, v, ks):
        xs, vs = terms(method, h, x, v, ks)
        w = h * method.weights[s, q]
        return axpy(xs, w, ks[r][0]), axpy(vs, w, ks[r][1])

    return njit(**UNROLLED)(added)


def _stages(pattern: tuple, s: int):
    """Stages ``s`` onwards of a step of ``pattern``: each stage's state ``x + sum_r (h
    a_sr) k_r``, one term at a time in the order of the row, and its acceleration,
    appended to ``ks`` (pairs of the stages' velocity and acceleration, 3-tuples)."""
    if s == len(pattern):
        return njit(**UNROLLED)(lambda method, special, scene, tile, x, v, t, h, p, ks: ks)
    terms = njit(**UNROLLED)(_no_terms)
    for q, r in enumerate(pattern[s]):
        terms = _then_term(terms, s, q, r)
    rest = _stages(pattern, s + 1)

    def stage(method, special, scene, tile, x, v, t, h, p, ks):
        xs, vs = terms(method, h, x, v, ks)
        a = point_accel(special, scene, tile, xs, vs, t + method.c[s] * h, p)
        return rest(method, special, scene, tile, x, v, t, h, p, (*ks, (vs, a)))

    return njit(**UNROLLED)(stage)


def _weighted(stages: int):
    """``(sum_s b_s v_s, sum_s b_s a_s)`` of the stages ``ks``, summed from 0.0 in stage
    order, one 3-tuple each."""
    total = njit(**UNROLLED)(lambda method, ks: ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))
    for s in range(stages):
        total = _then_weight(total, s)
    return total


def _then_weight(total, s: int):
    def added(method, ks):
        dx, dv = total(method, ks)
        return axpy(dx, method.b[s], ks[s][0]), axpy(dv, method.b[s], ks[s][1])

    return njit(**UNROLLED)(added)


@functools.cache
def unrolled_step(pattern: tuple):
    """The step of one particle of a tableau whose non-zero entries below the diagonal are
    ``pattern`` (row by row, :func:`any_method.pattern`), its stages unrolled: stage ``s`` at
    ``x + sum_r (h a_sr) k_r`` over the entries of its row, one term at a time, its
    acceleration a ``special`` particle's or not (:func:`tiles.point_accel`); then ``x + h sum_s b_s k_s``
    summed from 0.0 in stage order. The weights are read from the tableau, so Heun and the
    midpoint method share it; made once a process for each pattern."""
    stages, weighted = _stages(pattern, 0), _weighted(len(pattern))

    def step(method, special, scene, tile, x, v, t, h, p):
        dx, dv = weighted(method, stages(method, special, scene, tile, x, v, t, h, p, ()))
        return axpy(x, h, dx), axpy(v, h, dv)

    return njit(**UNROLLED)(step)


@carries(carries_state=False)
class Tableau(NamedTuple):
    """An explicit tableau as a compiled step reads it: ``b`` and ``c`` ((s,) float64, the
    method's ``B`` and row sums of ``A``); for each row ``s`` of ``A``, its ``terms[s]``
    non-zero entries below the diagonal, their columns ``cols[s, :terms[s]]`` (int64) and
    values ``weights[s, :terms[s]]`` in order (each (s, s)); ``evaluations`` (s) a step
    makes."""

    b: np.ndarray
    c: np.ndarray
    terms: np.ndarray
    cols: np.ndarray
    weights: np.ndarray
    evaluations: int

    @classmethod
    def of(cls, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> Tableau:
        """The tableau ``a`` (s, s), ``b`` (s,), ``c`` (s,) of a method."""
        s = len(b)
        terms = np.zeros(s, dtype=np.int64)
        cols, weights = np.zeros((s, s), dtype=np.int64), np.zeros((s, s))
        for i in range(s):
            nonzero = np.flatnonzero(a[i, :i])
            terms[i] = len(nonzero)
            cols[i, : len(nonzero)] = nonzero
            weights[i, : len(nonzero)] = a[i, nonzero]
        return cls(np.array(b, dtype=float), np.array(c, dtype=float), terms, cols, weights, len(b))

    @property
    def stages(self) -> int:
        """Stages a step evaluates."""
        return len(self.b)
