"""Expand case x engine x method x dt, run each pair in isolation, measure, tabulate."""

from __future__ import annotations

import dataclasses
import statistics
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from adapters import get_adapter
from adapters.base import Trajectory
from cases.case import Case
from truestep import metrics
from truestep.isolation import run_isolated

RESULT_COLUMNS = [
    "case", "engine", "method", "dt", "dt_kind", "status", "error", "energy_drift",
    "energy_drift_final", "nfev", "steps", "wall_s", "repeats", "t_fail", "missing", "message",
]
"""The columns of ``results.csv`` (property columns follow, one per named property)."""


@dataclass
class Timing:
    """How runs are timed: a short warm-up, a first timed run (whose trajectory is kept),
    then more timed repeats while they fit in the budget.

    The warm-up runs the same scene, engine and method for :attr:`warmup_fraction` of the
    duration (JIT compilation, caches, lazy imports, first-call costs). Repeats:
    ``clamp(budget_s / first time, 1, max_repeats)`` timed runs in all; the reported wall
    time is their median, never including the warm-up or scene building. Runs shorter
    than ``budget_s / max_repeats`` (17 ms) are the ones scheduling noise distorts most,
    and they get all the repeats; a run of 50 ms or more is timed once.
    """

    budget_s: float = 0.05
    max_repeats: int = 3
    warmup_fraction: float = 0.05


def simulate_timed(engine: str, case: Case, method: str, dt: float, timing: Timing) -> Trajectory:
    """Warm up, time, keep the first timed trajectory; runs inside the child process."""
    adapter = get_adapter(engine)
    short = dataclasses.replace(case, duration=max(case.duration * timing.warmup_fraction,
                                                   min(dt, case.duration)))
    adapter.simulate(short, method, dt)
    traj = adapter.simulate(case, method, dt)
    walls = [traj.wall_s]
    if traj.status == "ok":
        n = int(np.clip(timing.budget_s / max(traj.wall_s, 1e-9), 1, timing.max_repeats))
        walls += [adapter.simulate(case, method, dt).wall_s for _ in range(n - 1)]
        traj.wall_s = statistics.median(walls)
    traj.extra["repeats"] = np.array(len(walls))
    return traj


def measure(case: Case, traj: Trajectory) -> dict[str, float]:
    """Every metric of one run, from its trajectory and the case's reference."""
    from truestep.properties import PROPERTIES

    out: dict[str, float] = {}
    exact = metrics.exact_for(case, traj.t) if traj.status == "ok" else None
    out["error"] = metrics.position_error(case, traj, exact) if exact is not None else np.nan
    drift, drift_end = metrics.energy_drift(case, traj, exact)
    out["energy_drift"], out["energy_drift_final"] = drift, drift_end
    for name in case.properties:
        out[name] = PROPERTIES[name](case, traj) if traj.status == "ok" else np.nan
    return out


TRACE_POINTS = 400
"""Energy traces kept for the report are thinned to at most this many points."""


def energy_trace(traj: Trajectory) -> tuple[np.ndarray, np.ndarray] | None:
    """Times (s) and energies (J), thinned to :data:`TRACE_POINTS`, or ``None``."""
    if traj.energy is None or len(traj.t) < 2:
        return None
    keep = np.unique(np.linspace(0, len(traj.t) - 1, TRACE_POINTS).round().astype(int))
    return traj.t[keep], traj.energy[keep]


