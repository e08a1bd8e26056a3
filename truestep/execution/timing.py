"""How a row's runs are made and timed, inside its child process: the measured run
(watched at every step where the adapter can), a warm-up, the timed runs, and how they
combine into the row's trajectory (:func:`merged`). The measured run and the timed runs
may run in one process (:func:`simulate_timed`) or in two (the measured run on a core the
timed runs do not need: :func:`truestep.execution.runner.run_matrix`)."""

from __future__ import annotations

import dataclasses
import statistics
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from truestep.adapters import get_adapter
from truestep.adapters.base import Trajectory
from truestep.cases.case import Case


@dataclass(frozen=True)
class Timing:
    """How runs are timed: a short warm-up, a first timed run (whose trajectory is kept),
    then more timed runs until the timing is stable.

    The warm-up runs the same scene, engine and method for :attr:`warmup_fraction` of the
    duration (JIT compilation, caches, lazy imports, first-call costs). A first run
    shorter than :attr:`min_total_s` is repeated until the timed runs add up to
    :attr:`min_total_s` and number at least :attr:`min_repeats` (at most
    :attr:`max_repeats`): short runs are the ones scheduling and timer noise distort most.
    A run up to :attr:`long_run_s` is timed twice, so that its spread is known; a longer
    one once (one run of that length is not moved by noise beyond a few percent). The
    reported wall time is the median of the timed runs, and ``wall_s_spread`` half their
    interquartile range (:func:`spread`). Neither the warm-up nor scene building is
    timed. How many runs are timed depends on the machine's speed; nothing else does.
    """

    min_total_s: float = 0.05
    min_repeats: int = 3
    max_repeats: int = 25
    long_run_s: float = 0.5
    warmup_fraction: float = 0.05
    timed: bool = True
    """``False``: the row's engine makes no speed claim on its device
    (:func:`makes_speed_claim`): one run, the measured one, and nothing timed."""
    apart: bool = True
    """Whether a sweep's measured runs may run in a process of their own, on a core the
    timed runs do not use (:func:`truestep.execution.runner.split_sweep`): worth a second
    process (a fork and an exit of some ms each) when rows are long enough to pay it."""

    def runs_after(self, first_s: float) -> int:
        """How many timed runs in all, after a first one of ``first_s`` seconds."""
        if first_s >= self.long_run_s:
            return 1
        if first_s >= self.min_total_s:
            return 2
        wanted = int(np.ceil(self.min_total_s / max(first_s, 1e-9)))
        return int(np.clip(wanted, self.min_repeats, self.max_repeats))


QUICK_TIMING = Timing(min_total_s=0.002, min_repeats=3, max_repeats=5, long_run_s=0.002, apart=False)
"""``--quick`` runs time a row of 2 ms or more once, a shorter one 3 to 5 times (a single
timing of a short row moves by a large factor from run to run: a CI's ``--time-against``
needs the median and the spread there, at a small cost a row); its rows are measured
and timed in one process."""


UNTIMED = Timing(timed=False)
"""How the rows of an engine that makes no speed claim run: once, untimed, beside other
work (their ``repeats`` is 0; the ``wall_s`` they carry is that run's, taken on a busy machine)."""


def makes_speed_claim(adapter) -> bool:
    """Whether an engine's wall times are a speed claim on the device it runs on: its
    optional ``speed_claim`` attribute (default true). MuJoCo Warp on Warp's CPU device says
    no: there it is a correctness peer of MuJoCo C, a GPU pipeline stepped one thread at a
    time. Rows of an engine that makes none are run once, untimed, on the cores the timed
    runs leave free (:func:`run_matrix`)."""
    return bool(getattr(adapter, "speed_claim", True))


def spread(walls: list[float]) -> float:
    """Half the interquartile range of timed runs' wall times, s (half their range with
    fewer than four runs; NaN for one run): how far the median may move with noise."""
    if len(walls) < 2:
        return float("nan")
    if len(walls) < 4:
        return (max(walls) - min(walls)) / 2
    q25, q75 = np.percentile(walls, [25, 75])
    return float(q75 - q25) / 2


@dataclass(frozen=True)
class End:
    """Where a run ended, enough to tell two runs of one scene apart (:func:`end_of`):
    its status, work counts and last record (time, positions, velocities)."""

    status: str
    counts: tuple[int, int]
    """Evaluations and steps (how many records a run kept is not where it ended)."""
    last: tuple[np.ndarray, ...]


def end_of(traj: Trajectory) -> End:
    """The :class:`End` of a run: status, ``(nfev, steps)`` and the last record."""
    last = [traj.t[-1:], traj.x[-1:]] + ([traj.v[-1:]] if traj.v is not None else [])
    return End(traj.status, (traj.nfev, traj.steps), tuple(np.array(a) for a in last))


