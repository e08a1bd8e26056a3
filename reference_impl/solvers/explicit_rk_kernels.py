"""An explicit Runge-Kutta step of :mod:`~truestep.reference_impl.solvers.explicit_rk`, compiled.

:class:`Tableau` is a method's tableau as a compiled step reads it. Its stages are stepped
as :func:`~truestep.reference_impl.solvers.explicit_rk.rk_stages` steps them (stage ``s``
at ``x + sum_r (h a_sr) k_r``, the terms added one at a time in the order of ``r``, zero
weights left out) and the step ends with ``x + h sum_s b_s k_s``, the sum from ``0.0`` in
the order of the stages. The tableau is data: every explicit method shares one compiled
step in passes (:func:`stage_input` and :func:`tableau_finish` around each evaluation,
:func:`~truestep.reference_impl.solvers.any_method.any_passes`); a fused step
(:func:`tiles.fused_step`) takes the step of one particle unrolled for the tableau's
pattern of non-zero entries (:meth:`Tableau.point_step`). Twin:
:meth:`~truestep.reference_impl.solvers.explicit_rk.ExplicitRungeKutta.step`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from truestep.reference_impl import tiles
from truestep.reference_impl.class_kernels import carries
from truestep.reference_impl.compose import glue
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
def tableau_point_loop(method, scene, tile, x, v, t, h, p):
    """One particle's step of the tableau with its stages in a loop, their values in
    column ``p`` of ``KX``, ``KV``: the sums of :func:`point_step_lines` in the same order,
    for the rare particles a fused step takes again alone (a loop compiles faster than
    the stages unrolled; their speed does not matter)."""
    KX, KV, b = tile.KX, tile.KV, method.b
    for s in range(b.shape[0]):
        xs, vs = x, v
        for q in range(method.terms[s]):
            r = method.cols[s, q]
            w = h * method.weights[s, q]
            xs, vs = axpy(xs, w, load(KX[r], p)), axpy(vs, w, load(KV[r], p))
        store(KX[s], p, vs)
        store(KV[s], p, point_accel(scene, tile, xs, vs, t + method.c[s] * h, p))
    dx, dv = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    for s in range(b.shape[0]):
        dx, dv = axpy(dx, b[s], load(KX[s], p)), axpy(dv, b[s], load(KV[s], p))
    return axpy(x, h, dx), axpy(v, h, dv)


def point_step_lines(terms: list[list[int]], stages: int) -> list[str]:
    """The body of a tableau's step for one particle (see :meth:`Tableau.point_step`):
    its stages in order, stage ``s`` at ``x + sum (h a_sr) k_r`` over the non-zero entries
    ``terms[s]`` of its row, one term at a time, its acceleration from the slot
    ``point_accel``; then ``x + h sum_s b_s k_s`` summed from 0.0 in stage order."""
    lines = []
    for s in range(stages):
        lines += [f"x{s}, v{s} = x, v"]
        for q, r in enumerate(terms[s]):
            lines += [
                f"w = h * method.weights[{s}, {q}]",
                f"x{s}, v{s} = axpy(x{s}, w, v{r}), axpy(v{s}, w, a{r})",
            ]
        lines += [f"a{s} = point_accel(scene, tile, x{s}, v{s}, t + method.c[{s}] * h, p)"]
    lines += ["dx, dv = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)"]
    lines += [f"dx, dv = axpy(dx, method.b[{s}], v{s}), axpy(dv, method.b[{s}], a{s})" for s in range(stages)]
    return [*lines, "return axpy(x, h, dx), axpy(v, h, dv)"]


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

    def point_step(self):
        """The step of one particle (a filling of :func:`tiles.point_step`): the stages
        unrolled for this tableau's pattern of non-zero entries, which the code is made
        from (its weights are read from the tableau, so Heun and the midpoint method
        share it)."""
        terms = [list(self.cols[s, : self.terms[s]]) for s in range(len(self.b))]
        return glue(
            tiles.point_step,
            point_step_lines(terms, len(self.b)),
            {"axpy": axpy, "point_accel": tiles.point_accel},
        )

    def special_step(self):
        """The step of one special particle (a filling of :func:`tiles.special_step`)."""
        return tableau_point_loop

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
