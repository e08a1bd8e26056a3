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
from collections.abc import Callable, Iterable, Iterator
from typing import Any, cast

import numba

from truestep.reference_impl import compiled, tiles
from truestep.reference_impl.model import ParticleModel

DERIVATIVE = None
"""The "method" of a pair whose compiled derivative (:func:`compiled.derivative_for`, what
Drake's integrators call) is wanted rather than a loop."""


def loops_needed(pairs: Iterable[tuple[ParticleModel | None, str | type | None]]) -> list[tuple]:
    """One (model, method) of ``pairs`` for each loop they need that this process has not
    prepared, in order of first need (pairs the compiled path cannot run are left out); a
    pair whose method is :data:`DERIVATIVE` needs the model's compiled derivative."""
    return [pair for pair, _ in _needed_with_weights(pairs)]


def _needed_with_weights(pairs: Iterable[tuple]) -> list[tuple[tuple, float]]:
    """:func:`loops_needed`, each with its :data:`WEIGHTS` (how long it takes to compile,
    in units of a loop in passes)."""
    needed: list[tuple[tuple, float]]
    seen, needed = set(compiled._PREPARED), []
    for model, method in pairs:
        if method is DERIVATIVE:
            if compiled.derivative_reason(model) is not None:
                continue
            if (key := compiled.derivative_key(cast(ParticleModel, model))) not in seen:  # None has a reason
                seen.add(key)
                needed.append(((model, method), WEIGHTS["derivative"]))
            continue
        if compiled.compiled_reason(model, method) is not None:
            continue
        scene = compiled.pack(cast(ParticleModel, model))  # None has a reason
        kind = compiled.method_kind(method)
        layout = compiled.layout_for(kind, scene)
        key = compiled.composition(compiled.loop_kind(kind, layout, scene)[1], layout, scene)
        if key not in seen:
            seen.add(key)
            fused = isinstance(layout, tiles.Fused)
            needed.append(((model, method), WEIGHTS["fused" if fused else "passes"]))
    return needed


WEIGHTS = {"fused": 2.0, "passes": 1.0, "derivative": 0.1}
"""How long a loop of each kind takes to compile, relative to a loop in passes: a fused
loop holds a step of one particle for every built-in method (and its special particles'),
so it takes about twice as long, and a derivative a small part of a loop in passes (the
logs of a cold ``truestep compile`` on this repository's cases). Used only to order the
work among processes (longest first); nothing computed depends on it."""


def longest_first(weighted: list[tuple[tuple, float]]) -> list[tuple]:
    """The pairs of ``weighted`` (pair, weight), heaviest first, ties in their order."""
    order = sorted(range(len(weighted)), key=lambda i: (-weighted[i][1], i))
    return [weighted[i][0] for i in order]


def shares(weighted: list[tuple[tuple, float]], count: int) -> list[list[tuple]]:
    """``weighted`` (pair, weight) split into ``count`` shares of about equal weight, the
    same in every process (heaviest first, each to the lightest share so far, the lower
    index on a tie): the work of processes that cannot hand it out as they go."""
    loads = [0.0] * count
    parts: list[list[tuple]] = [[] for _ in range(count)]
    for i in sorted(range(len(weighted)), key=lambda i: (-weighted[i][1], i)):
        k = min(range(count), key=lambda k: (loads[k], k))
        parts[k].append(weighted[i][0])
        loads[k] += weighted[i][1]
    return parts