def same_end(a: End, b: End) -> bool:
    """Whether two runs of the same scene ended in the same state, bit for bit (runs that
    did not finish are only checked to have failed alike: a run watched at every step
    finds a blow-up earlier than one checked every few steps)."""
    if a.status != b.status:
        return False
    if a.status != "ok":
        return True
    if a.counts != b.counts or len(a.last) != len(b.last):
        return False
    return all(np.array_equal(p, q, equal_nan=True) for p, q in zip(a.last, b.last, strict=True))


NOT_REPEATABLE = "not repeatable: timed runs of the same scene ended in different states"
"""The note of a row whose engine gave another end state when run again (an engine that is
not deterministic): its numbers may differ from run to run and machine to machine."""


def watches_every_step(adapter) -> bool:
    """Whether ``adapter.simulate`` takes ``monitor=True`` (Adapter protocol, item 9)."""
    import inspect

    try:
        return "monitor" in inspect.signature(adapter.simulate).parameters
    except (TypeError, ValueError):
        return False


WATCHED_STEP_S = 1e-3
"""The shortest step (s: a watched run's wall time over its steps) that hides a light
watch (:func:`light_watch`: a copy of the state a step, a few microseconds; watched and
plain runs of Drake's such rows differ by about 1%, the noise of one run:
``benchmarks/light_watch.py``): a long row (:attr:`Timing.long_run_s`) whose steps take this long is timed
from its watched run, not stepped once more. An adapter whose watch costs less says its own
(:func:`watched_step_s`)."""


def light_watch(adapter, method: str | None = None) -> bool:
    """Whether ``adapter`` watches every step (:func:`watches_every_step`) and says that
    watching ``method`` adds no more than a copy of the state a step to the same stepping,
    inside its timed region (its optional ``light_watch``, Adapter protocol item 9:
    ``True`` for every method, or the methods it holds for): a long row of long steps is
    then timed from its watched run (:func:`timed_from_watched`). Without ``method``:
    whether it holds for every method."""
    if not watches_every_step(adapter):
        return False
    said = getattr(adapter, "light_watch", False)
    if isinstance(said, bool):
        return said
    return method is not None and method in said


def watched_step_s(adapter, method: str) -> float:
    """The shortest step (s) of ``method`` whose watch ``adapter`` says is hidden in it:
    its optional ``watched_step_s`` (Adapter protocol item 9: one number, or one for each
    method), else :data:`WATCHED_STEP_S`."""
    said = getattr(adapter, "watched_step_s", WATCHED_STEP_S)
    if isinstance(said, Mapping):
        said = said.get(method, WATCHED_STEP_S)
    return float(said)


@dataclass
class TimedRuns:
    """What the timed runs of one row give (:func:`timed_runs`): each one's wall time (s),
    where each ended (:class:`End`), and the first one's ``path``."""

    walls: list[float]
    ends: list[End]
    path: Any = None


TIMED_RECORDS = 2
"""The records a timed run of a fixed-step method keeps when the row is measured from
another run (its start, middle and end: :func:`~truestep.reference_impl.integrate.record_indices`):
the time of a speed claim is the engine's stepping, not the harness reading its state back
at every record (an engine stepped from Python paid a call per record, many times its
stepping on a small net recorded at every step). An error-controlled method keeps the
case's records: where it records may decide where it stops."""


def timed_case(adapter, case: Case, method: str) -> Case:
    """The case a timed run runs when the row is measured from another run: the case with
    :data:`TIMED_RECORDS` records for a fixed-step method, the case itself for an
    error-controlled one."""
    if method in getattr(adapter, "adaptive_methods", ()):
        return case
    return dataclasses.replace(case, max_records=min(case.max_records, TIMED_RECORDS))


def timed_runs(
    adapter,
    case: Case,
    method: str,
    dt: float,
    timing: Timing,
    *,
    warm_up: bool,
    lean: bool = False,
    known_s: float | None = None,
) -> tuple[Trajectory, TimedRuns]:
    """The timed runs of one row (:meth:`Timing.runs_after`), none of them watched, after a
    short warm-up when ``warm_up`` (:attr:`Timing.warmup_fraction` of the duration: JIT
    compilation, caches, first-call costs); the first run's trajectory and all of them.
    A run that did not finish is not repeated. ``lean``: the row is measured from another
    run, and the timed runs keep few records (:func:`timed_case`). ``known_s``: the wall
    time of that run (the same steps, watched, so no faster), s: how many runs to time is
    decided from the faster of it and the first timed run, so that a first run the machine
    held up (a short row timed many times too long on a busy CI) is not the row's only sample."""
    if lean:
        case = timed_case(adapter, case, method)
    if warm_up:
        _warm_up(adapter, case, method, dt, timing)
    first = adapter.simulate(case, method, dt)
    runs = TimedRuns([first.wall_s], [end_of(first)], first.path)
    if first.status == "ok":
        for _ in range(timing.runs_after(min(first.wall_s, known_s or np.inf)) - 1):
            again = adapter.simulate(case, method, dt)
            runs.walls.append(again.wall_s)
            runs.ends.append(end_of(again))
    return first, runs


