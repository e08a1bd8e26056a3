"""Expand case x engine x method x dt, run each pair in isolation, measure, tabulate."""

from __future__ import annotations

import contextlib
import itertools
import os
import sys
import time
import traceback
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from truestep.adapters import (
    PREPARE_ALL_S,
    PREPARE_S,
    PluginFailed,
    adapter_class,
    get_adapter,
    plugin_answer,
    truestep_target,
)
from truestep.adapters.base import Trajectory, duplicate_of
from truestep.adapters.devices import engine_device
from truestep.cases.case import Case
from truestep.execution.progress import Progress
from truestep.execution.sweep_groups import group_sweeps, weight
from truestep.execution.sweep_job import SweepJob, host_name
from truestep.execution.timing import (
    NOT_REPEATABLE as NOT_REPEATABLE,
)
from truestep.execution.timing import (
    QUICK_TIMING,
    UNTIMED,
    TimedRuns,
    Timing,
    light_watch,
    makes_speed_claim,
    measured_run,
    merged,
    simulate_timed,
    timed_runs,
    watches_every_step,
)
from truestep.execution.timing import (
    spread as spread,
)
from truestep.measures import metrics
from truestep.measures.trust import checked
from truestep.numerics import own_run
from truestep.reference_impl.model import ParticleModel
from truestep.runtime import faults
from truestep.runtime.isolation import Call, Lanes, Outcome, run_isolated, untimed_workers
from truestep.runtime.time_limit import TimeLimitExceeded, time_limit
from truestep.tables.spec import RESULTS, writable

if TYPE_CHECKING:
    from truestep.execution.cluster import Cluster
    from truestep.execution.journal import Journal

RESULT_COLUMNS = RESULTS.names
"""The columns of ``results.csv`` (:data:`truestep.tables.spec.RESULTS`); one column per named
property follows them."""
MACHINE_COLUMNS = RESULTS.where(machine=True)
"""The columns of ``results.csv`` that depend on the machine and its load (timings, the
host) or on where the case file lies (``case_source`` of a file outside the library).
Every other column is the same, bit for bit, for the same revision and package versions on any
machine (:mod:`truestep.numerics`), except the message of a row whose engine is not
deterministic (:data:`NOT_REPEATABLE`)."""


MEASURED = ("ok", "stalled")
"""The statuses of a run that finished, whose error and properties are measured (a
``stalled`` row's are those of its frozen particles: :mod:`truestep.measures.stalled`)."""


def measure(case: Case, traj: Trajectory) -> dict[str, float]:
    """Every metric of one run, from its trajectory and the case's reference."""
    from truestep.measures.properties import PROPERTIES

    out: dict[str, float] = {}
    exact = metrics.exact_for(case, traj.t) if traj.status in MEASURED else None
    if exact is not None:
        out["error"] = metrics.position_error(case, traj, exact)
        out["error_final"] = metrics.position_error(case, traj, exact, norm="final")
        out["error_v"] = metrics.position_error(case, traj, exact, part="v")
    else:
        out["error"] = out["error_final"] = out["error_v"] = np.nan
    drift, drift_end = metrics.energy_drift(case, traj, exact)
    out["energy_drift"], out["energy_drift_final"] = drift, drift_end
    for name in case.properties:
        out[name] = PROPERTIES[name](case, traj) if traj.status in MEASURED else np.nan
    return out


TRACE_POINTS = 400
"""Energy traces kept for the report are thinned to at most this many points."""


def energy_trace(traj: Trajectory) -> tuple[np.ndarray, np.ndarray] | None:
    """Times (s) and energies (J), thinned to :data:`TRACE_POINTS`, or ``None``."""
    if traj.energy is None or len(traj.t) < 2:
        return None
    keep = np.unique(np.linspace(0, len(traj.t) - 1, TRACE_POINTS).round().astype(int))
    return traj.t[keep], traj.energy[keep]


PARTS = ("both", "measured", "timed")
"""What a sweep's process runs at each step: the whole row (:func:`simulate_timed`), or one
of its halves when they run apart (:func:`split_sweep`): the measured run alone
(:func:`measured_run`, a :class:`Trajectory`) or the timed runs alone (:func:`timed_runs`, a
:class:`TimedRuns`)."""


