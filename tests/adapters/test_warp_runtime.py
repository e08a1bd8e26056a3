"""Warp's engines compile their kernels beside the reference on a first run
(:meth:`truestep.adapters.warp_runtime.WarpAdapter.prepare_all`): in a process of their
own, started only where Warp's kernel cache holds none of the engine's kernels, and
awaited before any run."""

from __future__ import annotations

import pytest

from truestep.adapters import get_adapter
from truestep.adapters import warp_runtime as wr

pytest.importorskip("newton")


def test_a_cache_without_the_engine_s_modules_is_cold(tmp_path, monkeypatch):
    wr.start()  # as cold_cache does first: a started Warp has set its cache folder
    monkeypatch.setattr(wr.wp.config, "kernel_cache_dir", str(tmp_path))
    assert wr.cold_cache("newton")
    (tmp_path / "wp_mujoco_warp._src.smooth_9c01802").mkdir()
    assert wr.cold_cache("newton") and not wr.cold_cache("mujoco_warp")
    (tmp_path / "wp_newton._src.solvers.solver_1a2b3c4").mkdir()
    assert not wr.cold_cache("newton")
    monkeypatch.setattr(wr.wp.config, "kernel_cache_dir", str(tmp_path / "gone"))
    assert wr.cold_cache("newton")


def test_a_warm_cache_starts_no_process(case_named, monkeypatch):
    monkeypatch.setattr(wr, "cold_cache", lambda package: False)
    adapter = get_adapter("newton")
    adapter.prepare_all([(case_named("spring-chain"), "semi-implicit")])
    assert "newton" not in wr._WARMING


def test_a_cold_cache_compiles_apart_and_the_run_waits_for_it(case_named, monkeypatch, capfd):
    """The background process builds the scenes (here from the warm cache: quick), says
    so one line a scene, and ends; ``prepared()`` (what the run awaits) and the first
    ``prepare`` wait for it."""
    monkeypatch.setattr(wr, "cold_cache", lambda package: True)
    monkeypatch.setattr(wr, "_GPU_WANTED", [])  # a process that made no GPU adapter
    monkeypatch.setattr(wr, "_PREPARED", set())  # nothing built here yet
    adapter = get_adapter("newton")
    pairs = [(case_named("spring-chain"), "semi-implicit"), (case_named("spring-chain"), "xpbd")]
    adapter.prepare_all(pairs)
    proc = wr._WARMING["newton"]
    adapter.prepare_all(pairs)  # one at a time per engine
    assert wr._WARMING["newton"] is proc
    adapter.prepared()
    assert "newton" not in wr._WARMING and proc.exitcode == 0
    said = [line for line in capfd.readouterr().err.splitlines() if "kernels" in line]
    assert said[-1].startswith("[newton kernels] 2 scene(s) built, their kernels compiled, in ")
    assert all(" / " in line for line in said[:-1])  # a scene that took SAID_S or more, here from the cache


def test_a_background_compile_past_its_limit_is_stopped(monkeypatch):
    import multiprocessing
    import time

    proc = multiprocessing.get_context("fork").Process(target=time.sleep, args=(60,), daemon=True)
    proc.start()
    monkeypatch.setitem(wr._WARMING, "slow-engine", proc)
    began = time.monotonic()
    wr.settle("slow-engine", limit_s=0.2)
    assert not proc.is_alive() and time.monotonic() - began < 10


def _probe(code: str) -> str:
    """``code`` run by a fresh interpreter (Warp not started there); its standard output."""
    import subprocess
    import sys
    import textwrap

    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout.strip()


STARTED = "from warp._src import context; print(context.runtime is not None)"
"""Whether Warp's runtime is started in this process (Warp's own module state)."""


def test_a_gpu_adapter_leaves_warp_unstarted_before_the_fork_and_the_cpu_path_still_prepares():
    """A process that made an adapter for a GPU device builds no scene before its runs are
    forked, not even a CPU engine's (a started Warp would have looked for CUDA there: the
    runs on the GPU would inherit a CUDA they cannot use); without one, a CPU engine's
    scene is built before the fork, as it was (the runs find its kernels loaded).
    Importing the Warp engines, as every run's parent does, starts no runtime either:
    each probe says so first."""
    prepare_both = """
        from truestep.adapters.mujoco_warp_adapter import MujocoWarpAdapter
        from truestep.adapters.newton_adapter import NewtonAdapter
        from truestep.adapters import warp_runtime as wr
        from truestep.cases.loader import CASE_DIR, load_case
        {started}
        case = load_case(CASE_DIR / "spring-chain.toml")
        {make}
        for adapter in adapters:
            adapter.prepare(case, adapter.methods[0])
            adapter.prepare_all([(case, adapter.methods[0])])
        wr.settle_all()
        print(wr.wants_gpu())
        {started}
    """
    both = "adapters = [NewtonAdapter(device='cuda:0'), MujocoWarpAdapter()]"
    gpu = _probe(prepare_both.format(make=both, started=STARTED))
    assert gpu.splitlines() == ["False", "True", "False"]
    cpu = _probe(prepare_both.format(make="adapters = [MujocoWarpAdapter()]", started=STARTED))
    assert cpu.splitlines() == ["False", "False", "True"]
