"""The simulation loop of :func:`~truestep.reference_impl.integrate.integrate`, compiled: one
driver for every compiled step.

:func:`drive` steps a packed scene (:mod:`~truestep.reference_impl.compiled`) with a
method's compiled step in either layout (:mod:`~truestep.reference_impl.tiles`), and owns
what every run needs besides the physics: the records at the steps
:func:`~truestep.reference_impl.integrate.record_indices` picks, the blow-up check every
:data:`~truestep.reference_impl.integrate.CHECK_EVERY` steps against
:data:`~truestep.reference_impl.integrate.BLOWUP` with ``integrate``'s stop policy, the
timing, and, when asked, the energy at every step (:func:`watch_energy`).

A scene cut into tiles takes each tile through all its steps before the next. A blow-up
found in one tile of several is run again as one tile from the start, so that the records
and the step it stopped at are what stepping the whole scene gives.
"""

from __future__ import annotations

import functools
import math
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba import njit
from numba.extending import overload

from truestep.reference_impl.by_type import BY_TYPE, field_type, tag_key
from truestep.reference_impl.forces_kernels import COLD, KERNEL, LEAF, LOOP
from truestep.reference_impl.fused_steps import fused_step_for
from truestep.reference_impl.integrate import BLOWUP, CHECK_EVERY, record_indices
from truestep.reference_impl.particles_kernels import cut, total_energy
from truestep.reference_impl.solvers.any_method import AnyMethod
from truestep.reference_impl.tiles import Fused, load, scratch, store, tile_view


class EnergyMonitor(NamedTuple):
    """The running ``bounds`` (float64, (2,): min and max, J) of the total energy of every
    state of a run, the first included; non-finite energies are left out. A run that does
    not track the energy passes empty ``bounds`` (:data:`UNWATCHED`)."""

    bounds: np.ndarray


def unwatched() -> EnergyMonitor:
    """The monitor of a run that does not track the energy: no bounds, nothing computed."""
    return EnergyMonitor(np.empty(0))


@njit(**KERNEL)
def watch_energy(monitor, scene, tile):
    """Fold the tile's total energy into ``monitor`` (the tile is then the whole scene), or
    nothing when its ``bounds`` are empty: one loop serves runs that track the energy and
    runs that do not, at the cost of a test a step (timed runs track nothing)."""
    if monitor.bounds.shape[0] == 0:
        return
    e = total_energy(scene, tile.X, tile.V)
    if e < monitor.bounds[0]:
        monitor.bounds[0] = e
    if e > monitor.bounds[1]:
        monitor.bounds[1] = e


@njit(**LEAF)
def finite(X, V):
    """Every component of the (3, m) state finite and within :data:`BLOWUP` (NaN fails
    both comparisons): :func:`integrate._finite`."""
    ok = True
    for p in range(X.shape[1]):
        for c in range(3):
            x, v = X[c, p], V[c, p]
            ok &= (-BLOWUP < x) & (x < BLOWUP) & (-BLOWUP < v) & (v < BLOWUP)
    return ok


@njit(**KERNEL)
def write(xs, vs, ts, r, tile, lo, t):
    """Record the tile's state (particles ``lo ...``) and the time ``t`` at record ``r``."""
    X, V = tile.X, tile.V
    for p in range(X.shape[1]):
        xs[r, lo + p, 0], xs[r, lo + p, 1], xs[r, lo + p, 2] = X[0, p], X[1, p], X[2, p]
        vs[r, lo + p, 0], vs[r, lo + p, 1], vs[r, lo + p, 2] = V[0, p], V[1, p], V[2, p]
    ts[r] = t


@njit(**COLD)
def first_bad(xs, vs, lo, hi, checked, kept):
    """The first record from ``checked`` to ``kept`` not finite in particles ``lo`` to
    ``hi``, or -1."""
    for r in range(checked, kept):
        for p in range(lo, hi):
            for c in range(3):
                if not (-BLOWUP < xs[r, p, c] < BLOWUP and -BLOWUP < vs[r, p, c] < BLOWUP):
                    return r
    return -1


@njit(**COLD)
def stopped(xs, vs, ts, tile, lo, checked, kept, recorded, t):
    """``integrate``'s stop on a failed check: the records end at the first non-finite one
    since the last good check, or, if all of those are finite, with the state now (unless
    it was just recorded). Returns the records kept."""
    bad = first_bad(xs, vs, lo, lo + tile.X.shape[1], checked, kept)
    if bad >= 0:
        return bad + 1
    if not recorded:
        write(xs, vs, ts, kept, tile, lo, t)
        return kept + 1
    return kept


