"""The compiled reference's stepping time on a few rows of each layout, to compare revisions.

Each row (case, method, step) runs once to compile or load its loop, then seven times;
the script prints the fastest and the median wall time of the compiled loop alone
(:func:`~truestep.reference_impl.compiled.run_compiled`: packing, compiling and records
are outside it). Rows: one particle (harmonic-oscillator), the rain's 1000 independent
particles (fused layout, vectorised), a cloth and a chain (passes layout), a ball on a
plane (fused, one tile: velocity Verlet).

Usage: ``python benchmarks/compiled_speed.py``. To compare with another revision, run it
from a worktree of that revision with ``PYTHONPATH=<worktree>`` in the same hour, on an
otherwise idle machine; the numbers are seconds of this machine, not ratios.
"""

from __future__ import annotations

import argparse
import statistics

from truestep.cases import library, load_case
from truestep.reference_impl.compiled import run_compiled

ROWS = (
    ("harmonic-oscillator", "rk4", 2e-3),
    ("harmonic-oscillator", "lecture", 2e-3),
    ("particle-rain", "lecture", 1e-3),
    ("particle-rain", "rk4", 1e-3),
    ("hanging-cloth", "rk4", 1e-3),
    ("hanging-cloth", "lecture", 1e-3),
    ("spring-chain", "verlet", 1e-3),
    ("bouncing-ball", "verlet", 1e-3),
)
"""(case, method, step in s) of each row."""
REPEATS = 7


def main() -> None:
    layout = argparse.RawDescriptionHelpFormatter
    argparse.ArgumentParser(description=__doc__, formatter_class=layout).parse_args()
    cases = library()
    for name, method, dt in ROWS:
        model = load_case(cases[name]).model
        duration = load_case(cases[name]).duration
        run_compiled(model, method, duration, dt, progress=lambda line: None)
        walls = [run_compiled(model, method, duration, dt)[1] for _ in range(REPEATS)]
        print(
            f"{name:20s} {method:8s} {dt:g} s  fastest {min(walls) * 1e3:9.3f} ms"
            f"  median {statistics.median(walls) * 1e3:9.3f} ms"
        )


if __name__ == "__main__":
    main()
