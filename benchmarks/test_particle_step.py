"""Particle rain: gravity, drag and a floor plane, stepped by the lecture's update.

Run: ``python -m pytest benchmarks/test_particle_step.py --benchmark-only -q`` (or with
``--benchmark-enable`` where ``addopts`` does not say ``--benchmark-skip``).

Each test prints particle-steps per second (from the median round, and the best round)
and the fraction of the machine's memory bandwidth the call used, measured in the same
run: the bandwidth is that of a numpy copy of a 256 MB array (bytes moved = 2 x its size,
best of 5), and a step of the compiled path
(:func:`truestep.reference_impl.compiled.run_compiled`, the lecture's update) reads and
writes ``n`` particles' positions and velocities (96 bytes) at least once. ``steps = 1``
is a single step per call (memory-bound at large n); ``steps = 100`` is a run of 100
steps, as the ``particle-rain`` case makes them. The numpy rows step the same scene
through :class:`~truestep.reference_impl.particles.ParticleSystem` with the lecture's
solver and the collision pass: the reference implementation the compiled path is tested
equal to.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from truestep.reference_impl.compiled import run_compiled
from truestep.reference_impl.model import ParticleModel, Plane
from truestep.reference_impl.particles import ParticleSystem
from truestep.reference_impl.passes import passes_for
from truestep.reference_impl.solvers import LectureUpdate

GRAVITY = np.array([0.0, -9.81, 0.0])
DRAG, MASS, RADIUS, RESTITUTION, DT = 0.05, 0.01, 0.005, 0.6, 1e-3
FLOOR_POINT, FLOOR_NORMAL = np.zeros(3), np.array([0.0, 1.0, 0.0])
BYTES_PER_PARTICLE = 2 * (6 * 8)


@pytest.fixture(scope="module")
def bandwidth() -> float:
    """Memory bandwidth of this machine now, bytes/s: numpy copy of 256 MB, best of 5."""
    src = np.random.default_rng(0).random(2**25)
    dst = np.empty_like(src)
    best = np.inf
    for _ in range(5):
        start = time.perf_counter()
        np.copyto(dst, src)
        best = min(best, time.perf_counter() - start)
    return 2 * src.nbytes / best


def rain(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions (n, 3) above the floor, velocities (n, 3), contact flags (n,)."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1.0, 1.0, (n, 3))
    x[:, 1] = rng.uniform(RADIUS, 2.0, n)
    v = rng.normal(0.0, 1.0, (n, 3))
    return x, v, np.zeros(n, dtype=bool)


def report(
    benchmark, capsys, label: str, n: int, steps: int, bandwidth: float, walls: list[float] | None = None
) -> None:
    """Print and store the rates, from the benchmark's rounds or from ``walls`` (the
    stepping times the compiled path reports, packing and allocation excluded)."""
    median = float(np.median(walls)) if walls else benchmark.stats.stats.median
    rate = n * steps / median
    best = n * steps / (min(walls) if walls else benchmark.stats.stats.min)
    used = BYTES_PER_PARTICLE * n / median
    benchmark.extra_info.update(
        particle_steps_per_s=rate,
        best_particle_steps_per_s=best,
        bandwidth_fraction=used / bandwidth,
        bandwidth_bytes_per_s=bandwidth,
    )
    with capsys.disabled():
        print(
            f"\n{label:6s} n={n:>8d} steps/call={steps:>3d}: {rate:9.3g} particle-steps/s "
            f"(best round {best:9.3g}), {used / 1e9:6.2f} GB/s = {used / bandwidth:6.1%} of the "
            f"{bandwidth / 1e9:.1f} GB/s copy bandwidth"
        )


def rain_model(n: int) -> ParticleModel:
    x0, v0, _ = rain(n)
    return ParticleModel(
        mass=np.full(n, MASS),
        x0=x0,
        v0=v0,
        radius=np.full(n, RADIUS),
        fixed=np.zeros(n, bool),
        gravity=GRAVITY,
        drag=DRAG,
        planes=[Plane(FLOOR_POINT, FLOOR_NORMAL, RESTITUTION)],
    )


@pytest.mark.parametrize("steps", [1, 100])
@pytest.mark.parametrize("n", [1_000, 100_000, 1_000_000])
def test_rain_compiled(benchmark, capsys, bandwidth, n, steps):
    model = rain_model(n)
    run_compiled(rain_model(10), "lecture", DT, DT)  # compile (or load) outside the timing

    walls: list[float] = []

    def one_run() -> None:
        walls.append(run_compiled(model, "lecture", steps * DT, DT, max_records=1)[1])

    benchmark.group = f"rain, n = {n}"
    rounds = max(3, min(50, int(2e8 // (n * steps))))
    benchmark.pedantic(one_run, rounds=rounds, warmup_rounds=1)
    report(benchmark, capsys, "numba", n, steps, bandwidth, walls[1:])


@pytest.mark.parametrize("n", [1_000, 100_000])
def test_rain_numpy_reference(benchmark, capsys, bandwidth, n):
    x0, v0, _ = rain(n)
    model = ParticleModel(
        mass=np.full(n, MASS),
        x0=x0,
        v0=v0,
        radius=np.full(n, RADIUS),
        fixed=np.zeros(n, bool),
        gravity=GRAVITY,
        drag=DRAG,
        planes=[Plane(FLOOR_POINT, FLOOR_NORMAL, RESTITUTION)],
    )
    system = ParticleSystem(model, passes_for(model))
    solver = LectureUpdate(system)

    def step() -> None:
        solver.step(DT)
        system.between_steps(DT)

    benchmark.group = f"rain, n = {n}"
    benchmark.pedantic(step, rounds=max(5, min(200, int(2e7 // n))), warmup_rounds=1)
    report(benchmark, capsys, "numpy", n, 1, bandwidth)
    assert np.all(np.isfinite(system.get_state()))