@functools.cache
def tile_runner(layout: type, patterns: tuple):
    """The loop over a tile's steps in ``layout`` (:class:`Passes` or :class:`Fused`; fused,
    with the step of one particle of every tableau of ``patterns``): the layout's first
    pass and its step, compiled into it: :func:`run_tile`'s code for that layout (numba
    compiles it as the overload of :func:`run_tile`, one function: no call between)."""
    start = getattr(layout, "start")  # noqa: B009  # set by @carries, unseen by a type checker
    step = fused_step_for(patterns) if layout is Fused else getattr(AnyMethod, "passes")  # noqa: B009

    def run(method, layout, scene, X0, V0, lo, h, n_steps, record, buffers, xs, vs, ts, monitor):
        m = scene.particles.mass.shape[0]
        tile = tile_view(buffers, m)
        for p in range(m):
            store(tile.X, p, load(X0, lo + p))
            store(tile.V, p, load(V0, lo + p))
        t = 0.0
        start(scene, tile, t)
        write(xs, vs, ts, 0, tile, lo, t)
        watch_energy(monitor, scene, tile)
        kept, checked, nfev = 1, 1, 0
        for i in range(1, n_steps + 1):
            nfev += step(method, scene, tile, t, h)
            t = t + h
            if record[i]:
                write(xs, vs, ts, kept, tile, lo, t)
                kept += 1
            watch_energy(monitor, scene, tile)
            if i % CHECK_EVERY == 0 or i == n_steps:
                if finite(tile.X, tile.V):
                    checked = kept
                    continue
                return stopped(xs, vs, ts, tile, lo, checked, kept, record[i], t), i, nfev, True
        return kept, n_steps, nfev, False

    return run


def run_tile(method, layout, scene, X0, V0, lo, h, n_steps, record, buffers, xs, vs, ts, monitor):
    """Particles ``lo`` to ``lo + m`` of ``scene`` (a tile of m) from ``X0``, ``V0`` through
    ``n_steps`` steps of ``h`` s by ``method`` in ``layout``, in the scratch ``buffers``
    (:func:`tile_runner` for the layout and the method's patterns). Returns (records kept,
    steps, evaluations, unstable)."""
    run = tile_runner(type(layout), method.patterns.key)
    return run(method, layout, scene, X0, V0, lo, h, n_steps, record, buffers, xs, vs, ts, monitor)


@overload(run_tile, **BY_TYPE)
def _run_tile(method, layout, scene, X0, V0, lo, h, n_steps, record, buffers, xs, vs, ts, monitor):
    return tile_runner(layout.instance_class, tag_key(field_type(method, "patterns")))


@njit(**LOOP)
def drive(
    method, layout, size, first, stride, scene, X0, V0, h, n_steps, record, buffers, xs, vs, ts, monitor
):
    """Tiles ``first``, ``first + stride``, ... of ``scene`` (``size`` particles each) through
    ``n_steps`` steps (:func:`run_tile`); ``first = 0, stride = 1``: every tile. Returns
    (records kept, steps, evaluations, unstable, split) of the last tile it ran: with
    ``split``, a tile of several blew up and the run must be made again as one tile.
    Compiled once for each combination of the types of its arguments (the method record,
    the layout, the scene's kinds; :mod:`~truestep.reference_impl.by_type`), with caching and
    without Python's lock, so that threads may run other tiles of the same run at once
    (:func:`run`)."""
    n = X0.shape[1]
    size = max(1, min(size, n))
    kept, steps, nfev, unstable = 0, 0, 0, False
    for lo in range(first * size, max(n, 1), stride * size):
        hi = min(lo + size, n)
        kept, steps, nfev, unstable = run_tile(
            method, layout, cut(scene, lo, hi), X0, V0, lo, h, n_steps, record, buffers, xs, vs, ts, monitor
        )
        if unstable and size < n:
            return kept, steps, nfev, unstable, True
    return kept, steps, nfev, unstable, False


_POOLS: dict[tuple[int, int], ThreadPoolExecutor] = {}
"""The thread pools of this process, by (process id, threads): a forked process starts its own."""


def _pool(threads: int) -> ThreadPoolExecutor:
    """A pool of ``threads`` threads, made once per process and size (its threads started
    once, not at every run)."""
    key = (os.getpid(), threads)
    if key not in _POOLS:
        _POOLS[key] = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="truestep-tiles")
    return _POOLS[key]