def simulate_sweep(
    engine: str, case: Case, method: str, dts: list[float], timing: Timing, part: str = "both"
) -> list[Trajectory | TimedRuns | Outcome | str]:
    """:func:`simulate_timed` at every step of a sweep, in one child process (or the
    ``part`` of it named in :data:`PARTS`).

    Each entry is the step's Trajectory (or TimedRuns), the error message of an exception
    it raised, or a ``timeout`` :class:`Outcome` for a step that ran past the case's
    ``timeout`` (the other steps still run; a step stuck in compiled code that no signal
    interrupts is left to the process's own timeout, :func:`run_sweep`). Runs of one case,
    engine and method share a process: the engine's first-use costs are paid once, and no
    engine state outlives a run (every adapter builds and tears down its scene per run).
    The first step that runs warms the process up for all of them.
    """
    out: list[Trajectory | TimedRuns | Outcome | str] = []
    for dt in dts:
        warm = any(isinstance(o, (Trajectory, TimedRuns)) for o in out)
        try:
            with time_limit(case.timeout_s, f"the run at {dt:g}"):
                if part == "measured":
                    out.append(measured_run(get_adapter(engine), case, method, dt))
                elif part == "timed":
                    out.append(
                        timed_runs(
                            get_adapter(engine), case, method, dt, timing, warm_up=not warm, lean=True
                        )[1]
                    )
                else:
                    out.append(simulate_timed(engine, case, method, dt, timing, warm_up=not warm))
        except TimeLimitExceeded as err:  # this step's timeout row; the sweep goes on
            out.append(Outcome("timeout", message=str(err)))
        except Exception as err:  # a row that says so; the sweep goes on
            tb = traceback.extract_tb(err.__traceback__)
            where = f" at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else ""
            out.append(f"{type(err).__name__}: {err}{where}")
    return out


def simulate_sweeps(sweeps: list[tuple]) -> list[list[Trajectory | TimedRuns | Outcome | str]]:
    """:func:`simulate_sweep` of each of ``sweeps`` (its arguments), one after another in
    one child process (:mod:`truestep.execution.sweep_groups`): each sweep's entries as
    :func:`simulate_sweep` gives them alone."""
    return [simulate_sweep(*args) for args in sweeps]


def split_sweep(engine: str, timing: Timing, method: str | None = None) -> bool:
    """Whether a sweep's measured runs go apart from its timed runs (:data:`PARTS`): for an
    engine that makes a speed claim and watches every step, whose measured run is a
    second stepping of every row, where the timing allows it (:attr:`Timing.apart`),
    unless its watch of ``method`` is light (:func:`~truestep.execution.timing.light_watch`:
    its sweeps run whole where the timed runs run, a long row of long steps timed from its
    watched run). Apart, it is untimed work on a core of its own while
    the timed runs keep theirs, and the row's numbers are the same
    (:func:`~truestep.execution.timing.merged`)."""
    adapter = get_adapter(engine)
    return (
        timing.timed
        and timing.apart
        and makes_speed_claim(adapter)
        and watches_every_step(adapter)
        and not light_watch(adapter, method)
    )


def joined(measured: Outcome, timed: Outcome) -> Outcome:
    """The outcome of a whole sweep from those of its two halves (:func:`split_sweep`):
    each step the measured run's failure, else the timed runs' failure, else the measured
    run with the timed runs' timing. A half whose process did not end ``ok`` makes the
    whole not ``ok`` (its steps are then run again one by one, :func:`sweep_rows`)."""
    for half in (measured, timed):
        if half.status != "ok":
            return half
    steps = []
    for m, r in zip(measured.value, timed.value, strict=True):
        fine = isinstance(m, Trajectory) and isinstance(r, TimedRuns)
        steps.append(merged(m, r) if fine else m if not isinstance(m, Trajectory) else r)
    return Outcome("ok", value=steps, output=(measured.output + timed.output).strip())


def unreadable(row: dict) -> None:
    """A row holding a value no results table may hold (a negative error, a fraction of a
    count, an infinite drift: :func:`truestep.tables.io.check_rows`' bounds, from an
    adapter's or a case's own measure) becomes ``crashed``, naming the column and the value,
    and that cell is left empty: what ``run`` writes, ``gate`` reads."""
    from truestep.tables.spec import RESULTS

    for c in RESULTS.columns:
        value = row.get(c.name)
        if c.least is None or value is None or isinstance(value, str):
            continue
        try:
            v = float(value)
        except (TypeError, ValueError, OverflowError):
            v = float("inf")
        bad = np.isinf(v) or v < c.least or (c.most is not None and v > c.most)
        bad = bad or (c.whole and np.isfinite(v) and v != round(v))
        if bad:
            row[c.name] = np.nan
            said = f"the run gave {c.name} = {v:.6g}, not a value a results table holds"
            row.update(status="crashed", message="; ".join(m for m in (row.get("message"), said) if m))


