"""The simulation loop: a solver step, then the events that act between steps."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from truestep.reference_impl.solvers.base import Solver, SolverFailed

BLOWUP = 1e12
"""A state component beyond this magnitude counts as a blow-up (SI units throughout)."""
CHECK_EVERY = 64
"""Fixed steps between blow-up checks (and at the last step): a blow-up is found within
this many steps of the first non-finite state, without a check after every step."""


@dataclass
class Run:
    """What :func:`integrate` returns.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Recorded times, seconds; ``t[0]`` is the start.
    x : ndarray, shape (T, dim)
        The system's flat state at those times.
    nfev : int
        Derivative evaluations made by the solver.
    steps : int
        Solver steps taken.
    wall_s : float
        Seconds spent stepping (recording included, setup excluded).
    extra : dict of str to ndarray, shape (T, ...)
        The system's :meth:`~truestep.reference_impl.system.System.observe` at each record.
    status : str
        ``ok``; ``unstable`` if the state went non-finite or beyond ``BLOWUP``;
        ``solver-failed`` if a step's equations had no solution the solver found
        (:class:`~truestep.reference_impl.solvers.base.SolverFailed`).
    t_fail : float or None
        Time of the first step at which the state was found unstable (or the solver
        failed).
    message : str
        What the solver said when it stopped the run, or ``""``.
    """

    t: np.ndarray
    x: np.ndarray
    nfev: int
    steps: int
    wall_s: float
    extra: dict[str, np.ndarray]
    status: str = "ok"
    t_fail: float | None = None
    message: str = ""


def record_indices(n_steps: int, max_records: int) -> np.ndarray:
    """Step indices (``0..n_steps``) at which to record, at most ``max_records + 1``."""
    if n_steps <= max_records:
        return np.arange(n_steps + 1)
    return np.unique(np.linspace(0, n_steps, max_records + 1).round().astype(int))


def integrate(
    solver: Solver, t_end: float, dt: float, *, max_records: int = 2000,
    record_at: np.ndarray | None = None, on_step: Callable[[], None] | None = None,
    sample_at: np.ndarray | None = None,
) -> Run:
    """Step ``solver.system`` from its current time to ``t_end``.

    Fixed-step solvers take ``round((t_end - t0) / dt)`` steps of ``dt`` seconds; an
    adaptive solver takes steps of its own choosing, at most ``t_end - t`` each, and
    every accepted step is recorded. After each step the system's ``between_steps``
    runs (collisions, emitters, lifetimes). Stepping stops at the first non-finite or
    runaway state, which is recorded with status ``unstable``, or at a step the solver
    could not solve (status ``solver-failed``, with its message).

    ``record_at``: the step indices (``0..n``) a fixed-step run records, instead of
    :func:`record_indices`'s; ``on_step``: called after every accepted step of an adaptive
    solver (to keep its continuous extension, say); ``sample_at``: times (s) at which an
    adaptive solver with a continuous extension also records the run between its steps.

    An adaptive solver with a continuous extension (``solver.dense()``) stops each step at
    the first event the system watches for (:meth:`~truestep.reference_impl.system.System.event_watch`:
    a particle reaching a plane, friction stopping it), and the passes act there. A step
    cut at an event is not recorded when ``sample_at`` is given (its state is the instant
    of a jump, two-valued); the samples around it are.
    """
    system = solver.system
    t0 = system.get_time()
    ts, xs, obs = [t0], [system.get_state()], [system.observe()]
    status, t_fail, steps, message = "ok", None, 0, ""
    start = time.perf_counter()
    if solver.adaptive:
        t = t0
        slack = 1e-12 * max(1.0, abs(t_end))  # a remainder below this is round-off in t
        # ``extra`` keeps the keys of the first observation: if it has none, nothing
        # observed later would be kept, so the system is not asked again.
        observed = bool(obs[0])
        locate = callable(getattr(solver, "dense", None))
        grid = np.asarray(sample_at, float) if sample_at is not None and locate else None
        next_sample = 0
        if locate:
            system.located = True
            system.rest_height = float(getattr(solver, "atol", 0.0))
        while t_end - t > slack:
            watch = system.event_watch() if locate else None
            g0 = watch(system.get_state()) if watch is not None else None
            try:
                h = solver.step(t_end - t)
            except FloatingPointError as err:
                status, t_fail, message = "unstable", t, str(err)
                break
            except SolverFailed as err:
                status, t_fail, message = "solver-failed", t, str(err)
                break
            if on_step is not None:
                on_step()
            full = h
            if watch is not None:
                h = _stop_at_event(system, solver, watch, g0, t, h)
            if grid is not None:  # the run between steps, by the solver's continuous extension
                dense = solver.dense()
                while next_sample < len(grid) and grid[next_sample] < t + h - slack:
                    if grid[next_sample] > t + slack:
                        ts.append(float(grid[next_sample]))
                        xs.append(dense(grid[next_sample]))
                        if observed:
                            obs.append(system.observe())
                    next_sample += 1
            system.between_steps(h)
            steps += 1
            t = system.get_time()
            x = system.get_state()
            if h == full or grid is None or t_end - t <= slack:  # not a step cut at an event
                ts.append(t)
                xs.append(x)
                if observed:
                    obs.append(system.observe())
            if not _well_inside(x) and not _finite(x):
                if ts[-1] != t:
                    ts.append(t)
                    xs.append(x)
                    if observed:
                        obs.append(system.observe())
                status, t_fail = "unstable", t
                break
    else:
        n_steps = round((t_end - t0) / dt)
        marks = np.zeros(n_steps + 1, dtype=bool)
        marks[record_indices(n_steps, max_records) if record_at is None
              else np.asarray(record_at, int)] = True
        checked = 1  # records before this index are known finite
        for i in range(1, n_steps + 1):
            try:
                solver.step(dt)
            except FloatingPointError as err:
                status, t_fail, message = "unstable", system.get_time(), str(err)
                break
            except SolverFailed as err:
                status, t_fail, message = "solver-failed", system.get_time(), str(err)
                break
            system.between_steps(dt)
            steps = i
            if marks[i]:
                ts.append(system.get_time())
                xs.append(system.get_state())
                obs.append(system.observe())
            if i % CHECK_EVERY == 0 or i == n_steps:
                x = xs[-1] if marks[i] else system.get_state()
                if _finite(x):
                    checked = len(xs)
                    continue
                bad = next((k for k in range(checked, len(xs)) if not _finite(xs[k])), None)
                if bad is None:  # first seen between records: record it
                    ts.append(system.get_time())
                    xs.append(x)
                    obs.append(system.observe())
                else:
                    del ts[bad + 1 :], xs[bad + 1 :], obs[bad + 1 :]
                status, t_fail = "unstable", ts[-1]
                break
    wall = time.perf_counter() - start
    extra = {k: np.array([o[k] for o in obs]) for k in obs[0]}
    return Run(np.array(ts), np.array(xs), solver.nfev, steps, wall, extra, status, t_fail,
               message)


EVENT_PRECISION = 1e-12
"""An event is located to this fraction of the run's time (at least 1 s of it)."""


