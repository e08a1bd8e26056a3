"""``truestep compile``: the reference's loops (and the engines' kernels) compiled ahead."""

from __future__ import annotations

import argparse
import os


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``compile`` command's parser, under ``sub``."""
    comp = sub.add_parser(
        "compile",
        help="compile the reference's loops ahead (a build step)",
        description="Compile the reference implementation's loops for every "
        "case of the library and of the figures and every fixed-step method, "
        "on every core, into numba's on-disk cache, as a first `truestep run` "
        "does before its first timed run (about 70 s on 2 cores when the cache "
        "is empty; a second call only loads them); with MuJoCo Warp installed, "
        "also its kernels for every scene it runs, into Warp's kernel cache "
        "(about 60 s on one core when empty).",
    )
    comp.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """``truestep compile``: compile the reference's loops for every case file of the library
    and of the figures, every fixed-step method, on every core, into numba's cache (what a
    first ``truestep run`` does before its first timed run): a build step for a fresh
    machine."""
    import time

    from truestep.cases import load_case, load_cases
    from truestep.figures.scenes import FIGURE_CASE_DIR
    from truestep.reference_impl.precompile import compile_all

    began = time.perf_counter()
    cases = [*load_cases("*"), *(load_case(p) for p in sorted(FIGURE_CASE_DIR.glob("*.toml")))]
    models = [c.model for c in cases if c.model is not None]
    workers = len(os.sched_getaffinity(0))
    compile_all(models, workers=workers, progress=lambda line: print(line, flush=True))
    print(f"reference loops ready in {time.perf_counter() - began:.1f} s ({workers} workers)")
    from truestep.adapters import adapter_class, engine_status, registered

    for engine in registered():
        if engine_status(engine) != "installed":
            continue
        warm = getattr(adapter_class(engine), "warm", None)
        if warm is not None:
            began = time.perf_counter()
            built = warm(cases, say=lambda line: print(line, flush=True))
            print(f"{engine} kernels ready in {time.perf_counter() - began:.1f} s ({built} scenes)")
    return 0