def row_from(
    case: Case,
    engine: str,
    method: str,
    dt: float,
    *,
    adaptive: bool,
    outcome: Trajectory | Outcome | str,
    traces: dict | None = None,
) -> dict:
    """One row of ``results.csv`` from what a run gave: a Trajectory, an exception's
    message (``crashed``) or an isolation outcome that is not ``ok``.

    If ``traces`` is given, the run's thinned energy trace is stored in it under
    ``(case, engine, method, dt_kind, dt)``.
    """
    row = {
        "case": case.name,
        "engine": engine,
        "method": method,
        "dt": dt,
        "dt_kind": "tolerance" if adaptive else "step",
        "device": engine_device(engine),
    }
    if isinstance(outcome, str):
        row.update(status="crashed", message=outcome[:MESSAGE_CHARS])
        return row
    if isinstance(outcome, Outcome):
        row.update(status=outcome.status, message=with_output(outcome.message, outcome.output))
        return row
    traj = checked(
        outcome, case.particles.n if isinstance(case.scene, ParticleModel) else None, duration=case.duration
    )
    if isinstance(traj, str):  # the adapter broke its contract: this row, not the run
        row.update(status="crashed", message=traj)
        return row
    row.update(
        nfev=traj.nfev,
        steps=traj.steps,
        wall_s=traj.wall_s,
        wall_s_spread=float(traj.extra.get("wall_s_spread", np.nan)),
        repeats=int(traj.extra.get("repeats", 0)),
        path=str(traj.path)[:MESSAGE_CHARS],
    )
    timed_out = _MEASURE_TIMED_OUT.get(case.file)
    try:
        if timed_out:
            raise TimeLimitExceeded(timed_out)
        with time_limit(case.timeout_s, "measuring the run (exact solution included)"):
            if traj.status == "ok" and (failed := _motion_failure(case, traj)) is not None:
                traj.status, traj.t_fail = "unstable", failed.t
                traj.message = "; ".join(m for m in (traj.message, failed.reason) if m)
            if traj.status == "ok" and (frozen := _stalled(case, engine, traj)) is not None:
                traj.status = "stalled"
                traj.message = "; ".join(m for m in (traj.message, frozen) if m)
            row.update(status=traj.status, t_fail=traj.t_fail, message=str(traj.message)[:MESSAGE_CHARS])
            row.update(measure(case, traj))
            unreadable(row)
    except TimeLimitExceeded as err:  # a hang on case data: this case's rows, not the run's
        _MEASURE_TIMED_OUT[case.file] = str(err)
        row.update(status="timeout", message=str(err))
    except Exception as err:  # measuring this run failed: this row says so, the run goes on
        row.update(
            status="crashed", message=f"measuring the run failed: {type(err).__name__}: {str(err)[:120]}"
        )
    if traces is not None:
        trace = energy_trace(traj)
        if trace is not None:
            traces[(case.name, engine, method, row["dt_kind"], dt)] = trace
    return row


def _stalled(case: Case, engine: str, traj: Trajectory) -> str | None:
    """:func:`truestep.measures.stalled.stalled` against the case's exact motion at the
    run's records, in the precision the engine declares."""
    from truestep.measures.stalled import stalled

    exact = metrics.exact_for(case, traj.t)
    return stalled(case, traj, exact, metrics.precision_of(engine))


def _motion_failure(case: Case, traj: Trajectory):
    """:func:`truestep.measures.stability.motion_failure` against the case's energy scale."""
    from truestep.measures.energy_scale import energy_scale
    from truestep.measures.stability import motion_failure

    return motion_failure(case, traj, energy_scale(case))


MESSAGE_CHARS = 2000
"""The most characters of a row's message (an adapter's, an exception's, its output)."""
OUTPUT_CHARS = 500
"""The most characters of an engine process's own output a failed row shows."""