def _stop_at_event(system, solver, watch, g0: np.ndarray, t0: float, h: float) -> float:
    """Cut the step just taken back to its first event, if one happened in it.

    The components of ``watch`` that went from ``>= 0`` (at the start, ``g0``) to ``< 0``
    (at the end) mark events; the solver's continuous extension (``solver.dense()``) is
    bisected, on those components alone (``watch.focus``), for the first time any of
    them is below zero, to :data:`EVENT_PRECISION`, and the system is set to the state
    just there. Returns the step kept (s). An event at the very start of the step is
    left to the pass at its end (no step of zero length)."""
    g1 = watch(system.get_state())
    crossing = (g0 >= 0) & (g1 < 0)
    if not crossing.any():
        return h
    dense = solver.dense()
    index, values = watch.focus(crossing)
    lo, hi = t0, t0 + h
    precision = EVENT_PRECISION * max(1.0, abs(t0 + h))
    while hi - lo > precision:
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if (values(dense(mid, index)) < 0).any():
            hi = mid
        else:
            lo = mid
    if hi - t0 <= precision:
        return h
    system.set_state(dense(hi), hi)
    return hi - t0


def _finite(x: np.ndarray) -> bool:
    """Every component finite and within :data:`BLOWUP` (NaN fails both comparisons)."""
    return bool(x.size == 0 or (-BLOWUP < x.min() and x.max() < BLOWUP))


def _well_inside(x: np.ndarray) -> bool:
    """A one-reduction sufficient test for :func:`_finite`, for the check after every step.

    ``x . x < BLOWUP**2`` means every ``|x_i| < BLOWUP`` (rounding is monotonic, so a
    component at the bound makes the sum reach ``BLOWUP**2`` too); NaN, infinity or an
    overflowing sum (numpy warns of it) fail it, and then :func:`_finite` decides.
    """
    return bool(np.dot(x, x) < BLOWUP * BLOWUP)
