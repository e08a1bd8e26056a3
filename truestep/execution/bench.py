"""How cost grows with work: particle-steps per second against n on the rain scene.

:func:`scaling_table` runs the ``particle-rain`` case (independent balls over a floor)
with ``n`` particles, for ``n`` from 1e2 to 1e6, through every fixed-step method of every
engine named, and tabulates particle-steps per second (``n * steps / wall_s``) beside the
fraction of this machine's copy bandwidth (:func:`copy_bandwidth`, measured in the same
run) that rate stands for. :func:`scaling_plot` draws it. ``truestep bench`` does both.

Only the adapter API is used (``missing``, ``adaptive_methods``, ``simulate`` and its
``Trajectory.wall_s`` and ``steps``): whatever path an adapter takes to step the scene,
the numbers are what a user of that adapter gets, reading the state back included.

How a run is timed
------------------
- The scene at ``n`` is the case's own ``[[scene.blocks]]`` with ``count = n``, read by
  the case loader's scene reader: the same seeded uniform positions in the same box, the
  same mass, radius, floor and gravity, so each particle's physics is the case's.
- Every call of an adapter happens in a forked child process
  (:func:`truestep.runtime.isolation.run_isolated`), one at a time: a crash or a hang is a row
  (``crashed``, ``timeout``), and no run shares the CPU with another.
- Warm-up: an engine that compiles what a scene needs (``adapter.prepare(case, method)``,
  the reference) does so first, in this process, so that every child it forks finds it
  ready. Then each (engine, method) runs once at the smallest n (at most
  :data:`WARMUP_N`) in a child of its own, untimed: first-use costs (imports, caches an
  engine keeps on disk) are paid there, and runs of doubling length time a step there
  until one takes :data:`CALIBRATION_S`. Every timed child then warms up again at that n
  for 2 steps (first calls in a fresh process) before its one timed run.
- Steps per run: about ``target_s`` (0.2 s) of timed stepping, at least
  :data:`MIN_STEPS`, and at most the case's own duration (1 s at ``dt = 1e-3``: the fall
  and the first bounces). A run of ``k`` steps simulates the first ``k * dt`` seconds of
  the rain, and a step costs what the particles are doing: once they rest on the floor a
  step costs several times a step of the fall, so no run goes past the case's duration,
  and every row's steps are of the same phase of the rain. Where a run of the whole
  duration is shorter than the target, the child runs it again (each run built afresh),
  up to :data:`MAX_REPEATS` runs, and the row's ``wall_s`` is their median.
- The seconds per step at ``n`` are extrapolated from the pair's smaller sizes (the
  larger of an affine and a power-law fit through the last two, so a cost that grows
  faster than n is not underestimated); where building the scene is cheap (predicted
  under a quarter of the target), the child times a probe run at ``n`` of a tenth of
  those steps first and takes the steps from it.
- The budget: ``budget_s`` seconds for the whole table, from the call to the last row:
  the bandwidth measurement, compiling, the warm-ups and the timed children. Each
  (engine, method) in turn gets an equal share of what is left and spends it, its
  compiling and warm-up first, then from the smallest n up; a size whose predicted cost
  (the untimed work of its child, building the scene above all, plus the timed stepping:
  the work, steps times n, at the cost per particle-step measured at smaller n, the
  larger of an affine and a power-law extrapolation, and for building the same engine's
  other methods) times :data:`MARGIN` does not fit in what is left of the share is
  ``skipped``, with the numbers in its note, and so is every larger size. A child is
  killed when it outlasts both what is left of the share and 3 x its predicted cost, and
  always when the budget ends (``timeout``; an overrun comes out of the later shares): a
  timing surprise costs a row, never the budget. The first size runs whenever any of the
  budget is left (its warm-up within :data:`FIRST_TIMEOUT_S` at most), since it
  calibrates the rest. After a crash or a timeout the larger sizes are skipped, saying
  why.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import re
import time
import tomllib
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from truestep.adapters import PluginFailed, get_adapter, plugin_answer
from truestep.adapters.devices import CPU, engine_device
from truestep.cases.case import Case
from truestep.execution.bench_defaults import BUDGET_S, SIZES
from truestep.execution.progress import Progress
from truestep.runtime.isolation import Outcome, run_isolated
from truestep.tables.spec import SCALING

RAIN_CASE = "particle-rain"
"""The case whose scene is scaled: independent balls over a floor."""
NOT_RUN = ("skipped", "unsupported")
"""Statuses of rows that did not run (over the budget, or a scene the engine cannot
model): they name no device."""


TARGET_S = 0.2
"""Seconds of timed stepping each run aims at."""

MIN_STEPS = 2
"""Steps of a run at least, however long one step takes."""

MAX_REPEATS = 25
"""Timed runs of one row at most, when a run of the case's whole duration is shorter than
the target (their median is the row's ``wall_s``)."""

WARMUP_N = 100
"""Particles of the untimed warm-up runs (fewer if the table's smallest n is)."""

CALIBRATION_S = 0.02
"""The warm-up child times runs at the warm-up size until one takes this long, s."""

PROBE_FRACTION = 0.1
"""A probe run at n takes this fraction of the steps predicted for the target."""

PROBE_BUILD = 0.25
"""A child probes at n when building there is predicted to take at most this fraction
of the target (building twice costs little)."""

FIRST_TIMEOUT_S = 60.0
"""Seconds the warm-up child and the first size of a pair may take at least (plus 5 x
the target), whatever is left of the share, and at most what is left of the budget."""

RESERVE_S = 0.05
"""Seconds of the budget kept for assembling the table after the last child."""

MARGIN = 1.2
"""A run is started only if its predicted cost times this fits in what is left."""

TIMEOUT_FACTOR = 3.0
"""A child may take this many times its predicted cost even when the share has less left
(an extrapolation from smaller n can be a few times off)."""

BYTES_PER_PARTICLE_STEP = 2 * 2 * 3 * 8
"""Bytes one particle-step moves at least: positions and velocities (3 float64 each),
each read and written once."""

COLUMNS = SCALING.names
"""The columns of ``scaling.csv`` (:data:`truestep.tables.spec.SCALING`)."""


def copy_bandwidth(nbytes: int = 2**28, repeats: int = 5) -> float:
    """This machine's memory bandwidth now, bytes/s: a numpy copy of ``nbytes`` bytes.

    Counts ``2 * nbytes`` bytes moved per copy (read and written), best of ``repeats``
    copies (the first one also faults the destination's pages in).
    """
    src = np.ones(max(1, nbytes // 8))
    dst = np.empty_like(src)
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        np.copyto(dst, src)
        best = min(best, time.perf_counter() - start)
    return 2 * src.nbytes / best


def rain_case(n: int, case: Case | None = None) -> Case:
    """The rain case with ``n`` particles: its ``[[scene.blocks]]`` read with ``count = n``.

    ``case`` defaults to the library's ``particle-rain``. The scene is read by the case
    loader's own scene reader from the case file, so positions are drawn by the same
    seeded rule in the same box; everything else of the case is kept. Raises
    ``ValueError`` for a case whose scene is not one block of particles.
    """
    from truestep.cases.fields import Fields
    from truestep.cases.loader import library, load_case
    from truestep.cases.scene import read_scene

    case = case or load_case(library()[RAIN_CASE])
    table = tomllib.loads(Path(case.file).read_text())["scene"]
    blocks = table.get("blocks", [])
    if len(blocks) != 1 or any(k in table for k in ("particles", "meshes", "emitters")):
        raise ValueError(f"case: {case.name} has no single [[scene.blocks]] to scale")
    scene = {**table, "blocks": [{**blocks[0], "count": int(n)}]}
    return dataclasses.replace(case, scene=read_scene(Fields(case.file, scene, "scene")))


def _with_steps(case: Case, steps: int, dt: float) -> Case:
    """The case run for ``steps`` steps of ``dt`` s, its state read back at the end only."""
    return dataclasses.replace(case, duration=steps * dt, max_records=1)


def _steps_for(seconds_per_step: float, target_s: float, max_steps: int) -> int:
    """Steps for ``target_s`` s of stepping at ``seconds_per_step``, from
    :data:`MIN_STEPS` to ``max_steps``."""
    if not seconds_per_step > 0:
        return max_steps
    return int(min(max_steps, max(MIN_STEPS, round(target_s / seconds_per_step))))


def _repeats_for(run_s: float, target_s: float) -> int:
    """Timed runs of ``run_s`` s each that make up ``target_s``, 1 to :data:`MAX_REPEATS`."""
    if not run_s > 0:
        return MAX_REPEATS
    return int(min(MAX_REPEATS, max(1, math.ceil(target_s / run_s))))


def _calibrate(adapter, case: Case, method: str, dt: float, max_steps: int) -> float:
    """Seconds per step at ``case``'s n: runs of 8, 64, ... steps (at most ``max_steps``)
    until one takes :data:`CALIBRATION_S` (untimed: it chooses the steps only)."""
    steps = min(8, max_steps)
    while True:
        traj = adapter.simulate(_with_steps(case, steps, dt), method, dt)
        per_step = traj.wall_s / max(traj.steps, 1)
        if traj.wall_s >= CALIBRATION_S or steps >= max_steps or traj.status != "ok":
            return per_step
        steps = min(max_steps, max(8 * steps, math.ceil(1.5 * CALIBRATION_S / max(per_step, 1e-9))))


def threaded(engine: str) -> bool:
    """Whether truestep's own adapter of ``engine`` takes a count of ``threads`` (the
    reference: :class:`~truestep.adapters.reference.ReferenceAdapter`)."""
    from truestep.adapters import adapter_class

    cls = adapter_class(engine)
    return cls.__module__.startswith("truestep.") and "threads" in inspect.signature(cls).parameters


def _adapter(engine: str, threads: int):
    """``engine``'s adapter, on ``threads`` threads where it takes a count (:func:`threaded`)."""
    if threads > 1 and threaded(engine):
        from truestep.adapters import adapter_class

        return adapter_class(engine)(threads=threads)
    return get_adapter(engine)


def _adapters_on(engines: list[str], threads: int) -> tuple[dict[str, Any], dict[str, int]]:
    """Each engine's adapter (:func:`_adapter`) and the threads it runs on: ``threads``
    where it takes a count, else 1."""
    if not (isinstance(threads, int) and threads >= 1):
        raise ValueError(f"threads: a whole number of at least 1, got {threads!r}")
    on = {e: threads if threads > 1 and threaded(e) else 1 for e in engines}
    return {e: _adapter(e, on[e]) for e in engines}, on


def _warm_up(engine: str, method: str, dt: float, warm: Case, max_steps: int, threads: int = 1) -> float:
    """In the warm-up child: a first run of 2 steps, then :func:`_calibrate`; returns
    seconds per step at ``warm``'s n."""
    adapter = _adapter(engine, threads)
    adapter.simulate(_with_steps(warm, MIN_STEPS, dt), method, dt)
    return _calibrate(adapter, warm, method, dt, max_steps)


def _timed_run(
    engine: str,
    method: str,
    dt: float,
    case: Case,
    warm: Case,
    steps: int,
    probe: bool,
    target_s: float,
    max_steps: int,
    threads: int = 1,
) -> dict:
    """In a timed child (``engine``'s adapter on ``threads`` threads where it takes a count:
    :func:`_adapter`): warm up on ``warm`` (2 steps); probe at ``case``'s n if asked
    (:data:`PROBE_FRACTION` of ``steps``; the steps then come from it); then run ``case``
    timed, once, or again (each run built afresh) while the runs so far are shorter than
    ``target_s`` in all (at most :data:`MAX_REPEATS` runs, and at most 3 x ``target_s`` of
    their building and stepping); a run that is not ``ok`` ends it and is reported alone.
    Returns plain numbers: ``steps`` of a run, ``wall_s`` (the median timed stepping),
    ``repeats``, ``wall_total_s``, ``status`` and ``message`` (of the last run),
    ``run_s`` (seconds of the ``simulate`` calls of the timed runs: building, stepping,
    reading back) and ``probe_s`` (seconds spent probing)."""
    adapter = _adapter(engine, threads)
    adapter.simulate(_with_steps(warm, MIN_STEPS, dt), method, dt)
    began = time.perf_counter()
    if probe:
        trial = adapter.simulate(
            _with_steps(case, max(MIN_STEPS, round(PROBE_FRACTION * steps)), dt), method, dt
        )
        if trial.status == "ok" and trial.steps > 0 and trial.wall_s > 0:
            steps = _steps_for(trial.wall_s / trial.steps, target_s, max_steps)
    probed = time.perf_counter()
    walls: list[float] = []
    while True:
        traj = adapter.simulate(_with_steps(case, steps, dt), method, dt)
        walls.append(float(traj.wall_s))
        if traj.status != "ok":  # a run that stopped early is the row, alone
            walls = walls[-1:]
            break
        if (
            sum(walls) >= target_s
            or len(walls) >= MAX_REPEATS
            or time.perf_counter() - probed >= 3 * target_s
        ):
            break
    return {
        "steps": int(traj.steps),
        "wall_s": float(np.median(walls)),
        "repeats": len(walls),
        "wall_total_s": float(sum(walls)),
        "status": traj.status,
        "message": traj.message,
        "run_s": time.perf_counter() - probed,
        "probe_s": probed - began,
    }


def _extrapolate(points: dict[int, float], n: int) -> float:
    """Seconds at ``n`` from seconds measured at smaller sizes (``points``: n -> s).

    One point: proportional to n. Two or more: the larger of the affine fit and the
    power law through the last two (exponent within 0..2), never below the last point.
    """
    ns = sorted(k for k in points if k <= n)
    if not ns:
        return 0.0
    nb, tb = ns[-1], max(points[ns[-1]], 1e-9)
    if len(ns) == 1 or nb == n:
        return tb * n / nb
    na, ta = ns[-2], max(points[ns[-2]], 1e-9)
    affine = tb + max(0.0, (tb - ta) / (nb - na)) * (n - nb)
    exponent = min(2.0, max(0.0, math.log(tb / ta) / math.log(nb / na)))
    return max(affine, tb * (n / nb) ** exponent)


def _prepare_and_warm_up(
    pair: _Pair, adapter, dt: float, warm: Case, max_steps: int, first_timeout: float
) -> tuple:
    """Compile what the pair's engine needs in this process (``adapter.prepare``, where it
    has one), then its warm-up child (:func:`_warm_up`), both out of its share; returns the
    warm-up's outcome and a note for its first row when they took long."""
    began = time.perf_counter()
    prepare = getattr(adapter, "prepare", None)
    if prepare is not None:
        prepare(warm, pair.method)
    left = pair.budget_left()
    if left <= 0:
        pair.stop = f"budget: the {pair.budget_s:g} s budget ended before the warm-up"
        warm_up = Outcome("ok", math.nan)
    else:
        warm_up = run_isolated(
            _warm_up, (pair.engine, pair.method, dt, warm, max_steps, pair.threads), min(first_timeout, left)
        )
    pair.spent = time.perf_counter() - began
    note = ""
    if warm_up.status == "ok" and not pair.stop:
        pair.per_step[warm.particles.n] = warm_up.value
        if pair.spent > 1.0:
            note = (
                f"compiling and the warm-up (n={_fmt_n(warm.particles.n)}, untimed) took "
                f"{pair.spent:.2g} s of the pair's share"
            )
    return warm_up, note


def _static_reason(adapter, case: Case, engine: str, method: str) -> tuple[str, str] | None:
    """``(status, note)`` of a pair that is not run at any n, or ``None`` to run it (``crashed``
    where the adapter's ``missing`` or ``duplicate`` raised)."""
    try:
        missing = plugin_answer(engine, "missing()", adapter.missing, case, method)
        duplicate: Any = getattr(adapter, "duplicate", None)  # called only where not None
        asked = duplicate is not None and not missing
        same = plugin_answer(engine, "duplicate()", duplicate, case, method) if asked else None
    except PluginFailed as err:
        return "crashed", str(err)
    if missing:
        return "unsupported", "needs " + ", ".join(sorted(missing))
    if method in adapter.adaptive_methods:
        return "skipped", (
            "adaptive: its dt is a tolerance and it chooses its own steps, so steps per run cannot be set"
        )
    reasons = [r for e, m, r in case.skip if e == engine and m in (method, "*")]
    if same:
        reasons.append(same)
    if reasons:
        return "skipped", f"the case skips it: {reasons[0]}"
    return None


def _fmt_n(n: int) -> str:
    return f"{n:,}"


class _Pair:
    """What one (engine, method) has measured and spent while its sizes run, smallest first."""

    def __init__(
        self, engine: str, method: str, share: float, budget_s: float, deadline: float, threads: int = 1
    ) -> None:
        self.engine, self.method, self.share, self.budget_s = engine, method, share, budget_s
        self.threads = threads  # the adapter's threads (1 where it takes no count)
        self.deadline = deadline  # time.perf_counter() when the budget ends
        self.spent = 0.0  # seconds of this pair's compiling, warm-up and children so far
        self.fixed = 0.0  # seconds of the last timed child outside its timed simulate call
        self.per_step: dict[int, float] = {}  # n -> timed seconds per step
        self.build: dict[int, float] = {}  # n -> untimed seconds of the timed simulate call
        self.stop = ""  # why the larger sizes are not run

    def _left(self) -> str:
        return (
            f"{max(self.share - self.spent, 0):.2g} s were left of this pair's "
            f"{self.share:.2g} s share of the {self.budget_s:g} s budget"
        )

    def budget_left(self) -> float:
        """Seconds until the budget ends, less :data:`RESERVE_S`."""
        return self.deadline - time.perf_counter() - RESERVE_S

    def run(
        self,
        n: int,
        dt: float,
        target_s: float,
        max_steps: int,
        bandwidth: float,
        scene,
        warm_n: int,
        first_timeout: float,
        engine_build: dict[int, float],
    ) -> dict:
        """Predict the row at ``n``; skip it, or run it in a child; the row's fields."""
        t_step = _extrapolate(self.per_step, n)
        steps = _steps_for(t_step, target_s, max_steps)
        repeats = _repeats_for(steps * t_step, target_s)
        own = _extrapolate(self.build, n) if self.build else 0.0
        t_build = max(own, engine_build.get(n, 0.0))
        probe = t_build <= PROBE_BUILD * target_s
        predicted = (
            self.fixed + t_build * (repeats + probe) + steps * t_step * (repeats + PROBE_FRACTION * probe)
        )
        first = not self.build
        if not first and self.spent + MARGIN * predicted > self.share:
            source = "this engine's other methods" if t_build > own else "smaller n"
            self.stop = (
                f"budget: the run at n={_fmt_n(n)} would take ~{predicted:.2g} s "
                f"({steps} steps of ~{t_step:.2g} s, building the scene and other untimed "
                f"work ~{predicted - repeats * steps * t_step:.2g} s, extrapolated from "
                f"{source}); " + self._left()
            )
            return {"status": "skipped", "note": self.stop}
        timeout = min(
            max(self.share - self.spent, TIMEOUT_FACTOR * predicted, first_timeout if first else 0.0),
            self.budget_left(),
        )
        if timeout <= 0:
            self.stop = f"budget: the {self.budget_s:g} s budget ended before the run at n={_fmt_n(n)}"
            return {"status": "skipped", "note": self.stop}
        began = time.perf_counter()
        outcome = run_isolated(
            _timed_run,
            (
                self.engine,
                self.method,
                dt,
                scene(n),
                scene(warm_n),
                steps,
                probe,
                target_s,
                max_steps,
                self.threads,
            ),
            timeout,
        )
        elapsed = time.perf_counter() - began
        self.spent += elapsed
        if outcome.status != "ok":
            what = "timed out" if outcome.status == "timeout" else "crashed"
            self.stop = f"the run at n={_fmt_n(n)} {what}"
            note = outcome.message
            if outcome.status == "timeout":
                note = (
                    f"did not finish within {timeout:.2g} s (predicted ~{predicted:.2g} s; "
                    f"the pair had {max(self.share - self.spent + elapsed, 0):.2g} s of its "
                    f"{self.share:.2g} s share left)"
                )
                # building at this n takes at least this long, whatever the method: say twice
                engine_build[n] = max(engine_build.get(n, 0.0), 2 * (elapsed - self.fixed))
            return {"status": outcome.status, "untimed_s": elapsed, "note": note}
        r = outcome.value
        rate = n * r["steps"] / r["wall_s"] if r["wall_s"] > 0 else math.nan
        if r["steps"] > 0 and r["wall_s"] > 0:
            self.per_step[n] = r["wall_s"] / r["steps"]
        self.build[n] = max((r["run_s"] - r["wall_total_s"]) / r["repeats"], 0.0)
        engine_build[n] = max(engine_build.get(n, 0.0), self.build[n])
        self.fixed = max(elapsed - r["run_s"] - r["probe_s"], 0.0)
        return {
            "steps": r["steps"],
            "repeats": r["repeats"],
            "wall_s": r["wall_s"],
            "particle_steps_per_s": rate,
            "bandwidth_fraction": rate * BYTES_PER_PARTICLE_STEP / bandwidth,
            "untimed_s": max(elapsed - r["wall_total_s"], 0.0),
            "status": r["status"],
            "note": r["message"],
        }


def scaling_table(
    engines: Iterable[str],
    *,
    sizes: Sequence[float] = SIZES,
    dt: float = 1e-3,
    budget_s: float = BUDGET_S,
    progress: Callable[[str], None] | None = None,
    target_s: float = TARGET_S,
    case: Case | None = None,
    threads: int = 1,
) -> pd.DataFrame:
    """Particle-steps per second against n on the rain scene, per engine and method.

    Parameters
    ----------
    engines : engine names (registered, or ``module:Class`` already resolved)
    sizes : particle counts n (rounded to integers, run in increasing order)
    dt : the step, s
    budget_s : seconds for the whole table (see the module docstring: each (engine,
        method) gets an equal share of what is left; sizes that would not fit are
        ``skipped`` with the reason)
    progress : receives one line per row; default, lines (or a bar) on standard error
    target_s : seconds of timed stepping each run aims at
    case : the scene to scale (default the library's ``particle-rain``; one block)
    threads : threads of the engines whose adapter takes a count (:func:`threaded`: the
        reference, whose tiles of independent particles then run that many at once); every
        other engine runs as it does. Those rows' notes say so.

    Each engine computes on the device the run resolved for it (``truestep bench
    --device``, :mod:`truestep.adapters.devices`; the CPU by default), which each row that
    ran names (``device``).

    Returns
    -------
    DataFrame with one row per (engine, method, n), columns :data:`COLUMNS`:
    ``steps`` of a timed run; ``repeats``, the timed runs of the row (more than one
    where a run of the case's whole duration is shorter than ``target_s``);
    ``wall_s``, the median timed stepping of a run, s (scene building excluded, the
    adapter's reading back included); ``particle_steps_per_s`` = ``n * steps / wall_s``;
    ``bandwidth_fraction`` = that rate times :data:`BYTES_PER_PARTICLE_STEP` (96 B:
    positions and velocities, float64, read and written) over the copy bandwidth (above
    1: the state stays in cache between steps); ``untimed_s``, the rest of the timed
    child's time, s (process start, its warm-up, building the scenes, a probe run,
    reading back, teardown); ``status`` ``ok``, ``unstable``, ``crashed``, ``timeout``,
    ``unsupported`` or ``skipped``; ``note``, the reason, or the engine's notes; ``device``,
    where the row computed (empty for a row that did not run).
    ``attrs`` holds ``bandwidth_bytes_per_s``, ``bytes_per_particle_step``, ``dt``,
    ``budget_s``, ``target_s``, ``threads``, ``elapsed_s`` (seconds of the whole call,
    within the budget) and ``warmup_s`` (those of compiling and the warm-up children,
    within it).
    """
    from truestep.cases.loader import library, load_case
    from truestep.numerics import pin_threads

    pin_threads()
    case = case or load_case(library()[RAIN_CASE])
    ns = sorted({round(float(s)) for s in sizes})
    if not ns or ns[0] < 1:
        raise ValueError(f"sizes: need at least one size of 1 or more, got {list(sizes)}")
    start_all = time.perf_counter()
    deadline = start_all + budget_s
    bandwidth = copy_bandwidth()
    engines = list(dict.fromkeys(engines))
    adapters, on = _adapters_on(engines, threads)

    rows: list[dict] = []
    pairs: list[tuple[str, str]] = []
    for engine, adapter in adapters.items():
        for method in adapter.methods:
            why = _static_reason(adapter, case, engine, method)
            if why is None:
                pairs.append((engine, method))
            else:
                rows += [
                    {"engine": engine, "method": method, "n": n, "status": why[0], "note": why[1]} for n in ns
                ]

    scenes: dict[int, Case] = {}

    def scene(n: int) -> Case:
        if n not in scenes:
            scenes[n] = rain_case(n, case)
        return scenes[n]

    warm_n = min(WARMUP_N, ns[0])
    max_steps = max(MIN_STEPS, case.steps_for(dt)[0])  # a run covers at most the case's duration
    first_timeout = FIRST_TIMEOUT_S + 5 * target_s
    engine_build: dict[str, dict[int, float]] = {}  # engine -> n -> untimed s of its simulate
    warmups_s = 0.0
    with Progress(len(pairs) * len(ns), "bench", say=progress) as bar:
        for k, (engine, method) in enumerate(pairs):
            share = max(0.0, deadline - time.perf_counter()) / (len(pairs) - k)
            pair = _Pair(engine, method, share, budget_s, deadline, on[engine])
            warm, warm_note = _prepare_and_warm_up(
                pair, adapters[engine], dt, scene(warm_n), max_steps, first_timeout
            )
            warmups_s += pair.spent
            for n in ns:
                row: dict[str, Any] = {"engine": engine, "method": method, "n": n}
                if warm.status != "ok" and not pair.stop:
                    what = "timed out" if warm.status == "timeout" else "crashed"
                    row.update(
                        status=warm.status,
                        note=f"in the warm-up (n={_fmt_n(warm_n)}, untimed): {warm.message}",
                    )
                    pair.stop = f"the warm-up at n={_fmt_n(warm_n)} {what}"
                elif pair.stop:
                    row.update(status="skipped", note=pair.stop)
                else:
                    row.update(
                        pair.run(
                            n,
                            dt,
                            target_s,
                            max_steps,
                            bandwidth,
                            scene,
                            warm_n,
                            first_timeout,
                            engine_build.setdefault(engine, {}),
                        )
                    )
                    if warm_note and n == ns[0]:
                        row["note"] = "; ".join(x for x in (row["note"], warm_note) if x)
                if on[engine] > 1:
                    row["note"] = "; ".join(x for x in (f"on {on[engine]} threads", row.get("note")) if x)
                rows.append(row)
                bar.done(
                    f"{engine:9s} {method:17s} n={n:>9,d} {row['status']:8s} "
                    f"steps={row.get('steps', 0):<7d} wall={row.get('wall_s', math.nan):.3g}s "
                    f"rate={row.get('particle_steps_per_s', math.nan):.3g}/s"
                )

    table = pd.DataFrame(rows)
    for col in COLUMNS:
        if col not in table:
            table[col] = np.nan
    table["device"] = [
        "" if status in NOT_RUN else engine_device(str(engine))
        for engine, status in zip(table["engine"], table["status"], strict=True)
    ]
    order = {e: i for i, e in enumerate(engines)}
    methods = {(e, m): i for e in engines for i, m in enumerate(adapters[e].methods)}
    table = table.assign(
        _e=table["engine"].map(order),
        _m=[methods[(e, m)] for e, m in zip(table["engine"], table["method"], strict=True)],
    )
    table = table.sort_values(["_e", "_m", "n"], kind="stable")[COLUMNS].reset_index(drop=True)
    table["n"] = table["n"].astype(int)
    table["steps"] = table["steps"].astype("Int64")
    table["repeats"] = table["repeats"].astype("Int64")
    table["note"] = table["note"].fillna("").astype(str)
    table.attrs.update(
        bandwidth_bytes_per_s=bandwidth,
        bytes_per_particle_step=BYTES_PER_PARTICLE_STEP,
        dt=dt,
        budget_s=budget_s,
        target_s=target_s,
        threads=threads,
        elapsed_s=time.perf_counter() - start_all,
        warmup_s=warmups_s,
    )
    return table


def _short_n(n: float) -> str:
    """``1e4`` for a power of ten, else ``12,500``."""
    k = round(math.log10(n)) if n > 0 else 0
    return f"1e{k}" if n == 10**k else _fmt_n(int(n))


def scaling_plot(table: pd.DataFrame, bandwidth: float, path: Path | str) -> Path:
    """Particle-steps per second against n (log-log), one line per engine/method.

    ``table`` is :func:`scaling_table`'s (rows with status ``ok`` are drawn);
    ``bandwidth`` the copy bandwidth, bytes/s, drawn as the rate a loop that streams
    positions and velocities through memory once per step would reach
    (``bandwidth / 96`` particle-steps/s), with the fraction of it on the right axis.
    A series that stops early says in its legend entry from which n on it was not run,
    and why (``budget``, ``crashed``, ``timeout``). Writes a PNG at ``path``; returns it.
    """
    import matplotlib.pyplot as plt

    from truestep.style import save, series_style

    path = Path(path)
    per_s = bandwidth / BYTES_PER_PARTICLE_STEP
    fig, ax = plt.subplots(figsize=(10.5, 5.4))
    for (engine, method), g in table.groupby(["engine", "method"], sort=False):
        ok = g[g["status"] == "ok"].sort_values("n")
        if ok.empty:
            continue
        label = f"{engine} / {method}"
        device = str(ok["device"].iloc[0]) if "device" in ok else ""
        if device not in ("", "nan", CPU):
            label += f" on {device}"
        threads = re.match(r"on (\d+) threads", str(ok["note"].iloc[0]))
        if threads:
            label += f", {threads.group(1)} threads"
        after = g[(g["n"] > ok["n"].max()) & (g["status"] != "ok")].sort_values("n")
        if len(after):
            first = after.iloc[0]
            note = str(first["note"])
            why = (
                "budget"
                if note.startswith("budget")
                else "a run timed out"
                if "timed out" in note or first["status"] == "timeout"
                else "a run crashed"
                if "crashed" in note or first["status"] == "crashed"
                else first["status"]
            )
            label += f"  (none from n = {_short_n(first['n'])}: {why})"
        ax.plot(ok["n"], ok["particle_steps_per_s"], label=label, **series_style(engine, method))
    ax.axhline(per_s, color="black", linewidth=1.0, linestyle=(0, (6, 3)))
    ax.annotate(
        f"copy bandwidth {bandwidth / 1e9:.1f} GB/s at {BYTES_PER_PARTICLE_STEP} B per "
        f"particle-step = {per_s:.2g} particle-steps/s",
        xy=(0.01, per_s),
        xycoords=("axes fraction", "data"),
        xytext=(0, 4),
        textcoords="offset points",
        fontsize=8,
    )
    ax.set_xscale("log")
    ax.set_yscale("log")
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, max(hi, per_s * 2.5))
    ax.set_xlabel("particles n")
    ax.set_ylabel("particle-steps per second\n(n x steps / median timed wall time)")
    right = ax.secondary_yaxis(
        "right",
        functions=(lambda y: y / per_s, lambda f: f * per_s),  # type: ignore[operator]  # stubs: y any ArrayLike
    )
    right.set_ylabel("fraction of the copy bandwidth")
    ax.grid(True, which="major", alpha=0.3)
    ax.set_title(
        "Particle rain: particle-steps per second against n, one engine per colour, "
        "one method per line style",
        fontsize=10,
    )
    if ax.get_legend_handles_labels()[0]:  # none when every row failed
        ax.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(1.11, 1.0), frameon=False)
    fig.tight_layout()
    return save(fig, path)
