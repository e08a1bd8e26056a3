"""Harness overhead of the engine adapters: ``adapter.simulate`` against a bare engine loop.

Run: ``/work/venv/bin/python -m pytest benchmarks/test_adapter_overhead.py --benchmark-enable -q -s``
Under ``--benchmark-skip`` (the project's default options, when they carry it) every test
here skips: together they take five to six minutes on this machine.

For each engine and method and each scene (``bouncing-ball``: one body and the engine's
own forces only, every step recorded at ``dt`` = 1 ms; ``particle-rain``: 1000 bodies,
151 records in 1500 steps) a test times, alternately (A B A B ...: machine noise hits
both alike),

- **A**, the adapter: ``adapter.simulate(case, method, dt).wall_s``, the adapter's own
  timed region (stepping and reading back the recorded states);
- **B**, a bare loop: the scene built by the adapter's own build function outside the
  timing, then only the engine's own calls, written as plainly as a user would: the
  same number of steps and the same reads (positions and velocities of every body) at
  the same recorded steps (:func:`truestep.reference_impl.integrate.record_indices`).

One warm-up pair, then :data:`REPEATS` to :data:`MAX_REPEATS` pairs (short runs repeat
more, see :data:`MIN_SECONDS`); the ratio is median(A) / median(B), the target at most
:data:`TARGET`. The machine is shared and noisy: compare ratios measured
in the same run, never absolute times across runs. pytest-benchmark's own statistics
time a whole pair (scene builds included); the numbers that matter are in
``benchmark.extra_info`` and in the table printed at the end (``-s``).

``test_mujoco_rollout`` times the ways of stepping MuJoCo with no per-step Python force:
one ``mj_step`` call per step (the bare loop above), ``mj_step(m, d, nstep=k)`` from
record to record, and one ``mujoco.rollout.rollout`` over the whole run (every step's
state stored, the records picked out), each as a ratio to the first. (The adapter uses
rollout in stretches of at most 64 steps; see :mod:`truestep.adapters.mujoco_adapter`.)
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np
import pybullet as p
import pymunk.batch
import pytest
from mujoco import rollout

from truestep.adapters.mujoco_adapter import MujocoAdapter
from truestep.adapters.mujoco_adapter import build as mujoco_build
from truestep.adapters.pybullet_adapter import PybulletAdapter
from truestep.adapters.pybullet_adapter import build_scene as pybullet_build
from truestep.adapters.pymunk_adapter import PymunkAdapter
from truestep.adapters.pymunk_adapter import build_scene as pymunk_build
from truestep.cases.case import Case
from truestep.cases.loader import CASE_DIR, load_case
from truestep.reference_impl.integrate import record_indices

SCENES: dict[str, float] = {"bouncing-ball": 1e-3, "particle-rain": 1e-3}
"""Scene name -> the step (s) it runs at: each case's finest step in its sweep."""
RUNS: list[tuple[str, str]] = [
    ("pymunk", "default"),
    ("pybullet", "default"),
    ("pybullet", "clean"),
    ("mujoco", "Euler"),
    ("mujoco", "RK4"),
]
REPEATS = 5
"""Fewest timed rounds per test, after one warm-up round."""
MIN_SECONDS = 0.5
"""Short runs repeat until each way has been timed for about this long (the one-ball
scene runs for 10-40 ms, where a shared machine's noise is several per cent)..."""
MAX_REPEATS = 60
"""... but at most this many rounds."""
WARMUP = 1
TARGET = 1.05
"""Adapter / bare loop: the adapter may be at most 5 % slower."""

Bare = Callable[[Case, str, float], tuple[float, np.ndarray]]
"""A bare loop: ``(case, method, dt) -> (seconds in the loop, last recorded positions)``."""


def bare_pymunk(case: Case, method: str, dt: float) -> tuple[float, np.ndarray]:
    """``space.step`` and pymunk's batched read of every body's position and velocity."""
    n_steps, h = case.steps_for(dt)
    marks = np.zeros(n_steps + 1, dtype=bool)
    marks[record_indices(n_steps, case.max_records)] = True
    scene = pymunk_build(case.model, collision_slop=PymunkAdapter.collision_slop)
    space = scene.space
    fields = pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.VELOCITY
    buffer = pymunk.batch.Buffer()
    states = []
    start = time.perf_counter()
    for k in range(1, n_steps + 1):
        space.step(h)
        if marks[k]:
            buffer.clear()
            pymunk.batch.get_space_bodies(space, fields, buffer)
            states.append(bytes(buffer.float_buf()))
    wall = time.perf_counter() - start
    x = np.zeros((case.model.n, 2))
    x[scene.slot] = np.frombuffer(states[-1], dtype=float).reshape(-1, 4)[scene.rows, :2]
    return wall, x


