"""How fast the compiled reference steps, as ratios to the engines measured in the same run.

Run: ``python -m pytest benchmarks/test_reference_speed.py -q -s`` (``-s`` prints the
tables at the end; about ten minutes on this machine, most of it the engines' own runs).
The machine is shared and noisy: every comparison here is a ratio of runs timed in turn
(A B A B ...) in one process, each an ``adapter.simulate(...).wall_s`` of the run
``results.csv`` times (:func:`timed`: the stepping, and the reading back of the three records
a timed run of a fixed-step method keeps), medians of
:data:`REPEATS` to :data:`MAX_REPEATS` rounds after one warm-up round.

- :func:`test_one_particle_step`: a particle on a spring (``harmonic-oscillator``, 1000
  steps of 2 ms), the cost of one step for every fixed-step reference method, beside
  MuJoCo's Euler in the same run. Targets (issue 21): RK4 at most
  :data:`PER_STEP_TARGET_NS` ``["rk4"]``, Euler ``["euler"]``.
- :func:`test_rain_against_every_engine`: ``particle-rain`` (1000 balls) at 1 ms, the
  reference's lecture update against every method of every engine, with no more error
  than the engine; target at least :data:`RAIN_TARGET` times the fastest engine.
- :func:`test_every_method_against_the_fastest_engine`: on every case the reference
  compiles that an engine also runs, at every step of its sweep where the fastest
  engine method takes at least :data:`SHARED_MIN_S`, every fixed-step reference method;
  target at least :data:`SHARED_TARGET` times that engine. Runs that blow up (timed to
  their blow-up in ``results.csv``) are left out, on both sides.

A missed target fails its test, with the numbers; the printed tables hold the rest.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable

import pytest

from truestep.adapters import get_adapter
from truestep.cases import load_cases
from truestep.cases.case import Case
from truestep.cases.loader import CASE_DIR, load_case
from truestep.execution.runner import measure, plan
from truestep.execution.timing import timed_case
from truestep.reference_impl.compiled import compiled_reason

FIXED = ["euler", "midpoint", "heun", "rk4", "symplectic-euler", "verlet", "lecture"]
ENGINES = ["pymunk", "pybullet", "mujoco"]
REPEATS = 5
"""Fewest timed rounds, after one warm-up round."""
MAX_REPEATS = 200
"""Most timed rounds."""
MIN_SECONDS = 0.3
"""Short runs repeat until the fastest way has been timed for about this long."""
PER_STEP_TARGET_NS = {"rk4": 50.0, "euler": 20.0}
RAIN_TARGET = 100.0
SHARED_TARGET = 10.0
SHARED_MIN_S = 1e-3


def timed(engine: str, case: Case, method: str, dt: float) -> Callable[[], float]:
    """A run of ``case`` by ``engine``/``method`` at ``dt``, returning its ``wall_s``: the
    run ``results.csv`` times (:func:`~truestep.execution.timing.timed_case`: a fixed-step
    method keeps its start, middle and end, not the case's records)."""
    adapter = get_adapter(engine)
    lean = timed_case(adapter, case, method)

    def run() -> float:
        trajectory = adapter.simulate(lean, method, dt)
        assert trajectory.status == "ok", f"{engine}/{method}: {trajectory.message}"
        return trajectory.wall_s

    return run


def runs_ok(engine: str, case: Case, method: str, dt: float) -> bool:
    """Whether ``engine``/``method`` runs ``case`` at ``dt`` to the end (as ``results.csv``
    compares: a run that blew up is timed to its blow-up, a time of no use here)."""
    return get_adapter(engine).simulate(case, method, dt).status == "ok"


def interleave(runs: list[Callable[[], float]]) -> list[float]:
    """The median seconds of each of ``runs``, timed in turn round after round: one
    warm-up round, then as many as give the fastest :data:`MIN_SECONDS` of timed runs."""
    samples: list[list[float]] = [[run()] for run in runs]
    shortest = min(s[0] for s in samples)
    rounds = min(MAX_REPEATS, max(REPEATS, math.ceil(MIN_SECONDS / max(shortest, 1e-9))))
    for _ in range(rounds):
        for run, sample in zip(runs, samples, strict=True):
            sample.append(run())
    return [statistics.median(s[1:]) for s in samples]


@pytest.fixture(scope="module")
def table():
    """Rows the tests add, printed at the end of the module (``-s`` shows them)."""
    rows: list[str] = []
    yield rows
    print("\n\n" + "\n".join(rows))


@pytest.mark.engine
def test_one_particle_step(benchmark, table):
    case, dt = load_case(CASE_DIR / "harmonic-oscillator.toml"), 2e-3
    steps = case.steps_for(dt)[0]
    runs = [timed("reference", case, m, dt) for m in FIXED] + [timed("mujoco", case, "Euler", dt)]
    walls = benchmark.pedantic(interleave, args=(runs,), rounds=1, iterations=1)
    per_step = {m: w / steps * 1e9 for m, w in zip([*FIXED, "mujoco/Euler"], walls, strict=True)}
    benchmark.extra_info.update(ns_per_step=per_step)
    table.append(f"one particle on a spring, {steps} steps of {dt * 1e3:g} ms: ns per step")
    table += [
        f"  {m:18s} {ns:8.1f}"
        + (f"   target <= {PER_STEP_TARGET_NS[m]:g}" if m in PER_STEP_TARGET_NS else "")
        for m, ns in per_step.items()
    ]
    missed = {m: round(per_step[m], 1) for m, t in PER_STEP_TARGET_NS.items() if per_step[m] > t}
    assert not missed, f"ns per step over the targets {PER_STEP_TARGET_NS}: {missed}"


def rain_runs() -> list[tuple[str, str]]:
    case = load_case(CASE_DIR / "particle-rain.toml")
    return [
        (engine, method)
        for engine in ENGINES
        for method, _, adaptive, why_not in plan(case, engine, quick=False)
        if not why_not and not adaptive
    ]


@pytest.mark.engine
@pytest.mark.parametrize(("engine", "method"), sorted(set(rain_runs())))
def test_rain_against_every_engine(benchmark, table, engine, method):
    case, dt = load_case(CASE_DIR / "particle-rain.toml"), 1e-3
    ours, theirs = benchmark.pedantic(
        interleave,
        args=([timed("reference", case, "lecture", dt), timed(engine, case, method, dt)],),
        rounds=1,
        iterations=1,
    )
    error = {
        e: measure(case, get_adapter(e).simulate(case, m, dt))["error"]
        for e, m in (("reference", "lecture"), (engine, method))
    }
    ratio = theirs / ours
    benchmark.extra_info.update(reference_s=ours, engine_s=theirs, ratio=ratio, error=error)
    table.append(
        f"rain at 1 ms: reference/lecture {ours * 1e3:.3f} ms, {engine}/{method} "
        f"{theirs * 1e3:.3f} ms: {ratio:6.1f}x; error {error['reference']:.3g} m "
        f"against {error[engine]:.3g} m; {1e6 / ours:.3g} particle-steps/s"
    )
    assert error["reference"] <= error[engine]
    if engine == "pymunk":  # the fastest engine on rain
        assert ratio >= RAIN_TARGET, f"{ratio:.1f}x pymunk, target {RAIN_TARGET:g}x"


def shared_cases() -> list[Case]:
    return [
        c
        for c in load_cases("*")
        if compiled_reason(c.model, "rk4") is None
        and any(not why for e in ENGINES for _, _, _, why in plan(c, e, quick=False))
    ]


@pytest.mark.engine
@pytest.mark.parametrize("case", shared_cases(), ids=lambda c: c.name)
def test_every_method_against_the_fastest_engine(benchmark, table, case):
    worst: list[str] = []

    def measure_case() -> None:
        for dt in case.dts:
            engines = [
                (e, m)
                for e in ENGINES
                for m, d, adaptive, why in plan(case, e, quick=False)
                if not why and not adaptive and d == dt and runs_ok(e, case, m, dt)
            ]
            if not engines:
                continue
            first = {em: timed(*em[:1], case, em[1], dt)() for em in engines}
            fastest = min(first, key=first.get)
            if first[fastest] < SHARED_MIN_S:
                continue
            ours = [m for m in FIXED if not plan_skips(case, m) and runs_ok("reference", case, m, dt)]
            runs = [timed(fastest[0], case, fastest[1], dt)]
            runs += [timed("reference", case, m, dt) for m in ours]
            walls = interleave(runs)
            for m, w in zip(ours, walls[1:], strict=True):
                ratio = walls[0] / w
                line = (
                    f"{case.name:20s} dt={dt:<9.3g} {m:17s} {w * 1e3:9.4f} ms, "
                    f"{fastest[0]}/{fastest[1]} {walls[0] * 1e3:9.4f} ms: {ratio:6.1f}x"
                )
                table.append(line)
                benchmark.extra_info[f"{m}@{dt:g}"] = ratio
                if ratio < SHARED_TARGET:
                    worst.append(line)

    benchmark.pedantic(measure_case, rounds=1, iterations=1)
    assert not worst, "under the target of " + f"{SHARED_TARGET:g}x:\n" + "\n".join(worst)


def plan_skips(case: Case, method: str) -> bool:
    """Whether the runner leaves ``method`` of the reference out on ``case``."""
    return any(why for m, _, _, why in plan(case, "reference", quick=False) if m == method)
