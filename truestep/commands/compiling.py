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
        "is empty; a second call only loads them); with MuJoCo Warp or Newton "
        "installed, also their kernels for every scene they run, into Warp's "
        "kernel cache, each in a process of its own beside the reference's "
        "(about 40 s of one core each when empty).",
    )
    comp.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """``truestep compile``: compile the reference's loops for every case file of the library
    and of the figures, every fixed-step method, on every core, into numba's cache (what a
    first ``truestep run`` does before its first timed run), and the kernels of each
    installed engine that has a ``warm`` hook (Warp's engines) into its own cache, each
    engine in a forked process beside the reference's compile: a build step for a fresh
    machine. Exit 1 where an engine's kernels failed to compile (one line says which)."""
    import multiprocessing
    import time

    from truestep.adapters import adapter_class, engine_status, registered
    from truestep.cases import load_case, load_cases
    from truestep.figures.scenes import FIGURE_CASE_DIR
    from truestep.reference_impl.precompile import compile_all

    began = time.perf_counter()
    cases = [*load_cases("*"), *(load_case(p) for p in sorted(FIGURE_CASE_DIR.glob("*.toml")))]
    hooks = [
        (engine, warm)
        for engine in registered()
        if engine_status(engine) == "installed"
        and (warm := getattr(adapter_class(engine), "warm", None)) is not None
    ]
    context = multiprocessing.get_context("fork")
    apart = [
        (engine, context.Process(target=_warm_apart, args=(engine, warm, cases, os.getpid()), daemon=True))
        for engine, warm in hooks
    ]
    for _, proc in apart:
        proc.start()
    models = [c.model for c in cases if c.model is not None]
    workers = len(os.sched_getaffinity(0))
    compile_all(models, workers=workers, progress=lambda line: print(line, flush=True))
    print(f"reference loops ready in {time.perf_counter() - began:.1f} s ({workers} workers)", flush=True)
    failed = 0
    for engine, proc in apart:
        proc.join()
        if proc.exitcode != 0:
            failed += 1
            print(f"truestep: {engine} kernels: the compile ended with exit code {proc.exitcode}", flush=True)
    return 1 if failed else 0


def _warm_apart(engine: str, warm, cases: list, parent: int) -> None:
    """In a forked process: ``warm(cases)`` (an engine's kernels into its cache), its lines
    printed as they come; dies with ``parent``; exit 1, with one line, if it raises."""
    import sys
    import time

    from truestep.runtime.oscalls import helper_of

    helper_of(parent)
    began = time.perf_counter()
    try:
        built = warm(cases, say=lambda line: print(line, flush=True))
    except Exception as err:
        print(f"truestep: {engine} kernels: {type(err).__name__}: {str(err)[:300]}", flush=True)
        sys.exit(1)
    print(f"{engine} kernels ready in {time.perf_counter() - began:.1f} s ({built} scenes)", flush=True)