def bare_pybullet(case: Case, method: str, dt: float) -> tuple[float, np.ndarray]:
    """``p.stepSimulation`` and one position and one velocity call per body."""
    n_steps, h = case.steps_for(dt)
    marks = np.zeros(n_steps + 1, dtype=bool)
    marks[record_indices(n_steps, case.max_records)] = True
    scene = pybullet_build(case.model, h, clean=method == "clean")
    cid, bodies = scene.client, scene.bodies.tolist()
    xs, vs = [], []
    try:
        start = time.perf_counter()
        for k in range(1, n_steps + 1):
            p.stepSimulation(physicsClientId=cid)
            if marks[k]:
                xs.append([p.getBasePositionAndOrientation(b, physicsClientId=cid)[0] for b in bodies])
                vs.append([p.getBaseVelocity(b, physicsClientId=cid)[0] for b in bodies])
        wall = time.perf_counter() - start
    finally:
        p.disconnect(cid)
    return wall, np.array(xs[-1])[:, :2]


def bare_mujoco(case: Case, method: str, dt: float) -> tuple[float, np.ndarray]:
    """One ``mj_step`` per step; ``qpos`` and ``qvel`` copied at the records."""
    n_steps = case.steps_for(dt)[0]
    marks = np.zeros(n_steps + 1, dtype=bool)
    marks[record_indices(n_steps, case.max_records)] = True
    scene = mujoco_build(case, method, dt)
    m, d = scene.model, scene.data
    qpos, qvel = [], []
    start = time.perf_counter()
    for k in range(1, n_steps + 1):
        mujoco.mj_step(m, d)
        if marks[k]:
            qpos.append(d.qpos.copy())
            qvel.append(d.qvel.copy())
    wall = time.perf_counter() - start
    return wall, qpos[-1].reshape(-1, scene.layout.dim)[:, :2]


def mujoco_chunks(case: Case, method: str, dt: float) -> tuple[float, np.ndarray]:
    """``mj_step(m, d, nstep=k)`` from one record to the next; ``qpos``, ``qvel`` copied there."""
    marks = record_indices(case.steps_for(dt)[0], case.max_records)
    scene = mujoco_build(case, method, dt)
    m, d = scene.model, scene.data
    qpos, qvel = [], []
    start = time.perf_counter()
    for chunk in np.diff(marks).tolist():
        mujoco.mj_step(m, d, nstep=chunk)
        qpos.append(d.qpos.copy())
        qvel.append(d.qvel.copy())
    wall = time.perf_counter() - start
    return wall, qpos[-1].reshape(-1, scene.layout.dim)[:, :2]


def mujoco_rollout(case: Case, method: str, dt: float) -> tuple[float, np.ndarray]:
    """One ``rollout.rollout`` over every step (states stored per step), records picked out.

    The output array is allocated outside the timing, as a user rolling out repeatedly would.
    """
    n_steps = case.steps_for(dt)[0]
    picks = record_indices(n_steps, case.max_records)[1:] - 1
    scene = mujoco_build(case, method, dt)
    m, d = scene.model, scene.data
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    initial = np.empty(mujoco.mj_stateSize(m, spec))
    mujoco.mj_getState(m, d, initial, spec)
    state = np.empty((1, n_steps, initial.size))
    sensordata = np.empty((1, n_steps, m.nsensordata))
    start = time.perf_counter()
    rollout.rollout(m, d, initial[None], nstep=n_steps, state=state, sensordata=sensordata)
    qpos = state[0, picks, 1 : 1 + m.nq].copy()
    qvel = state[0, picks, 1 + m.nq : 1 + m.nq + m.nv].copy()
    wall = time.perf_counter() - start
    assert qvel.shape == (len(picks), m.nv)
    return wall, qpos[-1].reshape(-1, scene.layout.dim)[:, :2]


ENGINES: dict[str, tuple[Callable[[], Any], Bare]] = {
    "pymunk": (PymunkAdapter, bare_pymunk),
    "pybullet": (PybulletAdapter, bare_pybullet),
    "mujoco": (MujocoAdapter, bare_mujoco),
}


