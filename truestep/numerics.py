"""One answer on every machine: the floating-point environment every run shares.

The same revision and package versions give bit-identical non-timing numbers only if
every library computes the same operations in the same order. Three things in a plain
numpy/scipy process depend on the machine instead:

1. **Threads.** OpenBLAS splits a product or a factorisation across as many threads as
   the machine has cores, and the partial sums then add up in another order (scipy's
   Radau on spring-chain: error 1.973156e-10 with two BLAS threads, 1.973537e-10 with
   one). Every process of a run computes on one thread: the environment variables below
   for processes started later, and :func:`pin_threads` (threadpoolctl) for libraries
   already loaded. One thread is also what makes the engines' timings comparable.
2. **OpenBLAS's kernels.** OpenBLAS picks kernels by the CPU it finds (Haswell, SkylakeX,
   Zen ...), and their dot products accumulate in different lane counts. On x86-64 with
   AVX2 and FMA truestep asks for the Haswell kernels (``OPENBLAS_CORETYPE``), which every
   such CPU runs.
3. **numpy's SIMD dispatch.** numpy computes ``exp``, ``log``, ``power``, ``sinh`` ... with
   AVX-512 code (``X86_V4``, ``AVX512_ICL``, ``AVX512_SPR``) where the CPU has it, and that
   code rounds differently from the AVX2 path. truestep switches the dispatch above
   ``X86_V3`` off (``NPY_DISABLE_CPU_FEATURES``), so a machine with AVX-512 computes what
   one without does.

numba code is compiled for the host CPU, but without ``fastmath`` LLVM neither fuses
multiply-adds nor reorders reductions, so its results do not depend on the vector width.

The ``truestep`` command sets the variables (where the user has not set them) before it
loads numpy (:func:`set_environment`, :mod:`truestep.command`). Importing :mod:`truestep`
changes nothing in a process (nor does its pytest plugin): a library user's run
(``truestep.run``, ``run_matrix``) holds every loaded BLAS and OpenMP runtime to one thread
and sets the variables for the processes it starts only while it runs (:func:`own_run`),
and computes with numpy's dispatch as the process found it unless the user called
:func:`set_environment` before importing numpy. :func:`fingerprint` records what actually
took effect, so a run whose environment differs says so (``run.json``, the report's footer,
``truestep gate --baseline``). ``TRUESTEP_NUMERICS=native`` leaves the machine's own
choices in place.

This module imports nothing heavy at import time.
"""

from __future__ import annotations

import contextlib
import os
import platform
import sys
from collections.abc import Iterator
from importlib import metadata
from typing import Any

THREAD_VARIABLES = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "BLIS_NUM_THREADS",
)
"""Thread counts of the BLAS and OpenMP runtimes a process may load: all set to 1."""
OPENBLAS_CORE = "Haswell"
"""The OpenBLAS kernels asked for on x86-64 CPUs with AVX2 and FMA."""
NUMPY_DISPATCH_OFF = (
    "X86_V4",
    "AVX512_ICL",
    "AVX512_SPR",
    "AVX512_SKX",
    "AVX512_CLX",
    "AVX512_CNL",
    "AVX512F",
    "AVX512CD",
)
"""numpy dispatch targets above ``X86_V3`` (the names of numpy 2.x and of 1.x): switched
off. numpy ignores names it does not know and targets the CPU does not have."""
PACKAGES = (
    "truestep",
    "numpy",
    "scipy",
    "numba",
    "llvmlite",
    "pandas",
    "pymunk",
    "pybullet",
    "mujoco",
    "drake",
    "mujoco-warp",
    "newton",
    "warp-lang",
    "distributed",
)
"""Packages whose versions a run records: a run is reproducible bit for bit with the same
revision and these versions (but those of :data:`SCHEDULING_ONLY`)."""
SCHEDULING_ONLY = frozenset({"distributed"})
"""Recorded packages that only move work between processes and machines: a run on a Dask
cluster gives a local run's tables, cell for cell (``tests/execution/test_cluster.py``),
so their versions do not decide whether two runs can be compared bit for bit
(:func:`differences`). A fresh install takes the newest ``distributed``: counting it made
CI's ``--identical`` quick gate fall back to tolerances when Dask released."""
OPT_OUT = "TRUESTEP_NUMERICS"
"""``TRUESTEP_NUMERICS=native``: leave threads, kernels and dispatch as the machine has them."""


WARP_GENERIC_CPU = ""
"""Warp's CPU compiler flags: a generic x86-64 (or aarch64) target, not Warp's default
``-march=native``, so that its kernels round alike on every machine of one architecture
(no FMA contraction or wider vectors chosen by the host)."""


def configure_warp(wp: Any) -> None:
    """Set Warp (the module ``wp``, imported by the caller) as truestep computes with it:
    warning log level; no backward (adjoint) kernels, since truestep never differentiates
    a run (a module that sets its own option keeps it; the forward kernels are the same
    code, and their results the same bits: the quick baseline's ``--identical`` gate
    covers Newton's and MuJoCo Warp's rows; it roughly halves Newton's first compile on the
    CPU, 37 s to 21 s for its three solvers); and CPU kernels compiled for
    :data:`WARP_GENERIC_CPU` unless ``TRUESTEP_NUMERICS=native``. Starts nothing (Warp's
    runtime looks for CUDA)."""
    wp.config.log_level = wp.LOG_WARNING
    wp.config.enable_backward = False
    if os.environ.get(OPT_OUT, "").lower() != "native":
        wp.config.cpu_compiler_flags = WARP_GENERIC_CPU