def run_one(case: Case, engine: str, method: str, dt: float, *, adaptive: bool,
            timing: Timing, traces: dict | None = None) -> dict:
    """One row of ``results.csv``: run in isolation, then measure.

    If ``traces`` is given, the run's thinned energy trace is stored in it under
    ``(case, engine, method, dt_kind, dt)``.
    """
    row = {
        "case": case.name, "engine": engine, "method": method, "dt": dt,
        "dt_kind": "tolerance" if adaptive else "step",
    }
    outcome = run_isolated(simulate_timed, (engine, case, method, dt, timing), case.timeout_s)
    if outcome.status != "ok":
        row.update(status=outcome.status, message=outcome.message)
        return row
    traj: Trajectory = outcome.value
    if traj.status == "ok" and (t_blow := metrics.energy_blowup(case, traj)) is not None:
        traj.status, traj.t_fail = "unstable", t_blow
        traj.message = (f"finite, but its energy grew from {traj.energy[0]:.4g} J to "
                        f"{traj.energy[-1]:.4g} J and was still rising")
    row.update(
        status=traj.status,
        nfev=traj.nfev,
        steps=traj.steps,
        wall_s=traj.wall_s,
        repeats=int(traj.extra.get("repeats", 0)),
        t_fail=traj.t_fail,
        message=traj.message,
    )
    row.update(measure(case, traj))
    if traces is not None:
        trace = energy_trace(traj)
        if trace is not None:
            traces[(case.name, engine, method, row["dt_kind"], dt)] = trace
    return row


def preload() -> None:
    """Load in this process what every forked run would otherwise load again: the
    compiled kernels of the reference implementation (the engine modules are imported
    by :func:`plan`)."""
    from reference_impl.forces import compile_springs
    from reference_impl.kernels import compile_rain

    compile_springs()
    compile_rain()


def plan(case: Case, engine: str, *, quick: bool) -> Iterable[tuple[str, float | None, bool, str]]:
    """(method, dt, adaptive, why-not) for every row this case and engine produce.

    ``why-not`` is empty for a run, else ``unsupported: <features>`` or ``skipped: <reason>``
    and the row is written without running.
    """
    adapter = get_adapter(engine)
    for method in adapter.methods:
        adaptive = method in adapter.adaptive_methods
        missing = adapter.missing(case, method)
        if missing:
            yield method, None, adaptive, "unsupported:" + ",".join(sorted(missing))
            continue
        skip = [r for e, m, r in case.skip if e == engine and m in (method, "*")]
        if skip:
            yield method, None, adaptive, "skipped:" + skip[0]
            continue
        for dt in case.sweep(adaptive=adaptive, quick=quick):
            yield method, dt, adaptive, ""


def run_matrix(
    cases: list[Case],
    engines: list[str],
    *,
    quick: bool = False,
    timing: Timing | None = None,
    progress: Callable[[str], None] | None = None,
    traces: dict | None = None,
) -> pd.DataFrame:
    """Run every (case, engine, method, dt) and return the tidy results table.

    Energy traces of the runs go into ``traces`` when it is given (see :func:`run_one`).
    """
    timing = timing or Timing(max_repeats=1 if quick else 3)
    say = progress or (lambda msg: print(msg, file=sys.stderr))
    preload()
    start = time.perf_counter()
    rows = []
    for case in cases:
        for engine in engines:
            for method, dt, adaptive, why_not in plan(case, engine, quick=quick):
                if why_not:
                    status, _, detail = why_not.partition(":")
                    rows.append({
                        "case": case.name, "engine": engine, "method": method,
                        "dt_kind": "tolerance" if adaptive else "step", "status": status,
                        "missing": detail if status == "unsupported" else "",
                        "message": detail if status == "skipped" else "",
                    })
                    continue
                row = run_one(case, engine, method, dt, adaptive=adaptive, timing=timing,
                              traces=traces)
                rows.append(row)
                say(f"{time.perf_counter() - start:7.1f}s {case.name:24s} {engine:9s} "
                    f"{method:17s} {dt:<9.3g} {row['status']:9s}"
                    f" err={row.get('error', np.nan):.3g} wall={row.get('wall_s', np.nan):.3g}s")
    return tidy(rows, cases)


def tidy(rows: list[dict], cases: list[Case]) -> pd.DataFrame:
    """Rows as a DataFrame with the contract's columns first, then property columns."""
    props = sorted({p for c in cases for p in c.properties})
    df = pd.DataFrame(rows)
    for col in RESULT_COLUMNS + props:
        if col not in df:
            df[col] = np.nan
    return df[RESULT_COLUMNS + props]
