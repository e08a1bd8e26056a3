"""Warp, started once for every engine built on it (MuJoCo Warp, Newton).

Importing this module imports and configures Warp the way truestep runs it: at warning
log level, with its CPU kernels compiled for a generic target (:data:`GENERIC_CPU`) unless
``TRUESTEP_NUMERICS=native``. It does not start Warp's runtime: :func:`start` does, without
its CUDA greeting on a machine with no GPU, in the process that first needs it. Starting it
looks for CUDA devices, and CUDA does not survive a fork, so a process that has made an
adapter for a GPU device (:func:`wants_gpu`) leaves it to the forked runs: a GPU run's
process starts CUDA itself, and no scene is built before the fork (:func:`prepare`).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import sys
import time
from collections.abc import Iterable
from typing import Any, ClassVar

from truestep.adapters.base import FixedStepAdapter
from truestep.adapters.devices import chosen
from truestep.adapters.quiet import without_banner
from truestep.numerics import WARP_GENERIC_CPU, configure_warp

BANNER = r"^Warp CUDA warning: Could not find or load the NVIDIA CUDA driver"
"""Warp's greeting on a machine without a GPU (its version banner is off by log level)."""

GENERIC_CPU = WARP_GENERIC_CPU
"""Warp's CPU compiler flags (:data:`truestep.numerics.WARP_GENERIC_CPU`);
``TRUESTEP_NUMERICS=native`` keeps Warp's default."""

DEVICE = "cpu"
"""Warp's device unless one is asked: the CPU, so that every machine computes the same
numbers (a GPU's float32 kernels need not round as the CPU's do)."""

PRECISION = "float32"
"""The floating-point type of the state of Warp's physics engines."""

with without_banner(BANNER):
    import warp as wp

configure_warp(wp)

_STARTED: list[bool] = []
"""Whether :func:`start` has started Warp in this process."""
_GPU_WANTED: list[str] = []
"""The devices other than the CPU that adapters made in this process asked for."""


def start() -> None:
    """Start Warp's runtime in this process, once (without its CUDA greeting where there is
    no GPU): the first scene a process builds calls it, and so does a look at its kernel cache."""
    if not _STARTED:
        with without_banner(BANNER):
            wp.init()
        _STARTED.append(True)


def want_gpu(device: str) -> None:
    """Say that an adapter made in this process computes on ``device`` (not the CPU): from
    then on nothing here starts Warp before the runs are forked (:func:`wants_gpu`)."""
    _GPU_WANTED.append(device)


def wants_gpu() -> bool:
    """Whether an adapter made in this process runs on a device other than the CPU: then
    nothing here starts Warp before the runs are forked (CUDA started in a parent is
    unusable in its forked children)."""
    return bool(_GPU_WANTED)


def host_view(array: Any) -> Any:
    """A numpy array over a Warp array's own memory when it lives on the CPU device (what
    the graph's launches write is there at once), else ``None``. Reading the state at
    every step through it costs a copy; ``array.numpy()`` costs more on top at every call
    (Warp's device lookup and a new numpy wrapper), a large part of a small scene's step."""
    return array.numpy() if array.device.is_cpu else None


def host_copy(array: Any, view: Any, n: int | None = None) -> Any:
    """The first ``n`` rows (all when ``None``) of a Warp array as a host numpy copy: from
    its :func:`host_view` ``view`` where it has one, else through ``array.numpy()``."""
    host = view if view is not None else array.numpy()
    return (host if n is None else host[:n]).copy()


_PREPARED: set[tuple] = set()
"""The kinds of scene :func:`prepare` has built in this process: (engine, method, the
case's features)."""


def prepare(adapter: Any, case: Any, method: str) -> bool:
    """Build ``case``'s scene for ``method`` in this process (on the CPU device only),
    before truestep forks the processes that run it: they find the solver's module
    imported and every Warp kernel module the scene needs loaded, where each would
    otherwise import and hash them afresh, in every process. Nothing is measured from
    this build; a scene the adapter cannot or will not run is not built. On a GPU nothing
    is done: CUDA is not started in a process that forks.

    Once a process for each engine, method and set of scene features (springs, planes,
    friction ...): the kernels a scene loads follow from its method and what it holds, and
    a build for every sweep held up the parent that starts the next one. A kernel module
    that a later scene needs and this build did not load is loaded by the run's own
    process, the same kernels. Returns whether a scene was built."""
    key = (adapter.name, method, frozenset(case.features))
    if (
        adapter.device != "cpu"
        or wants_gpu()
        or case.model is None
        or key in _PREPARED
        or adapter.missing(case, method)
    ):
        return False
    _PREPARED.add(key)
    skip = getattr(adapter, "skip", None)
    if skip is not None and skip(case, method):
        return False
    adapter.build(case, method, case.sweep(adaptive=False, quick=True)[0])
    return True


WARMING_S = 900.0
"""Seconds :func:`settle` waits for an engine's kernels to compile in the background before
it stops that process (the runs then compile what they need themselves)."""

_WARMING: dict[str, Any] = {}
"""The process compiling each engine's kernels in the background (:meth:`WarpAdapter.prepare_all`)."""


def cold_cache(package: str) -> bool:
    """Whether Warp's kernel cache holds no module of ``package`` (its directory's entries
    are named ``wp_<module>_<hash>``): the engine's kernels were never compiled here."""
    start()
    folder = wp.config.kernel_cache_dir
    if not folder or not os.path.isdir(folder):
        return True
    prefix = f"wp_{package}."
    with os.scandir(folder) as entries:
        return not any(entry.name.startswith(prefix) for entry in entries)