@pytest.fixture(scope="module")
def table():
    """Rows collected by the tests, printed at the end of the module (``-s`` shows them).

    Each row: (table, scene, engine, method, median A in s, median B in s, A / B of the
    medians, A / B of the fastest runs: less sensitive to another process's bursts).
    """
    rows: list[tuple[str, str, str, str, float, float, float, float]] = []
    yield rows
    heads = {
        "overhead": (
            f"adapter overhead, A = adapter.simulate(...).wall_s, B = bare engine loop; "
            f"median of {REPEATS}-{MAX_REPEATS} interleaved runs after {WARMUP} warm-up; target "
            f"A/B <= {TARGET:.2f}"
        ),
        "stepping": (
            f"MuJoCo without per-step Python forces, A = the way named, B = one mj_step "
            f"call per step; median of {REPEATS}-{MAX_REPEATS} interleaved runs after {WARMUP} "
            "warm-up"
        ),
    }
    for kind, head in heads.items():
        mine = [row[1:] for row in rows if row[0] == kind]
        if not mine:
            continue
        print(f"\n\n{head}")
        print(
            f"{'scene':14s} {'engine':9s} {'method':22s} {'A s':>9s} {'B s':>9s} {'A/B':>6s} "
            f"{'min A/min B':>11s}"
        )
        for scene, engine, method, a, b, ratio, best in mine:
            flag = "  > target" if kind == "overhead" and ratio > TARGET else ""
            print(f"{scene:14s} {engine:9s} {method:22s} {a:9.4f} {b:9.4f} {ratio:6.3f} {best:11.3f}{flag}")


def interleave(benchmark, runs: list[Callable[[], float]]) -> list[list[float]]:
    """Time each of ``runs`` (each returns its own seconds) in turn, round after round.

    One warm-up round, then as many rounds as give the fastest way :data:`MIN_SECONDS`
    of timed runs (:data:`REPEATS` to :data:`MAX_REPEATS`). Returns the timed samples of
    each way, warm-up dropped.
    """
    samples: list[list[float]] = [[] for _ in runs]

    def one_round() -> None:
        for run, sample in zip(runs, samples, strict=True):
            sample.append(run())

    one_round()
    shortest = min(sample[0] for sample in samples)
    rounds = min(MAX_REPEATS, max(REPEATS, math.ceil(MIN_SECONDS / shortest)))
    benchmark.pedantic(one_round, rounds=rounds, iterations=1)
    benchmark.extra_info["rounds"] = rounds
    return [sample[WARMUP:] for sample in samples]


@pytest.mark.engine
@pytest.mark.parametrize("scene", list(SCENES))
@pytest.mark.parametrize(("engine", "method"), RUNS)
def test_adapter_overhead(benchmark, table, engine, method, scene):
    case, dt = load_case(CASE_DIR / f"{scene}.toml"), SCENES[scene]
    make_adapter, bare = ENGINES[engine]
    adapter = make_adapter()
    last: dict[str, np.ndarray] = {}

    def run_adapter() -> float:
        trajectory = adapter.simulate(case, method, dt)
        assert trajectory.status == "ok", trajectory.message
        last["adapter"] = trajectory.x[-1, :, :2]
        return trajectory.wall_s

    def run_bare() -> float:
        wall, last["bare"] = bare(case, method, dt)
        return wall

    benchmark.group = f"adapter overhead: {scene}"
    a, b = interleave(benchmark, [run_adapter, run_bare])
    # Same engine, same scene, same calls: the two loops must end in the same state, to
    # the last bit (all three engines are deterministic within a process).
    np.testing.assert_array_equal(last["adapter"], last["bare"])
    ratio, best = statistics.median(a) / statistics.median(b), min(a) / min(b)
    benchmark.extra_info.update(
        adapter_s=a,
        bare_s=b,
        adapter_median_s=statistics.median(a),
        bare_median_s=statistics.median(b),
        ratio=ratio,
        ratio_of_minima=best,
        target=TARGET,
    )
    table.append(("overhead", scene, engine, method, statistics.median(a), statistics.median(b), ratio, best))


@pytest.mark.engine
@pytest.mark.parametrize("scene", list(SCENES))
@pytest.mark.parametrize("method", ["Euler", "RK4"])
def test_mujoco_rollout(benchmark, table, method, scene):
    case, dt = load_case(CASE_DIR / f"{scene}.toml"), SCENES[scene]
    loops = {"mj_step": bare_mujoco, "mj_step nstep": mujoco_chunks, "rollout": mujoco_rollout}
    last: dict[str, np.ndarray] = {}

    def timed(name: str) -> Callable[[], float]:
        def run() -> float:
            wall, last[name] = loops[name](case, method, dt)
            return wall

        return run

    benchmark.group = f"mujoco stepping: {scene}"
    samples = dict(zip(loops, interleave(benchmark, [timed(name) for name in loops]), strict=True))
    for name in loops:
        # The same steps of the same model, whoever loops: bitwise equal end states.
        np.testing.assert_array_equal(last[name], last["mj_step"])
    base, fastest = statistics.median(samples["mj_step"]), min(samples["mj_step"])
    for name, sample in samples.items():
        benchmark.extra_info[f"{name}_s"] = sample
        benchmark.extra_info[f"{name}_ratio"] = statistics.median(sample) / base
        if name != "mj_step":
            table.append(
                (
                    "stepping",
                    scene,
                    "mujoco",
                    f"{method}, {name}",
                    statistics.median(sample),
                    base,
                    statistics.median(sample) / base,
                    min(sample) / fastest,
                )
            )
