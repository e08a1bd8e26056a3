"""``truestep compile``'s work: the reference's loops for the cases given (the library's
and the figures'), compiled on every core into numba's cache, and each installed engine's
kernels (its optional ``warm`` hook) into its own cache, each engine in a forked process
beside the reference's compile: a build step for a fresh machine."""

from __future__ import annotations

import multiprocessing
import os
import time
from collections.abc import Callable

from truestep.cases.case import Case


def compile_everything(cases: list[Case], say: Callable[[str], None]) -> list[str]:
    """Compile the reference's loops for ``cases`` and every installed engine's kernels for
    them (each line of progress through ``say``, as it comes); return the engines whose
    kernels failed to compile (each said in one line)."""
    from truestep.adapters import adapter_class, engine_status, registered
    from truestep.reference_impl.precompile import compile_all

    began = time.perf_counter()
    hooks = [
        (engine, warm)
        for engine in registered()
        if engine_status(engine) == "installed"
        and (warm := getattr(adapter_class(engine), "warm", None)) is not None
    ]
    context = multiprocessing.get_context("fork")
    apart = [
        (
            engine,
            context.Process(target=warm_apart, args=(engine, warm, cases, os.getpid(), say), daemon=True),
        )
        for engine, warm in hooks
    ]
    for _, proc in apart:
        proc.start()
    models = [c.model for c in cases if c.model is not None]
    workers = len(os.sched_getaffinity(0))
    compile_all(models, workers=workers, progress=say)
    if any(c.kind == "ode" for c in cases):
        from truestep.reference_impl.odes_loop import warm as warm_ode_loop

        warm_ode_loop(say)
    say(f"reference loops ready in {time.perf_counter() - began:.1f} s ({workers} workers)")
    failed = []
    for engine, proc in apart:
        proc.join()
        if proc.exitcode != 0:
            failed.append(engine)
            say(f"truestep: {engine} kernels: the compile ended with exit code {proc.exitcode}")
    return failed


def warm_apart(engine: str, warm, cases: list, parent: int, say: Callable[[str], None]) -> None:
    """In a forked process: ``warm(cases)`` (an engine's kernels into its cache), its lines
    through ``say`` as they come; dies with ``parent``; exit 1, with one line, if it
    raises."""
    import sys

    from truestep.runtime.oscalls import helper_of

    helper_of(parent)
    began = time.perf_counter()
    try:
        built = warm(cases, say=say)
    except Exception as err:
        say(f"truestep: {engine} kernels: {type(err).__name__}: {str(err)[:300]}")
        sys.exit(1)
    say(f"{engine} kernels ready in {time.perf_counter() - began:.1f} s ({built} scenes)")