def _warm_up(adapter, case: Case, method: str, dt: float, timing: Timing) -> None:
    """A short untimed run of the row's scene (:attr:`Timing.warmup_fraction` of its
    duration, at least a step): JIT compilation, caches, first-call costs."""
    short = dataclasses.replace(
        case, duration=max(case.duration * timing.warmup_fraction, min(dt, case.duration))
    )
    adapter.simulate(short, method, dt)


def timed_from_watched(
    adapter, case: Case, method: str, dt: float, timing: Timing, *, warm_up: bool
) -> Trajectory:
    """A row of an adapter whose watch is light (:func:`light_watch`), made where the timed
    runs are made: the watched run, after a short warm-up when ``warm_up``. Where it ended
    ``ok`` and was long (:attr:`Timing.long_run_s`, the length timed once) of steps of
    :func:`watched_step_s` or more, it is also the row's one timed run: what the watch
    added is within the noise of one run, and a second stepping of seconds would buy nothing.
    A method whose ``watched_step_s`` is 0 says its watched run is its plain run, the same
    code in the timed region: a long run of it is the row's timed run however it ended
    (a run that failed stops at the same step watched or not).
    Otherwise the timed runs follow as for any row (:func:`timed_runs`; the watched run
    warmed the process up), each checked to end where it did (:func:`merged`)."""
    if warm_up:
        _warm_up(adapter, case, method, dt, timing)
    traj = measured_run(adapter, case, method, dt)
    step_s = watched_step_s(adapter, method)
    long_steps = traj.status == "ok" and traj.wall_s >= step_s * max(traj.steps, 1)
    if traj.wall_s >= timing.long_run_s and (long_steps or step_s == 0.0):
        return merged(traj, TimedRuns([traj.wall_s], [end_of(traj)], traj.path))
    _, runs = timed_runs(adapter, case, method, dt, timing, warm_up=False, lean=True, known_s=traj.wall_s)
    return merged(traj, runs)


def merged(traj: Trajectory, runs: TimedRuns) -> Trajectory:
    """The measured run ``traj`` with the timing of ``runs``: ``wall_s`` their median,
    ``repeats`` their number, ``wall_s_spread`` their :func:`spread`; and
    :data:`NOT_REPEATABLE` in its message if any of them ended elsewhere than it did."""
    ends = end_of(traj)
    traj.wall_s = statistics.median(runs.walls)
    traj.path = runs.path or traj.path
    if not all(same_end(ends, e) for e in runs.ends):
        traj.message = "; ".join(m for m in (traj.message, NOT_REPEATABLE) if m)
    traj.extra["repeats"] = np.array(len(runs.walls))
    traj.extra["wall_s_spread"] = np.array(spread(runs.walls))
    return traj


def measured_run(adapter, case: Case, method: str, dt: float) -> Trajectory:
    """The run a row is measured from, untimed: watched at every step where the adapter
    can (``simulate(..., monitor=True)``: the energy's extremes over every step)."""
    if not watches_every_step(adapter):
        return adapter.simulate(case, method, dt)
    watched: Any = adapter.simulate  # takes monitor= where watches_every_step says so
    return watched(case, method, dt, monitor=True)


def simulate_timed(
    engine: str, case: Case, method: str, dt: float, timing: Timing, *, warm_up: bool = True
) -> Trajectory:
    """Make the run the row is measured from, then time; runs inside the child process.

    The measured run (:func:`measured_run`) is not timed; it also warms the process up
    (compilation, caches, first-call costs) for the timed runs. An adapter that cannot
    watch every step is warmed up instead by a short run (unless ``warm_up`` is false:
    this process has just run the same case and method), and its first timed run is the
    measured run. The timed runs follow (:func:`timed_runs`), and every one of them is
    checked to end where the measured run did, bit for bit (:func:`merged`). An adapter
    whose watch is light times a long row of long steps from its measured run
    (:func:`timed_from_watched`). With an untimed ``timing`` (:data:`UNTIMED`) the
    measured run is the only one, and its row's ``repeats`` is 0.
    """
    adapter = get_adapter(engine)
    if not timing.timed:  # no speed claim: the measured run, once
        once = measured_run(adapter, case, method, dt)
        once.extra["repeats"] = np.array(0)
        once.extra["wall_s_spread"] = np.array(np.nan)
        return once
    if light_watch(adapter, method):
        return timed_from_watched(adapter, case, method, dt, timing, warm_up=warm_up)
    monitor = watches_every_step(adapter)
    traj = measured_run(adapter, case, method, dt) if monitor else None
    first, runs = timed_runs(
        adapter,
        case,
        method,
        dt,
        timing,
        warm_up=warm_up and not monitor,
        lean=monitor,
        known_s=None if traj is None else traj.wall_s,
    )
    return merged(first if traj is None else traj, runs)
