"""Compiling the reference's loops ahead of the runs that need them, on every core.

A compiled loop (:mod:`~truestep.reference_impl.compiled`) takes seconds to compile, on one
core, and milliseconds to load from numba's cache on disk. :func:`compile_all` compiles the
loops a sweep (or a test session) will need before it starts, several at once in forked
processes, so that the runs, timed one at a time, find them ready.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Iterable
from typing import cast

import numba

from truestep.reference_impl import compiled
from truestep.reference_impl.model import ParticleModel

DERIVATIVE = None
"""The "method" of a pair whose compiled derivative (:func:`compiled.derivative_for`, what
Drake's integrators call) is wanted rather than a loop."""


def loops_needed(pairs: Iterable[tuple[ParticleModel | None, str | type | None]]) -> list[tuple]:
    """One (model, method) of ``pairs`` for each loop they need that this process has not
    prepared, in order of first need (pairs the compiled path cannot run are left out); a
    pair whose method is :data:`DERIVATIVE` needs the model's compiled derivative."""
    needed: list[tuple]
    seen, needed = set(compiled._PREPARED), []
    for model, method in pairs:
        if method is DERIVATIVE:
            if compiled.derivative_reason(model) is not None:
                continue
            if (key := compiled.derivative_key(cast(ParticleModel, model))) not in seen:  # None has a reason
                seen.add(key)
                needed.append((model, method))
            continue
        if compiled.compiled_reason(model, method) is not None:
            continue
        scene = compiled.pack(cast(ParticleModel, model))  # None has a reason
        kind = compiled.method_kind(method)
        layout = compiled.layout_for(kind, scene)
        key = compiled.composition(compiled.loop_kind(kind, layout, scene)[1], layout, scene)
        if key not in seen:
            seen.add(key)
            needed.append((model, method))
    return needed


def _prepare_each(
    pairs: list[tuple], progress: Callable[[str], None] | None, parent: int | None = None, who: str = ""
) -> None:
    """Prepare each (model, method) of ``pairs``; the lines of a slow one (``progress``,
    standard error by default) carry how many of ``pairs`` are done and, from the pace so
    far, the seconds left: ``[3/12, ~40 s left] compiling ...``, after ``who`` does them
    (``worker 2 of 2: ``, where several processes share the work). In a forked helper,
    ``parent`` is the pid that started it: the helper is killed when that process ends
    (killed, interrupted), mid-compile too, instead of compiling on for nobody (a cache
    file cut short is compiled again by the next run: :mod:`truestep.reference_impl.cache_guard`)."""
    if parent is not None:
        from truestep.runtime.oscalls import helper_of

        helper_of(parent)
    say = progress or _stderr
    began = time.perf_counter()
    for i, (model, method) in enumerate(pairs):
        if parent is not None and os.getppid() != parent:
            os._exit(1)
        counted = _counted(say, i, len(pairs), began, who)
        if method is DERIVATIVE:
            compiled.derivative_for(model, progress=counted)
        else:
            compiled.prepared(model, method, progress=counted)


def _counted(
    say: Callable[[str], None], done: int, total: int, began: float, who: str = ""
) -> Callable[[str], None]:
    """``say`` with ``[who done + 1/total, ~ETA]`` before each line (``done`` finished so far)."""

    def counted(line: str) -> None:
        spent = time.perf_counter() - began
        eta = f", ~{spent / done * (total - done):.0f} s left" if done else ""
        say(f"[{who}{done + 1}/{total}{eta}] {line}")

    return counted


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def compile_all(
    models: Iterable[ParticleModel] = (),
    methods: Iterable[str] | None = None,
    *,
    pairs: Iterable[tuple] = (),
    workers: int = 1,
    share: tuple[int, int] = (0, 1),
    progress: Callable[[str], None] | None = None,
) -> None:
    """Compile (or load from numba's cache) the loops that ``methods`` (default: every
    fixed-step method, and the compiled derivative, :data:`DERIVATIVE`) need on
    ``models``, and those of ``pairs`` (model, method), so that forked runs find them
    ready.

    ``workers`` > 1 compiles them in that many processes at once (this one and forked
    ones, each a share of the loops, into numba's cache), then loads the others' from the
    cache: compiling is seconds a loop and uses one core. ``share`` (index, count) takes
    only every count-th loop from the index-th (for processes that share the work among
    themselves, such as a test session's workers)."""
    from truestep.reference_impl.solvers import METHODS

    names = list(methods) if methods is not None else [*METHODS, DERIVATIVE]
    wanted = [(model, method) for model in models for method in names] + list(pairs)
    needed = loops_needed(wanted)[share[0] :: share[1]]
    workers = max(1, min(workers, len(needed)))
    if workers > 1 and not numba.config.DISABLE_JIT:  # type: ignore[attr-defined]  # set at import
        context = multiprocessing.get_context("fork")
        children = [
            context.Process(
                target=_prepare_each,
                args=(needed[k::workers], None, os.getpid(), f"worker {k + 1} of {workers}: "),
                daemon=True,
            )
            for k in range(1, workers)
        ]
        for child in children:
            child.start()
        _prepare_each(needed[0::workers], progress, None, f"worker 1 of {workers}: ")
        for child in children:
            child.join()
    _prepare_each(needed, progress)