def _cpu_flags() -> set[str]:
    """The CPU's feature flags (Linux ``/proc/cpuinfo``; empty elsewhere)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def environment() -> dict[str, str]:
    """The variables :func:`set_environment` sets where they are unset."""
    env = dict.fromkeys(THREAD_VARIABLES, "1")
    if platform.machine().lower() in ("x86_64", "amd64"):
        flags = _cpu_flags()
        if {"avx2", "fma"} <= flags:
            env["OPENBLAS_CORETYPE"] = OPENBLAS_CORE
        env["NPY_DISABLE_CPU_FEATURES"] = " ".join(NUMPY_DISPATCH_OFF)
    return env


def set_environment() -> list[str]:
    """Set the variables of :func:`environment` that are unset, and say which could not
    take effect any more because numpy or scipy is already loaded (the threads are still
    pinned later, by :func:`pin_threads`). Does nothing with ``TRUESTEP_NUMERICS=native``."""
    if os.environ.get(OPT_OUT, "").lower() == "native":
        return []
    late = []
    for key, value in environment().items():
        if key in os.environ:
            continue
        os.environ[key] = value
        if key in ("NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE") and "numpy" in sys.modules:
            late.append(key)
    return late


@contextlib.contextmanager
def own_run() -> Iterator[None]:
    """truestep's own run in a process that is not truestep's (a library user's, a pytest
    session's): while it lasts, the variables of :func:`environment` are set where unset
    (for the processes the run starts) and every BLAS and OpenMP runtime loaded is held to
    one thread (the run's forked children inherit it); both are put back as they were when
    it ends. Nothing with ``TRUESTEP_NUMERICS=native``."""
    if os.environ.get(OPT_OUT, "").lower() == "native":
        yield
        return
    from threadpoolctl import threadpool_limits

    unset = [key for key in environment() if key not in os.environ]
    set_environment()
    try:
        with threadpool_limits(limits=1):
            yield
    finally:
        for key in unset:
            os.environ.pop(key, None)


_PINNED: list[object] = []


def pin_threads() -> None:
    """Limit every BLAS and OpenMP runtime loaded in this process to one thread (and keep
    the limit for the process's life, and its forked children's): for truestep's own
    processes only (its command, its cluster workers; a library user's run uses
    :func:`own_run`). Safe to call again."""
    if os.environ.get(OPT_OUT, "").lower() == "native":
        return
    from threadpoolctl import threadpool_limits

    _PINNED[:] = [threadpool_limits(limits=1)]


def _versions() -> dict[str, str]:
    out = {}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return out


def fingerprint() -> dict[str, Any]:
    """What decides the numbers besides the code: the packages' versions, the machine's
    architecture, the BLAS libraries loaded (their kernels and threads), numpy's SIMD
    dispatch. OpenMP runtimes are not listed: an engine loads one when it is imported
    (Drake does), so a process that has not imported it yet would differ, and every
    runtime is pinned to one thread (:func:`pin_threads`) wherever it is loaded. Two runs
    whose fingerprints are equal give the same non-timing numbers.

    Loads numpy and scipy's linear algebra (so that both BLAS libraries are seen)."""
    import numpy as np
    import scipy.linalg  # noqa: F401 (loads scipy's own OpenBLAS, so it is listed)
    from threadpoolctl import threadpool_info

    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__  # type: ignore[import-not-found]  # private, no stubs

        simd = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
    except ImportError:  # numpy 1.x spells the module without the underscore
        from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__  # type: ignore[no-redef]  # numpy 1.x

        simd = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
    blas = sorted(
        {
            f"{p.get('internal_api')} {p.get('version')} {p.get('architecture', '')} "
            f"threads={p.get('num_threads')}".strip()
            for p in threadpool_info()
            if p.get("user_api") == "blas"
        }
    )
    return {
        "machine": platform.machine(),
        "python": platform.python_version(),
        "packages": _versions(),
        "blas": blas,
        "numpy_simd": simd,
        "numpy_baseline": list(getattr(np, "__cpu_baseline__", [])) or _baseline(),
        "native": os.environ.get(OPT_OUT, "").lower() == "native",
    }


def _baseline() -> list[str]:
    try:
        from numpy._core._multiarray_umath import __cpu_baseline__
    except ImportError:
        from numpy.core._multiarray_umath import __cpu_baseline__  # type: ignore[no-redef]  # numpy 1.x
    return list(__cpu_baseline__)


def differences(a: dict, b: dict) -> list[str]:
    """What differs between two :func:`fingerprint` records, one short line each (the
    truestep version aside: a new version may change numbers on purpose; and the packages
    of :data:`SCHEDULING_ONLY`, which change none)."""
    out = []
    for key in sorted(set(a) | set(b)):
        if key == "packages":
            pa, pb = a.get(key, {}), b.get(key, {})
            out += [
                f"{name} {pa.get(name, '-')} -> {pb.get(name, '-')}"
                for name in sorted(set(pa) | set(pb))
                if name != "truestep" and name not in SCHEDULING_ONLY and pa.get(name) != pb.get(name)
            ]
        elif a.get(key) != b.get(key):
            out.append(f"{key}: {a.get(key)} -> {b.get(key)}")
    return out