def _build_each(adapter: Any, pairs: list[tuple[Any, str]], parent: int) -> None:
    """In a forked process: :func:`prepare` each (case, method), so that Warp compiles
    their kernels into its on-disk cache, each scene built one line on standard error
    (``[newton kernels 2/9] compiled for spring-chain / xpbd in 4.1 s``, where it takes
    :data:`SAID_S` or more, beside the reference's compile lines), and one line at the
    end; dies with ``parent``. A scene that fails to build is left
    for the run that needs it to report."""
    from truestep.runtime.oscalls import helper_of

    helper_of(parent)
    start, built = time.perf_counter(), 0
    for k, (case, method) in enumerate(pairs, start=1):
        began = time.perf_counter()
        with contextlib.suppress(Exception):  # the run that needs the scene builds it and says why
            if prepare(adapter, case, method):
                built += 1
                took = time.perf_counter() - began
                if took >= SAID_S:
                    where = f"{case.name} / {method}"
                    _say(f"[{adapter.name} kernels {k}/{len(pairs)}] compiled for {where} in {took:.1f} s")
    took = time.perf_counter() - start
    _say(f"[{adapter.name} kernels] {built} scene(s) built, their kernels compiled, in {took:.1f} s")


SAID_S = 0.5
"""Seconds a scene's build in the background compile takes before it is a line of its own
(one that loads what an earlier build compiled takes less)."""


def _say(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def settle(engine: str, limit_s: float = WARMING_S) -> None:
    """Wait for the background compile of ``engine``'s kernels, if one runs (at most
    ``limit_s`` seconds, then it is stopped)."""
    proc = _WARMING.pop(engine, None)
    if proc is None:
        return
    proc.join(limit_s)
    if proc.is_alive():
        proc.kill()
        proc.join()


def settle_all() -> None:
    """Wait for every background compile of Warp kernels (:func:`settle`)."""
    for engine in list(_WARMING):
        settle(engine)


class WarpAdapter(FixedStepAdapter):
    """What the adapters of Warp's engines share: the device (the CPU unless one is
    asked), float32 state, the scene built before the sweep's processes are forked
    (:func:`prepare`), one launch of the scene's captured step graph per step, and the
    device's note on every row. A subclass builds a scene with ``graph`` (a captured
    Warp graph of one step) and ``device``, and says what its rows note on the CPU
    (:attr:`cpu_note`)."""

    precision: ClassVar[str] = PRECISION
    """The state's floating-point type: order fits and baselines use its round-off floor."""
    cpu_note: ClassVar[str] = "Warp CPU device, float32"
    """The note of every row on the CPU device."""

    kernel_package: ClassVar[str] = ""
    """The Python package whose Warp kernels the engine compiles (:func:`cold_cache`)."""
    prepares_apart: ClassVar[bool] = True
    """:meth:`prepare_all` compiles in a process of its own and returns at once: the run
    starts it before the other engines' (:func:`truestep.execution.runner.compile_ahead`)
    and waits for it after them."""

    def __init__(self, *, device: str | None = None) -> None:
        self.device = device or chosen(self.name) or DEVICE
        if self.device != "cpu":
            want_gpu(self.device)

    def prepare_all(self, pairs: Iterable[tuple[Any, str]], *, workers: int = 1) -> None:
        """Where Warp's kernel cache holds none of this engine's kernels (a first run on
        the machine, on the CPU device), start compiling them for ``pairs`` (case, method)
        in a forked process: one scene built for each kind (:func:`prepare`), beside the
        reference's compile on the other cores, instead of one at a time in truestep's
        process while the runs wait. Returns at once; :func:`settle` waits for it. Nothing
        a run measures depends on it: a run finds the kernels in the cache, or compiles
        them."""
        if (
            self.device != "cpu"
            or wants_gpu()
            or not self.kernel_package
            or self.name in _WARMING
            or not cold_cache(self.kernel_package)
        ):
            return
        context = multiprocessing.get_context("fork")
        proc = context.Process(target=_build_each, args=(self, list(pairs), os.getpid()), daemon=True)
        proc.start()
        _WARMING[self.name] = proc

    def prepared(self) -> None:
        """Wait for :meth:`prepare_all`'s background compile, if one runs (:func:`settle`)."""
        settle(self.name)

    def prepare(self, case: Any, method: str) -> None:
        """Before the sweep's process is forked: the scene built once here, so that the
        process finds Warp's kernels loaded (:func:`prepare`), after the background
        compile of :meth:`prepare_all`, if one runs."""
        settle(self.name)
        prepare(self, case, method)

    def advance(self, scene: Any, k: int, steps: int, h: float) -> None:
        """Launch the scene's captured one-step graph ``steps`` times."""
        launch, graph = wp.capture_launch, scene.graph
        for _ in range(steps):
            launch(graph)

    def device_note(self, scene: Any) -> str:
        """The row's note on the device it ran on."""
        return self.cpu_note if scene.device == "cpu" else f"Warp device {scene.device}, float32"


__all__ = [
    "BANNER",
    "DEVICE",
    "GENERIC_CPU",
    "PRECISION",
    "WarpAdapter",
    "host_copy",
    "host_view",
    "prepare",
    "settle",
    "settle_all",
    "start",
    "want_gpu",
    "wants_gpu",
    "wp",
]