def with_output(message: str, output: str) -> str:
    """A failed row's message, with the end of what its engine process wrote (captured by
    :mod:`truestep.runtime.isolation`, never shown on truestep's own output)."""
    output = " ".join(output.split())
    if output:
        shown = output if len(output) <= OUTPUT_CHARS else "..." + output[-OUTPUT_CHARS:]
        message = f"{message}; engine output: {shown}" if message else f"engine output: {shown}"
    return message[:MESSAGE_CHARS]


SWEEP_SLACK = 1.25
"""The sweep process's own limit over the sum of its steps' limits: each step stops at its
``timeout`` inside the process (:func:`simulate_sweep`); the process limit is the backstop
for a step stuck where no signal reaches it."""
_MEASURE_TIMED_OUT: dict[str, str] = {}
"""Case files whose measuring ran out of time once (its exact solution, mostly): their
later rows say so at once instead of waiting out the limit again."""


def run_one(
    case: Case,
    engine: str,
    method: str,
    dt: float,
    *,
    adaptive: bool,
    timing: Timing,
    traces: dict | None = None,
) -> dict:
    """One row of ``results.csv``: run one step in its own process, then measure."""
    outcome = run_isolated(simulate_timed, (engine, case, method, dt, timing), case.timeout_s)
    row = row_from(
        case,
        engine,
        method,
        dt,
        adaptive=adaptive,
        traces=traces,
        outcome=outcome.value if outcome.status == "ok" else outcome,
    )
    if outcome.status == "ok" and row["status"] in ("crashed", "timeout"):
        row["message"] = with_output(row.get("message", ""), outcome.output)
    return row


def run_sweep(
    case: Case,
    engine: str,
    method: str,
    dts: list[float],
    *,
    adaptive: bool,
    timing: Timing,
    traces: dict | None = None,
    lanes: Lanes | None = None,
) -> list[dict]:
    """The rows of one case, engine and method over its sweep.

    The sweep runs in one child process (see :func:`simulate_sweep`; in the timed lane of
    ``lanes`` where it is given); if that process dies or runs out of time (``timeout_s``
    per step), every step is run again in a process of its own, so that the row of the step
    that crashed or hung says so and the others are measured.
    """
    if lanes is None:
        outcome = run_isolated(*sweep_call(case, engine, method, dts, timing))
    else:
        got: list[Outcome] = []
        lane = ([0], []) if timing.timed and makes_speed_claim(get_adapter(engine)) else ([], [0])
        made = sweep_call(case, engine, method, dts, timing)
        lanes.run(*lane, lambda _: made, lambda _, out: got.append(out))
        (outcome,) = got
    return sweep_rows(outcome, case, engine, method, dts, adaptive=adaptive, timing=timing, traces=traces)


def sweep_call(
    case: Case, engine: str, method: str, dts: list[float], timing: Timing, part: str = "both"
) -> Call:
    """The isolated call of one sweep (:func:`simulate_sweep`, its ``part``), after the adapter's
    optional ``prepare(case, method)`` here, before the fork (compiling, loading kernels:
    every run of the sweep finds it ready)."""
    prepare_here(engine, case, method)
    limit = SWEEP_SLACK * case.timeout_s * len(dts) + 10.0
    return simulate_sweep, (engine, case, method, dts, timing, part), limit


def prepare_here(engine: str, case: Case, method: str) -> None:
    """The adapter's optional ``prepare(case, method)`` (compile, load kernels) before
    truestep forks the runs that need it, within :data:`~truestep.adapters.PREPARE_S`
    seconds (:func:`~truestep.adapters.plugin_answer`): here in truestep's own process for
    its own adapters (the runs inherit the work), in a forked process for a plugin's
    (plugin code never runs in truestep's process; the runs find what it left on disk).
    A prepare that raises or gives no answer is let go: the runs then prepare in their own
    processes, which fail or run out of time alike, and their rows say why."""
    prepare = getattr(get_adapter(engine), "prepare", None)
    if prepare is not None:
        with contextlib.suppress(PluginFailed):
            plugin_answer(engine, "prepare()", prepare, case, method, limit_s=PREPARE_S, apart="only")


