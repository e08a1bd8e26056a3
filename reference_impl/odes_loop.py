"""The reference's fixed-step methods on the plain ODE systems, in one compiled loop.

:func:`run_ode` steps a system of :mod:`~truestep.reference_impl.odes` (its right-hand side
in :mod:`~truestep.reference_impl.odes_kernels`, chosen by a number) with an explicit
tableau or one of the three splittings, as
:func:`~truestep.reference_impl.integrate.integrate` steps its numpy system with the
solver classes: the same sums in the same order, the same times (``t + h`` a step), the
same records, evaluations, blow-up checks and stop. One loop for every system and method,
compiled once and cached: the system and the method are arguments, not code to generate.

The states equal the numpy path's bit for bit, tested on every ODE case and method. The
one sum numpy hands to BLAS, RK4's ``b @ k``, is summed here as OpenBLAS's Haswell kernels
(the ones truestep asks for, :mod:`truestep.numerics`) sum it for the two state sizes of the
library's systems (:func:`weighted_sum`, tested against ``b @ k``).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any, cast

import llvmlite.ir as llvm_ir  # type: ignore[import-untyped]
import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from truestep.reference_impl.integrate import BLOWUP, CHECK_EVERY, Run, record_indices
from truestep.reference_impl.odes_kernels import rhs
from truestep.reference_impl.solvers import get_solver
from truestep.reference_impl.solvers.explicit_rk import ExplicitRungeKutta
from truestep.reference_impl.solvers.splitting import LectureUpdate, SymplecticEuler, VelocityVerlet
from truestep.reference_impl.system import SecondOrderSystem, System

TABLEAU, SYMPLECTIC_EULER, VERLET, LECTURE = 0, 1, 2, 3
"""The kinds of step :func:`run_ode` takes."""
SPLITTINGS = {SymplecticEuler: SYMPLECTIC_EULER, VelocityVerlet: VERLET, LectureUpdate: LECTURE}
"""The splitting solver classes and their kinds."""
LOOP: dict[str, Any] = {"cache": True, "error_model": "numpy", "nogil": True}
"""How the loop is compiled: once, cached on disk."""


def ode_reason(system: System, method: str) -> str | None:
    """Why ``method`` on ``system`` cannot take the compiled loop, or ``None`` if it can."""
    if system.rhs_kernel() is None:
        return f"{type(system).__name__} has no compiled right-hand side"
    cls = get_solver(method)
    if cls in SPLITTINGS:
        return None if isinstance(system, SecondOrderSystem) else f"{method} needs a position/velocity split"
    if issubclass(cls, ExplicitRungeKutta) and not cls.adaptive:
        return None
    return f"{method} is not a fixed-step explicit method"


def _method(method: str) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """The loop's kind, tableau ``a`` (s, s), weights ``b`` (s,) and nodes ``c`` (s,) of
    ``method`` (a splitting's tableau is empty); ``c`` as ``rk_stages`` takes it, the row
    sums of ``a``."""
    cls = get_solver(method)
    if cls in SPLITTINGS:
        return SPLITTINGS[cls], np.zeros((0, 0)), np.zeros(0), np.zeros(0)
    tableau = cast(type[ExplicitRungeKutta], cls)
    a = np.ascontiguousarray(tableau.A, dtype=np.float64)
    b = np.ascontiguousarray(tableau.B, dtype=np.float64)
    return TABLEAU, a, b, np.array([float(row.sum()) for row in a])


def run(system: System, method: str, t_end: float, h: float, *, max_records: int = 2000) -> Run:
    """Step ``system`` (its state now) with ``method`` at step ``h`` (s) to ``t_end`` (s), as
    :func:`~truestep.reference_impl.integrate.integrate` does, and give its
    :class:`~truestep.reference_impl.integrate.Run` (``ode_reason`` must be ``None``;
    recording at :func:`~truestep.reference_impl.integrate.record_indices`; the system's
    state is left as it was)."""
    found = system.rhs_kernel()
    if found is None:
        raise ValueError(f"{type(system).__name__} has no compiled right-hand side")
    which, constants = found
    kind, a, b, c = _method(method)
    t0 = system.get_time()
    n_steps = round((t_end - t0) / h)
    marks = np.zeros(n_steps + 1, dtype=np.bool_)
    marks[record_indices(n_steps, max_records)] = True
    y0 = system.get_state()
    out_t = np.empty(int(marks.sum()) + 1)
    out_x = np.empty((len(out_t), len(y0)))
    params = np.array(constants + (0.0,) * (2 - len(constants)), dtype=float)
    start = time.perf_counter()
    kept, steps, nfev, bad = run_ode(which, params, kind, a, b, c, y0, t0, h, marks, out_t, out_x)
    wall = time.perf_counter() - start
    t_fail = float(out_t[kept - 1]) if bad else None
    t, x = out_t[:kept].copy(), out_x[:kept].copy()
    return Run(t, x, int(nfev), int(steps), wall, {}, "unstable" if bad else "ok", t_fail)


def warm(say: Callable[[str], None] | None = None) -> None:
    """Compile the loop (or load it from numba's cache) with a step of the circle field:
    one loop serves every system and method. Where that takes over half a second, a line
    through ``say`` (standard error by default) says so."""
    from truestep.reference_impl.odes import CircleField

    began = time.perf_counter()
    run(CircleField(np.array([1.0, 0.0])), "euler", 1.0, 1.0)
    took = time.perf_counter() - began
    if took > 0.5:
        line = f"compiled the reference's loop of the plain ODE systems in {took:.1f} s"
        (say or (lambda text: print(text, file=sys.stderr, flush=True)))(line)


@intrinsic
def fma(typingctx, a, b, c):
    """``a * b + c`` rounded once (LLVM's ``llvm.fma.f64``: IEEE's fused multiply-add, in
    hardware or not, the same bits on every machine)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        double = llvm_ir.DoubleType()
        fn = cgutils.get_or_insert_function(
            builder.module, llvm_ir.FunctionType(double, [double, double, double]), "llvm.fma.f64"
        )
        return builder.call(fn, args)

    return sig, codegen


@njit(**LOOP)
def weighted_sum(b, k, d):
    """``(b @ k)[d]`` for weights ``b`` (s,) and stages ``k`` (s, dim), summed as numpy's
    product sums it through OpenBLAS's Haswell kernels for four stages: of a state of 4,
    two fused chains ``b0 k0 + b2 k2`` and ``b1 k1 + b3 k3``, then added; of a state of 2,
    pairs of products, then added. Other sizes one product at a time, in order (exact for
    the tableaux with fewer stages: their weights make every product exact but one)."""
    s, dim = b.size, k.shape[1]
    if s == 4 and dim == 4:
        return fma(b[2], k[2, d], b[0] * k[0, d]) + fma(b[3], k[3, d], b[1] * k[1, d])
    if s == 4 and dim == 2:
        return (b[0] * k[0, d] + b[1] * k[1, d]) + (b[2] * k[2, d] + b[3] * k[3, d])
    total = b[0] * k[0, d]
    for j in range(1, s):
        total = total + b[j] * k[j, d]
    return total


@njit(**LOOP)
def _finite(x):
    """:func:`~truestep.reference_impl.integrate._finite`: every component finite and within
    ``BLOWUP`` (NaN fails both comparisons)."""
    return x.size == 0 or (-BLOWUP < x.min() and x.max() < BLOWUP)


STEP: dict[str, Any] = {**LOOP, "inline": "always"}
"""How a step of the loop is compiled: into the loop (:func:`run_ode`)."""


@njit(**STEP)
def _tableau_step(which, params, a, b, c, x, t, h, k, xi):
    """One explicit Runge-Kutta step of ``x`` (in place), as ``rk_stages`` and
    ``ExplicitRungeKutta.step`` take it; returns its evaluations."""
    dim, s = x.size, b.size
    for st in range(s):
        xi[:] = x
        for j in range(st):
            w = a[st, j]
            if w != 0.0:
                hw = h * w
                for d in range(dim):
                    xi[d] = xi[d] + hw * k[j, d]
        rhs(which, xi, t + c[st] * h, k[st], params)
    for d in range(dim):
        x[d] = x[d] + h * weighted_sum(b, k, d)
    return s


@njit(**STEP)
def _verlet_step(which, params, x, t, h, f, acc, xi, have_acc):
    """One velocity Verlet step of ``x`` (in place), reusing the last step's closing
    acceleration ``acc`` where ``have_acc``, as ``VelocityVerlet.step`` does; returns its
    evaluations."""
    half = x.size // 2
    made = 0
    if not have_acc:
        rhs(which, x, t, f, params)
        made += 1
        acc[:] = f
    half_h = 0.5 * h
    for d in range(half):
        v_half = x[half + d] + half_h * acc[half + d]
        xi[half + d] = v_half
        xi[d] = x[d] + h * v_half
    rhs(which, xi, t + h, f, params)
    for d in range(half):
        x[d] = xi[d]
        x[half + d] = xi[half + d] + half_h * f[half + d]
    acc[:] = f
    return made + 1


@njit(**STEP)
def _kick_drift(which, params, kind, x, t, h, f):
    """One symplectic Euler or lecture step of ``x`` (in place), as ``SymplecticEuler.step``
    and ``LectureUpdate.step`` take it; returns its evaluations."""
    half = x.size // 2
    rhs(which, x, t, f, params)
    for d in range(half):
        v = x[half + d]
        v_new = v + h * f[half + d]
        if kind == SYMPLECTIC_EULER:
            x[d] = x[d] + h * v_new
        else:
            x[d] = x[d] + (0.5 * h) * (v + v_new)
        x[half + d] = v_new
    return 1


@njit(**STEP)
def _stopped(x, t, out_t, out_x, kept, checked):
    """``_run_fixed``'s check of a run that is not finite now: the records kept (those up
    to the first bad one since ``checked``, or all and the state now if none is)."""
    for r in range(checked, kept):
        if not _finite(out_x[r]):
            return r + 1
    out_t[kept] = t
    out_x[kept] = x
    return kept + 1


@njit(**LOOP)
def run_ode(which, params, kind, a, b, c, y0, t0, h, marks, out_t, out_x):
    """``len(marks) - 1`` steps of ``h`` (s) of the system ``which`` (its ``params``) from
    ``y0`` (dim,) at ``t0`` (s), the step of ``kind`` (a tableau ``a``, ``b``, ``c``, or a
    splitting), recording at ``marks`` into ``out_t`` and ``out_x``. Returns (records kept,
    steps taken, evaluations, whether the state ran away); the checks and the stop are
    ``_run_fixed``'s."""
    dim = y0.size
    n = marks.size - 1
    x = y0.copy()
    t = t0
    k = np.empty((max(b.size, 1), dim))
    xi = np.empty(dim)
    f = np.empty(dim)
    acc = np.empty(dim)
    out_t[0] = t0
    out_x[0] = x
    kept, checked, nfev = 1, 1, 0
    for i in range(1, n + 1):
        if kind == TABLEAU:
            nfev += _tableau_step(which, params, a, b, c, x, t, h, k, xi)
        elif kind == VERLET:
            nfev += _verlet_step(which, params, x, t, h, f, acc, xi, i > 1)
        else:
            nfev += _kick_drift(which, params, kind, x, t, h, f)
        t = t + h
        if marks[i]:
            out_t[kept] = t
            out_x[kept] = x
            kept += 1
        if i % CHECK_EVERY == 0 or i == n:
            if _finite(x):
                checked = kept
                continue
            return _stopped(x, t, out_t, out_x, kept, checked), i, nfev, True
    return kept, n, nfev, False
