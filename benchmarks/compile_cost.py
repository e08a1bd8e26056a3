"""What compiling the reference's loops costs on a machine with nothing in numba's cache.

Compiles every loop the case library (and the figure cases) need, for every fixed-step
method, into a fresh cache directory, and prints each loop's time and the total, with
``--workers 1`` (one core) or more (forked processes, as ``truestep run`` compiles ahead).

Usage: ``python benchmarks/compile_cost.py [--workers N]`` (the cache directory is made
and removed here; NUMBA_CACHE_DIR must be set before numba is imported, so the script
runs itself again in a child process with it).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time


def measure(workers: int) -> None:
    began = time.perf_counter()
    from truestep.cases import load_case, load_cases
    from truestep.figures.scenes import FIGURE_CASE_DIR
    from truestep.reference_impl.precompile import compile_all, loops_needed
    from truestep.reference_impl.solvers import METHODS

    cases = [*load_cases("*"), *(load_case(p) for p in sorted(FIGURE_CASE_DIR.glob("*.toml")))]
    models = [c.model for c in cases if c.model is not None]
    loops = len(loops_needed([(m, name) for m in models for name in METHODS]))
    imported = time.perf_counter()
    compile_all(models, workers=workers, progress=lambda line: print(line, flush=True))
    done = time.perf_counter()
    print(
        f"{loops} loops compiled with {workers} worker(s) in {done - imported:.1f} s "
        f"(imports {imported - began:.1f} s)"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        measure(args.workers)
        return 0
    with tempfile.TemporaryDirectory(prefix="truestep-numba-") as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        return subprocess.call([sys.executable, __file__, "--child", "--workers", str(args.workers)], env=env)


if __name__ == "__main__":
    sys.exit(main())