def _on_threads(
    loop, method, layout, size: int, tiles: int, scene, state: tuple, scratches: list, out: tuple
) -> tuple:
    """The tiles of a run on ``len(scratches)`` threads, thread ``k`` stepping tiles ``k``,
    ``k + threads``, ... in its own scratch (the compiled loop holds no lock). Each tile's
    particles are stepped, and written to their own columns of the records, exactly as
    on one thread: a tile of independent particles reads nothing of another. Returns what
    one thread stepping every tile returns: the last tile's counts, or ``split`` where any
    tile of several blew up (the run is then made again as one tile, on one thread)."""
    threads = len(scratches)
    done = list(
        _pool(threads).map(
            lambda k: loop(method, layout, size, k, threads, scene, *state, scratches[k], *out),
            range(threads),
        )
    )
    if any(d[4] for d in done):
        return next(d for d in done if d[4])
    return done[(tiles - 1) % threads]


@dataclass
class DrivenRun:
    """What :func:`run` returns: the records (t (T,) s; x, v (T, n, 3), m and m/s), the
    counts of :class:`~truestep.reference_impl.integrate.Run`, the wall time of the
    stepping (s), ``extra`` (``energy_min``, ``energy_max`` in J when tracked) and
    ``rerun_whole``: whether a blow-up in one tile of several had the run made again as
    one tile (the wall time is that run's)."""

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    nfev: int
    steps: int
    status: str
    t_fail: float | None
    wall_s: float
    extra: dict[str, float] = field(default_factory=dict)
    rerun_whole: bool = False


def run(
    loop,
    method,
    layout,
    scene,
    x0: np.ndarray,
    v0: np.ndarray,
    h: float,
    n_steps: int,
    *,
    stages: int,
    planes: int,
    max_records: int = 2000,
    track_energy: bool = False,
    threads: int = 1,
) -> DrivenRun:
    """Step ``scene`` from ``x0``, ``v0`` ((n, 3), m and m/s) through ``n_steps`` steps of
    ``h`` s with ``loop`` (:func:`drive`) in ``layout``, in tiles of its ``size``
    particles; ``stages`` and ``planes`` size the scratch. Records and results are
    allocated before the timed call; with ``track_energy`` the scene is one tile and
    the energy is watched at every step. ``threads`` > 1 steps the tiles on that many
    threads at once (:func:`_on_threads`): the same numbers, bit for bit, as one thread."""
    n = len(x0)
    size = layout.size
    if track_energy:
        size = max(n, 1)
    marks = record_indices(n_steps, max_records)
    record = np.zeros(n_steps + 1, dtype=np.bool_)
    record[marks] = True
    slots = len(marks) + 1  # the state a failed check finds between records
    # written here, not only allocated: a fresh array's pages are mapped on first write,
    # which would then happen in the timed loop (at 1e6 particles, a third of its time)
    xs, vs, ts = np.full((slots, n, 3), np.nan), np.full((slots, n, 3), np.nan), np.full(slots, np.nan)
    X0, V0 = np.ascontiguousarray(x0.T, dtype=float), np.ascontiguousarray(v0.T, dtype=float)
    monitor = EnergyMonitor(np.array([math.inf, -math.inf])) if track_energy else unwatched()
    tiles = -(-max(n, 1) // max(1, min(size, max(n, 1))))
    threads = max(1, min(threads, tiles))
    scratches = [scratch(max(1, min(size, n)), stages, planes) for _ in range(threads)]
    state = (X0, V0, h, n_steps, record)
    out = (xs, vs, ts, monitor)
    start = time.perf_counter()
    if threads == 1:
        kept, steps, nfev, unstable, split = loop(
            method, layout, size, 0, 1, scene, *state, scratches[0], *out
        )
    else:
        kept, steps, nfev, unstable, split = _on_threads(
            loop, method, layout, size, tiles, scene, state, scratches, out
        )
    rerun = bool(split)
    if split:
        start = time.perf_counter()
        buffers = scratch(max(n, 1), stages, planes)
        kept, steps, nfev, unstable, split = loop(
            method, layout, max(n, 1), 0, 1, scene, *state, buffers, *out
        )
    wall = time.perf_counter() - start
    extra = (
        {"energy_min": float(monitor.bounds[0]), "energy_max": float(monitor.bounds[1])}
        if track_energy
        else {}
    )
    return DrivenRun(
        ts[:kept].copy(),
        xs[:kept].copy(),
        vs[:kept].copy(),
        int(nfev),
        int(steps),
        "unstable" if unstable else "ok",
        float(ts[kept - 1]) if unstable else None,
        wall,
        extra,
        rerun,
    )