def sweep_rows(
    outcome: Outcome,
    case: Case,
    engine: str,
    method: str,
    dts: list[float],
    *,
    adaptive: bool,
    timing: Timing,
    traces: dict | None = None,
) -> list[dict]:
    """The rows of a sweep from its process's outcome (see :func:`run_sweep`)."""
    if outcome.status != "ok":
        return [
            run_one(case, engine, method, dt, adaptive=adaptive, timing=timing, traces=traces) for dt in dts
        ]
    rows = [
        row_from(case, engine, method, dt, adaptive=adaptive, outcome=o, traces=traces)
        for dt, o in zip(dts, outcome.value, strict=True)
    ]
    for row in rows:
        if row["status"] in ("crashed", "timeout"):
            row["message"] = with_output(row.get("message", ""), outcome.output)
    return rows


def preload() -> None:
    """Prepare this process for runs, once for every forked run: the compiled spring loop of
    the reference implementation (the engine modules are imported by :func:`plan`; the
    reference's stepping loops are compiled by :func:`compile_ahead`; threads are held to
    one by the run, :func:`truestep.numerics.own_run`)."""
    from truestep.reference_impl.forces import compile_springs

    compile_springs()


def compile_ahead(planned: list[tuple], workers: int | None = None) -> None:
    """Compile what the planned sweeps (case, engine, method, entries) will run before the
    first is timed, for each engine that can (``prepare_all(pairs, workers=...)``), on
    ``workers`` cores (default: all). An adapter whose ``prepares_apart`` is true compiles
    in a process of its own and returns at once: it is started first, so that it compiles
    beside the others, and its ``prepared()`` is awaited after them, before any run.
    Nothing a run measures depends on it: a ``prepare_all`` that raises is one line on
    standard error, and each run then prepares what it needs itself (and fails in its own
    row if that fails too)."""
    pairs: dict[str, list[tuple]] = {}
    for case, engine, method, entries in planned:
        if not entries[0][3]:
            pairs.setdefault(engine, []).append((case, method))
    adapters = {engine: get_adapter(engine) for engine in pairs}
    apart = [e for e in pairs if getattr(adapters[e], "prepares_apart", False) is True]
    for engine in [*apart, *(e for e in pairs if e not in apart)]:
        ahead = getattr(adapters[engine], "prepare_all", None)
        if ahead is not None:
            _prepare_ahead(engine, "prepare_all()", ahead, pairs[engine], workers=workers)
    for engine in apart:
        done = getattr(adapters[engine], "prepared", None)
        if done is not None:
            _prepare_ahead(engine, "prepared()", done)


