"""The reference on every core: a rain of independent particles stepped on one thread and
on several, in one process, as particle-steps per second and their ratio.

A scene whose particles do not act on one another is cut into tiles of
:data:`~truestep.reference_impl.tiles.BLOCK` particles, each taken through all its steps
in the cache; ``ReferenceAdapter(threads=N)`` (``run_compiled(..., threads=N)``) steps N
tiles at once on N threads, with the same numbers, bit for bit (the script checks it).
The target on a 2-core machine: 2 threads at least 1.8 times one thread at 1e5
particles. Each size runs the lecture's symplectic Euler at 1 ms for the first
``--seconds`` of particle-rain (scaled so each run takes some tenths of a second), one
thread and N threads alternating, ``--repeats`` times; the medians are compared.

Usage: ``python benchmarks/reference_threads.py [--threads N] [--sizes 1e4,1e5,1e6]
[--repeats K]``. Run it on an otherwise idle machine with a warm numba cache.
"""

from __future__ import annotations

import argparse
import os
import statistics

from truestep import numerics

numerics.set_environment()

import numpy as np  # noqa: E402

from truestep.execution.bench import rain_case  # noqa: E402
from truestep.reference_impl.compiled import run_compiled  # noqa: E402

TARGET = 1.8
"""Two threads against one at 1e5 particles, on a 2-core machine."""
WORK = 5e7
"""Particle-steps of each timed run (at least 10 steps)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--threads", type=int, default=len(os.sched_getaffinity(0)), help="threads (default: every core)"
    )
    parser.add_argument("--sizes", default="1e4,1e5,1e6", help="particle counts (default 1e4,1e5,1e6)")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs of each kind per size (default 5)")
    args = parser.parse_args()
    dt, method = 1e-3, "symplectic-euler"
    print(f"reference {method}, dt {dt:g} s, particle-rain; 1 thread against {args.threads}")
    for n in (int(float(s)) for s in args.sizes.split(",")):
        model = rain_case(n).particles
        steps = max(10, min(1000, round(WORK / n)))
        run_compiled(model, method, 10 * dt, dt)  # compile or load the loop, fault the pages in
        walls: dict[int, list[float]] = {1: [], args.threads: []}
        runs = {}
        for _ in range(args.repeats):
            for threads in walls:
                run, wall = run_compiled(model, method, steps * dt, dt, max_records=20, threads=threads)
                walls[threads].append(wall)
                runs[threads] = run
        one, many = (statistics.median(walls[k]) for k in walls)
        same = all(
            np.array_equal(getattr(runs[1], f), getattr(runs[args.threads], f), equal_nan=True)
            for f in ("t", "x", "v")
        )
        ratio = one / many
        said = f" (target >= {TARGET:g})" if n == 100_000 and args.threads == 2 else ""
        print(
            f"n={n:.0e}: 1 thread {n * steps / one:.3g}, {args.threads} threads {n * steps / many:.3g} "
            f"particle-steps/s; ratio {ratio:.2f}{said}; records identical: {same}"
        )


if __name__ == "__main__":
    main()
