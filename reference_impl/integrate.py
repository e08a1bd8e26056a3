"""The simulation loop: a solver step, then the events that act between steps."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

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
    solver: Solver,
    t_end: float,
    dt: float,
    *,
    max_records: int = 2000,
    record_at: np.ndarray | None = None,
    on_step: Callable[[], None] | None = None,
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

    An adaptive step ends, at the latest, when the system's passes are next scheduled to
    act (:meth:`~truestep.reference_impl.system.System.next_pass_time`: an emitter's
    frame), so that they act at their instant. An adaptive solver with a continuous
    extension (``solver.dense()``) also stops each step at
    the first event the system watches for (:meth:`~truestep.reference_impl.system.System.event_watch`:
    a particle reaching a plane, friction stopping it), and the passes act there. A step
    cut at an event is not recorded when ``sample_at`` is given (its state is the instant
    of a jump, two-valued); the samples around it are.
    """
    system = solver.system
    t0 = system.get_time()
    first = system.observe()
    # An adaptive run keeps the keys of the first observation: if it has none, nothing
    # observed later would be kept, so the system is not asked again.
    rec = _Records([t0], [system.get_state()], [first], observed=bool(first) or not solver.adaptive)
    start = time.perf_counter()
    if solver.adaptive:
        status, t_fail, steps, message = _run_adaptive(solver, t_end, rec, on_step, sample_at)
    else:
        n_steps = round((t_end - t0) / dt)
        marks = np.zeros(n_steps + 1, dtype=bool)
        marks[record_indices(n_steps, max_records) if record_at is None else np.asarray(record_at, int)] = (
            True
        )
        status, t_fail, steps, message = _run_fixed(solver, dt, marks, rec)
    wall = time.perf_counter() - start
    extra = {k: np.array([o[k] for o in rec.obs]) for k in rec.obs[0]}
    return Run(np.array(rec.ts), np.array(rec.xs), solver.nfev, steps, wall, extra, status, t_fail, message)


@dataclass
class _Records:
    """A run's records so far: times (s), states and observations (each a list, one entry a
    record); ``observed``: whether to ask the system for an observation at each."""

    ts: list[float]
    xs: list[np.ndarray]
    obs: list[dict]
    observed: bool

    def add(self, system, t: float, x: np.ndarray) -> None:
        self.ts.append(t)
        self.xs.append(x)
        if self.observed:
            self.obs.append(system.observe())

    def cut_after(self, k: int) -> None:
        """Keep the records up to index ``k``."""
        del self.ts[k + 1 :], self.xs[k + 1 :], self.obs[k + 1 :]


Ending = tuple[str, float | None, int, str]
"""How a run ended: status, time of the failure (s) or None, steps taken, message."""


def _run_adaptive(
    solver: Solver,
    t_end: float,
    rec: _Records,
    on_step: Callable[[], None] | None,
    sample_at: np.ndarray | None,
) -> Ending:
    """The adaptive solver's steps to ``t_end`` (see :func:`integrate`)."""
    system: Any = solver.system  # a system that may take ``located`` and ``rest_height``
    t = system.get_time()
    slack = 1e-12 * max(1.0, abs(t_end))  # a remainder below this is round-off in t
    locate = callable(getattr(solver, "dense", None))
    grid = np.asarray(sample_at, float) if sample_at is not None and locate else None
    next_sample, steps = 0, 0
    if locate:
        system.located = True
        system.rest_height = float(getattr(solver, "atol", 0.0))
    while t_end - t > slack:
        watch = system.event_watch() if locate else None
        g0 = watch(system.get_state()) if watch is not None else None
        scheduled = system.next_pass_time()
        try:
            h = solver.step((scheduled if t + slack < scheduled < t_end else t_end) - t)
        except FloatingPointError as err:
            return "unstable", t, steps, str(err)
        except SolverFailed as err:
            return "solver-failed", t, steps, str(err)
        if on_step is not None:
            on_step()
        full = h
        if watch is not None:
            h = _stop_at_event(system, solver, watch, cast(np.ndarray, g0), t, h)
        if grid is not None:  # the run between steps, by the solver's continuous extension
            next_sample = _sample_between(solver, rec, grid, next_sample, t, t + h, slack)
        system.between_steps(h)
        steps += 1
        t = system.get_time()
        x = system.get_state()
        if h == full or grid is None or t_end - t <= slack:  # not a step cut at an event
            rec.add(system, t, x)
        if not _well_inside(x) and not _finite(x):
            if rec.ts[-1] != t:
                rec.add(system, t, x)
            return "unstable", t, steps, ""
    return "ok", None, steps, ""


def _sample_between(
    solver: Solver, rec: _Records, grid: np.ndarray, k: int, t0: float, t1: float, slack: float
) -> int:
    """Record the samples of ``grid`` from index ``k`` inside the step ``(t0, t1)`` (s), by the
    solver's continuous extension; returns the index of the first sample after the step."""
    dense = cast(Any, solver).dense()  # an adaptive solver with a continuous extension
    while k < len(grid) and grid[k] < t1 - slack:
        if grid[k] > t0 + slack:
            rec.add(solver.system, float(grid[k]), dense(grid[k]))
        k += 1
    return k


def _run_fixed(solver: Solver, dt: float, marks: np.ndarray, rec: _Records) -> Ending:
    """``len(marks) - 1`` fixed steps of ``dt`` (s), recording where ``marks`` says, checking
    for a blow-up every :data:`CHECK_EVERY` steps and at the end."""
    system = solver.system
    n_steps = len(marks) - 1
    checked = 1  # records before this index are known finite
    for i in range(1, n_steps + 1):
        try:
            solver.step(dt)
        except FloatingPointError as err:
            return "unstable", system.get_time(), i - 1, str(err)
        except SolverFailed as err:
            return "solver-failed", system.get_time(), i - 1, str(err)
        system.between_steps(dt)
        if marks[i]:
            rec.add(system, system.get_time(), system.get_state())
        if i % CHECK_EVERY == 0 or i == n_steps:
            x = rec.xs[-1] if marks[i] else system.get_state()
            if _finite(x):
                checked = len(rec.xs)
                continue
            bad = next((k for k in range(checked, len(rec.xs)) if not _finite(rec.xs[k])), None)
            if bad is None:  # first seen between records: record it
                rec.add(system, system.get_time(), x)
            else:
                rec.cut_after(bad)
            return "unstable", rec.ts[-1], i, ""
    return "ok", None, n_steps, ""


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