def _prepare_ahead(engine: str, what: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
    """``fn(*args)``, one of an adapter's calls of :func:`compile_ahead` (``workers``, where
    given, defaulting to every core), within :data:`~truestep.adapters.PREPARE_ALL_S`
    seconds; a call that fails is one line on standard error."""
    if "workers" in kwargs:
        kwargs["workers"] = kwargs["workers"] or len(os.sched_getaffinity(0))
    try:
        plugin_answer(engine, what, fn, *args, limit_s=PREPARE_ALL_S, apart="only", **kwargs)
    except PluginFailed as err:
        print(f"truestep: {err}; its runs prepare what they need themselves", file=sys.stderr)


def left_out(adapter, case: Case, method: str) -> str | None:
    """Why the adapter leaves a case it can model unrun (its optional ``skip``: a scene
    beyond the work it takes on), or ``None``."""
    skip = getattr(adapter, "skip", None)
    return skip(case, method) if skip is not None else None


def unsupported_message(engine: str, missing: str) -> str:
    """Why ``engine`` cannot model the features ``missing`` (comma-separated), from its
    adapter's optional ``unsupported_notes`` (feature -> reason), or ``""``."""
    notes = getattr(adapter_class(engine), "unsupported_notes", None) or {}
    reasons = [f"{f}: {notes[f]}" for f in missing.split(",") if f in notes]
    return "; ".join(reasons)


def plan(case: Case, engine: str, *, quick: bool) -> Iterable[tuple[str, float | None, bool, str]]:
    """(method, dt, adaptive, why-not) for every row this case and engine produce.

    ``why-not`` is empty for a run, else ``unsupported: <features>``, ``skipped: <reason>``
    or ``crashed: <why>`` (the adapter's ``missing``, ``duplicate`` or ``skip`` raised:
    :func:`~truestep.adapters.plugin_answer`) and the row is written without running.
    """
    adapter = get_adapter(engine)
    for method in adapter.methods:
        adaptive = method in adapter.adaptive_methods
        try:
            missing = plugin_answer(engine, "missing()", adapter.missing, case, method)
            said = (
                []
                if missing
                else [
                    plugin_answer(engine, "duplicate()", duplicate_of, adapter, case, method),
                    plugin_answer(engine, "skip()", left_out, adapter, case, method),
                ]
            )
        except PluginFailed as err:
            yield method, None, adaptive, f"crashed:{err}"
            continue
        if missing:
            yield method, None, adaptive, "unsupported:" + ",".join(sorted(missing))
            continue
        skip = [r for e, m, r in case.skip if e == engine and m in (method, "*")]
        skip += [r for r in said if r]
        if skip:
            yield method, None, adaptive, "skipped:" + skip[0]
            continue
        for dt in case.sweep(adaptive=adaptive, quick=quick):
            yield method, dt, adaptive, ""


@own_run()
def run_matrix(
    cases: list[Case],
    engines: list[str],
    *,
    quick: bool = False,
    timing: Timing | None = None,
    progress: Callable[[str], None] | None = None,
    traces: dict | None = None,
    journal: Journal | None = None,
    cluster: Cluster | None = None,
    lanes: Lanes | None = None,
) -> pd.DataFrame:
    """Run every (case, engine, method, dt) and return the tidy results table.

    Each case, engine and method's sweep runs in one child process at a time
    (:func:`run_sweep`), or, with a ``cluster`` (:class:`truestep.execution.cluster.Cluster`), as
    one task on its workers (one timed run per host at a time). The rows come in the
    same order either way. Energy traces of the runs go into ``traces`` when it is given
    (see :func:`row_from`). Progress goes to standard error (:class:`Progress`), or each
    row's line to ``progress`` when it is given. With a ``journal``
    (:class:`truestep.execution.journal.Journal`), each finished sweep is checkpointed there, and a
    sweep it already holds is taken from it instead of being run again. Every row
    records the ``host`` it ran on. The sweeps run here go through ``lanes`` where it is
    given (:class:`~truestep.runtime.isolation.Lanes`, whose backlog, the analyses'
    searches and drops, fills the cores the sweep's own runs leave).
    """
    timing = timing or (QUICK_TIMING if quick else Timing())
    preload()
    planned = [
        (case, engine, method, list(entries))
        for case in cases
        for engine in engines
        for method, entries in itertools.groupby(plan(case, engine, quick=quick), key=lambda e: e[0])
    ]
    total = sum(len(entries) for *_, entries in planned if not entries[0][3])
    compiling = time.perf_counter()
    if cluster is None:
        compile_ahead(planned)
    compiling = time.perf_counter() - compiling
    parts: list[list[dict]] = [[] for _ in planned]
    jobs: list[SweepJob] = []
    local: list[tuple[int, list[float], bool]] = []
    with Progress(total, "sweep", say=progress) as bar:

        def finished(k: int, done: list[dict], swept: dict) -> None:
            case, engine, method, entries = planned[k]
            parts[k] = done
            for row in done:
                bar.done(
                    f"{case.name:24s} {engine:9s} {method:17s} {row['dt']:<9.3g} "
                    f"{row['status']:9s} err={row.get('error', np.nan):.3g} "
                    f"wall={row.get('wall_s', np.nan):.3g}s"
                )
                faults.point("sweep")
            if traces is not None:
                traces.update(swept)
            if journal is not None:
                journal.put_sweep((case.name, engine, method), _steps(entries), done, swept)

        for k, (case, engine, method, entries) in enumerate(planned):
            adaptive, why_not = entries[0][2], entries[0][3]
            if why_not:
                status, _, detail = why_not.partition(":")
                parts[k] = [
                    {
                        "case": case.name,
                        "engine": engine,
                        "method": method,
                        "dt_kind": "tolerance" if adaptive else "step",
                        "status": status,
                        "missing": detail if status == "unsupported" else "",
                        "message": unsupported_message(engine, detail) if status == "unsupported" else detail,
                        "host": "",
                    }
                ]
                continue
            dts = _steps(entries)
            kept = journal.sweep((case.name, engine, method), dts) if journal is not None else None
            if kept is not None:
                parts[k] = kept[0]
                if traces is not None:
                    traces.update(kept[1])
                bar.done(
                    f"{case.name:24s} {engine:9s} {method:17s} {len(kept[0])} rows from the interrupted run",
                    n=len(kept[0]),
                )
                continue
            if cluster is not None:
                jobs.append(SweepJob(k, case, engine, method, dts, adaptive, timing, traces is not None))
                continue
            local.append((k, dts, adaptive))
        spent: dict[str, float] = {}
        if local:
            _run_here(_LocalSweeps(planned, local, timing, traces is not None, finished, spent), lanes)
        if jobs and cluster is not None:
            for k, done, swept in cluster.sweeps(jobs):
                finished(k, done, swept)
    table = tidy([row for part in parts for row in part], cases)
    table.attrs["sweep_seconds"] = {
        "compile": round(compiling, 3),
        **{f"sweep {e}": round(s, 3) for e, s in spent.items()},
    }
    return table


def _run_here(sweeps: _LocalSweeps, lanes: Lanes | None = None) -> None:
    """The sweeps of ``sweeps`` on this machine (:meth:`~truestep.runtime.isolation.Lanes.run`),
    through ``lanes`` where it is given (its backlog follows the sweep's untimed runs)."""
    if lanes is not None:
        lanes.run(sweeps.timed, sweeps.untimed, sweeps.call, sweeps.done)
        return
    with Lanes(untimed_workers()) as own:
        own.run(sweeps.timed, sweeps.untimed, sweeps.call, sweeps.done)


class _LocalSweeps:
    """The isolated calls of the sweeps ``local`` (planned index, steps, adaptive) run on
    this machine (:func:`_run_here`): the timed runs of engines that make a speed claim one
    process at a time on a core of their own (:attr:`timed`); everything untimed on the
    cores left (:attr:`untimed`): the rows of engines that make none
    (:func:`makes_speed_claim`), run once, and the measured runs of a split sweep
    (:func:`split_sweep`). Each sweep runs whole, or its measured and timed halves apart;
    the halves of a built-in engine's sweeps of one case, of one part and timing, in one
    call (:func:`~truestep.execution.sweep_groups.group_sweeps`, :func:`simulate_sweeps`).
    A sweep of a group whose process did not end ``ok``, or whose rows say a run crashed
    or timed out, is made again in a process of its own, so that its rows (their messages
    with its own output) are the ones it gives alone. Each finished sweep's rows go to
    ``finished(k, rows, traces)``; ``spent`` gets each engine's seconds of sweep
    processes, each from its fork to its end (:attr:`Outcome.seconds`) with the adapter's
    ``prepare`` before it, summed over processes that may overlap (a split sweep's two
    halves run at once)."""

    def __init__(
        self,
        planned: list[tuple],
        local: list[tuple[int, list[float], bool]],
        timing: Timing,
        keep_traces: bool,
        finished: Callable[[int, list[dict], dict], None],
        spent: dict[str, float],
    ) -> None:
        self.planned, self.local, self.keep_traces = planned, local, keep_traces
        self.finished, self.spent, self.here = finished, spent, host_name()
        self.timings = [
            timing if makes_speed_claim(get_adapter(planned[k][1])) else UNTIMED for k, _, _ in local
        ]
        self.halves = [
            (j, part)
            for j, t in enumerate(self.timings)
            for part in (("measured", "timed") if self._split(j, t) else ("both",))
        ]
        self.units = group_sweeps(
            [self._shares(j, part) for j, part in self.halves], [self._weight(j) for j, _ in self.halves]
        )
        self.grouped = {self.halves[i][0] for unit in self.units if len(unit) > 1 for i in unit}
        timed = [
            self.timings[j].timed and part != "measured"
            for j, part in (self.halves[u[0]] for u in self.units)
        ]
        self.timed = [u for u, t in enumerate(timed) if t]
        self.untimed = [u for u, t in enumerate(timed) if not t]
        self._prepared_s: dict[int, float] = {}
        self._waiting: dict[int, dict[str, Outcome]] = {}

    def _sweep(self, j: int) -> tuple:
        """(case, engine, method, entries) of the ``j``-th local sweep."""
        return self.planned[self.local[j][0]]

    def _split(self, j: int, timing: Timing) -> bool:
        """Whether the ``j``-th sweep runs as two halves (:func:`split_sweep`)."""
        _, engine, method = self._sweep(j)[:3]
        return split_sweep(engine, timing, method)

    def _shares(self, j: int, part: str) -> tuple | None:
        """What the ``j``-th sweep's ``part`` shares with the others of its group, or
        ``None`` for a plugin's (a process of its own)."""
        case, engine = self._sweep(j)[:2]
        return (engine, case.name, part, self.timings[j].timed) if truestep_target(engine) else None

    def _weight(self, j: int) -> float:
        """The ``j``-th sweep's share of a group: its runs, and their records' bytes (each
        body's position and velocity at each record, float64)."""
        case = self._sweep(j)[0]
        return weight(len(self.local[j][1]), case.bodies * (case.max_records + 1) * 48.0)

    def _made(self, i: int) -> Call:
        j, part = self.halves[i]
        case, engine, method, _ = self._sweep(j)
        return sweep_call(case, engine, method, self.local[j][1], self.timings[j], part)

    def call(self, u: int) -> Call:
        """The ``u``-th call, its sweeps prepared (:func:`sweep_call`)."""
        start = time.perf_counter()
        calls = [self._made(i) for i in self.units[u]]
        self._prepared_s[u] = time.perf_counter() - start
        if len(calls) == 1:
            return calls[0]
        return simulate_sweeps, ([args for _, args, _ in calls],), sum(limit for *_, limit in calls)

    def _alone(self, i: int) -> Outcome:
        """The ``i``-th half made again in a process of its own (prepare and run counted)."""
        engine = self._sweep(self.halves[i][0])[1]
        start = time.perf_counter()
        outcome = run_isolated(*self._made(i))
        self.spent[engine] = self.spent.get(engine, 0.0) + time.perf_counter() - start
        return outcome

    def done(self, u: int, outcome: Outcome) -> None:
        """The ``u``-th call's outcome, handed on sweep by sweep."""
        unit = self.units[u]
        engine = self._sweep(self.halves[unit[0]][0])[1]
        self.spent[engine] = self.spent.get(engine, 0.0) + self._prepared_s.pop(u, 0.0) + outcome.seconds
        if len(unit) == 1:
            self._half_done(unit[0], outcome)
            return
        for n, i in enumerate(unit):
            self._half_done(
                i, Outcome("ok", value=outcome.value[n]) if outcome.status == "ok" else self._alone(i)
            )

    def _half_done(self, i: int, outcome: Outcome) -> None:
        j, part = self.halves[i]
        if part != "both":
            self._waiting.setdefault(j, {})[part] = outcome
            if len(self._waiting[j]) < 2:
                return
            outcome = joined(self._waiting[j]["measured"], self._waiting.pop(j)["timed"])
        rows, swept = self._rows(j, outcome)
        if j in self.grouped and any(row["status"] in ("crashed", "timeout") for row in rows):
            again = [self._alone(h) for h, (sweep, _) in enumerate(self.halves) if sweep == j]
            rows, swept = self._rows(j, again[0] if len(again) == 1 else joined(*again))
        self.finished(self.local[j][0], rows, swept)

    def _rows(self, j: int, outcome: Outcome) -> tuple[list[dict], dict]:
        case, engine, method, _ = self._sweep(j)
        _, dts, adaptive = self.local[j]
        swept: dict = {}
        rows = sweep_rows(
            outcome,
            case,
            engine,
            method,
            dts,
            adaptive=adaptive,
            timing=self.timings[j],
            traces=swept if self.keep_traces else None,
        )
        for row in rows:
            row["host"] = self.here
        return rows, swept


def case_source(case: Case, lib: dict | None = None) -> str:
    """The case's name if the case library holds this very file, else its file path."""
    from truestep.cases.loader import library

    lib = library() if lib is None else lib
    known = lib.get(case.name)
    same = known is not None and Path(known).resolve() == Path(case.file).resolve()
    return case.name if same else case.file


def _steps(entries: list[tuple]) -> list[float]:
    """The steps (or tolerances) of a planned sweep's entries (method, dt, adaptive, why not)."""
    return [dt for _, dt, _, _ in entries if dt is not None]


def tidy(rows: list[dict], cases: list[Case]) -> pd.DataFrame:
    """Rows as a DataFrame with the contract's columns first, then property columns."""
    from truestep.cases.loader import library

    props = sorted({p for c in cases for p in c.properties})
    lib = library()
    sources = {c.name: case_source(c, lib) for c in cases}
    df = pd.DataFrame(rows)
    if len(df):
        df["case_source"] = df["case"].map(sources)
    for col in RESULT_COLUMNS + props:
        if col not in df:
            df[col] = np.nan
    return writable(df[RESULT_COLUMNS + props].copy())
