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


def test_a_cold_cache_compiles_apart_and_the_run_waits_for_it(case_named, monkeypatch):
    """The background process builds the scenes (here from the warm cache: quick) and
    ends; ``prepared()`` (what the run awaits) and the first ``prepare`` wait for it."""
    monkeypatch.setattr(wr, "cold_cache", lambda package: True)
    adapter = get_adapter("newton")
    pairs = [(case_named("spring-chain"), "semi-implicit"), (case_named("spring-chain"), "xpbd")]
    adapter.prepare_all(pairs)
    proc = wr._WARMING["newton"]
    adapter.prepare_all(pairs)  # one at a time per engine
    assert wr._WARMING["newton"] is proc
    adapter.prepared()
    assert "newton" not in wr._WARMING and proc.exitcode == 0


def test_a_background_compile_past_its_limit_is_stopped(monkeypatch):
    import multiprocessing
    import time

    proc = multiprocessing.get_context("fork").Process(target=time.sleep, args=(60,), daemon=True)
    proc.start()
    monkeypatch.setitem(wr._WARMING, "slow-engine", proc)
    began = time.monotonic()
    wr.settle("slow-engine", limit_s=0.2)
    assert not proc.is_alive() and time.monotonic() - began < 10