def _prepare_each(
    pairs: list[tuple],
    progress: Callable[[str], None] | None,
    parent: int | None = None,
    who: str = "",
    queue: Any = None,
    sharing: int = 1,
) -> None:
    """Prepare each (model, method) of ``pairs``; the lines of a slow one (``progress``,
    standard error by default) carry how many of ``pairs`` are started and, from the pace
    so far, the seconds left: ``[3/12, ~40 s left] compiling ...``, after ``who`` does them
    (``worker 2 of 2: ``, where several processes share the work). With ``queue`` (a
    shared counter: :func:`compile_all`), the processes that share it take the next pair
    of ``pairs`` each time one is free, so none waits while another has a long list
    (``sharing``: how many processes share it, for the lines' ETA); else every pair is
    this process's. In a forked helper, ``parent`` is the pid that started
    it: the helper is killed when that process ends (killed, interrupted), mid-compile
    too, instead of compiling on for nobody (a cache file cut short is compiled again by
    the next run: :mod:`truestep.reference_impl.cache_guard`)."""
    if parent is not None:
        from truestep.runtime.oscalls import helper_of

        helper_of(parent)
    say = progress or _stderr
    began = time.perf_counter()
    for mine, i in enumerate(_taken(len(pairs), queue)):
        if parent is not None and os.getppid() != parent:
            os._exit(1)
        model, method = pairs[i]
        counted = _counted(say, i, len(pairs), began, who, (mine, sharing) if queue is not None else (-1, 1))
        if method is DERIVATIVE:
            compiled.derivative_for(model, progress=counted)
        else:
            compiled.prepared(model, method, progress=counted)


def _taken(count: int, queue: Any) -> Iterator[int]:
    """The indices 0 .. ``count`` - 1 this process is to do: all of them in order, or, from
    a shared counter ``queue``, each next one no process has taken yet."""
    if queue is None:
        yield from range(count)
        return
    while True:
        with queue.get_lock():
            i = queue.value
            queue.value = i + 1
        if i >= count:
            return
        yield i


def _counted(
    say: Callable[[str], None],
    started: int,
    total: int,
    began: float,
    who: str = "",
    pace: tuple[int, int] = (-1, 1),
) -> Callable[[str], None]:
    """``say`` with ``[who started + 1/total, ~ETA]`` before each line (``started`` of
    ``total`` begun before this one). The ETA is this process's pace so far (s per loop it
    finished) over the loops left: where it does them all (``pace[0]`` < 0), this one and
    those after it; where ``pace[1]`` processes share them (``pace[0]`` finished by this
    one), those no process has begun, shared among them."""
    done, sharing = (started, 1) if pace[0] < 0 else pace
    left = total - started if pace[0] < 0 else max(total - started - 1, 0)

    def counted(line: str) -> None:
        spent = time.perf_counter() - began
        eta = f", ~{spent / done * left / sharing:.0f} s left" if done else ""
        say(f"[{who}{started + 1}/{total}{eta}] {line}")

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
    ones, into numba's cache), the longest first (:data:`WEIGHTS`), each process taking
    the next loop when it is free; then this process loads the others' from the cache:
    compiling is seconds a loop and uses one core. ``share`` (index, count) takes only
    the index-th of count shares of about equal weight (:func:`shares`), for processes
    that share the work among themselves without a common parent (a test session's
    workers)."""
    from truestep.reference_impl.solvers import METHODS

    names = list(methods) if methods is not None else [*METHODS, DERIVATIVE]
    wanted = [(model, method) for model in models for method in names] + list(pairs)
    weighted = _needed_with_weights(wanted)
    needed = longest_first(weighted) if share[1] == 1 else shares(weighted, share[1])[share[0]]
    workers = max(1, min(workers, len(needed)))
    if workers > 1 and not numba.config.DISABLE_JIT:  # type: ignore[attr-defined]  # set at import
        context = multiprocessing.get_context("fork")
        queue = context.Value("i", 0)
        children = [
            context.Process(
                target=_prepare_each,
                args=(needed, None, os.getpid(), f"worker {k + 1} of {workers}: ", queue, workers),
                daemon=True,
            )
            for k in range(1, workers)
        ]
        for child in children:
            child.start()
        _prepare_each(needed, progress, None, f"worker 1 of {workers}: ", queue, workers)
        for child in children:
            child.join()
    _prepare_each(needed, progress)
