"""``truestep bench``: the scaling table, its figure and its command, on tiny sizes."""

from __future__ import annotations

import itertools
import os
import time

import numpy as np
import pandas as pd
import pytest
from PIL import Image

import truestep.adapters
from truestep.adapters import get_adapter, resolve_engine
from truestep.cli import main
from truestep.execution import bench
from truestep.reporting import scaling as report_scaling

SIZES = (10, 100)
TARGET_S = 0.02
"""Tiny runs: these tests check the table's bookkeeping, not this machine's speed."""
AMPLE_S = 600.0
"""A budget no tiny table reaches however loaded the machine: a verdict here never depends
on the clock (that the budget bounds a table's wall time is timed in
``benchmarks/test_bench_budget.py``)."""


class CrashingAdapter:
    """An engine that dies, raises or hangs in every run (the warm-up included)."""

    name = "bench-crasher"
    methods = ("dies", "raises", "hangs")
    adaptive_methods = ()
    capabilities = frozenset()

    def missing(self, case, method):
        return set()

    def simulate(self, case, method, dt):
        if method == "dies":
            os._exit(3)
        if method == "hangs":
            time.sleep(60)
        raise RuntimeError("engine exploded")


def compile_reference_loops() -> None:
    """Compile the reference's loops for the rain scene (or load them from the cache) in
    this process, as ``truestep run`` does before its sweeps: these tests check the
    table's bookkeeping, not how long a cold numba cache takes."""
    reference = get_adapter("reference")
    for method in reference.methods:
        if method not in reference.adaptive_methods and method != "implicit-euler":
            reference.prepare(bench.rain_case(10), method)


@pytest.fixture(scope="module")
def table() -> pd.DataFrame:
    compile_reference_loops()
    lines: list[str] = []
    out = bench.scaling_table(
        ["reference", "pymunk"], sizes=SIZES, budget_s=AMPLE_S, target_s=TARGET_S, progress=lines.append
    )
    out.attrs["lines"] = lines
    return out


def test_the_rain_scene_at_n_is_the_case_s_own_block(case_named):
    case = case_named("particle-rain")
    same = bench.rain_case(case.model.n, case)
    assert np.array_equal(same.model.x0, case.model.x0)
    assert np.array_equal(same.model.v0, case.model.v0)
    small, large = bench.rain_case(10, case), bench.rain_case(5000, case)
    # the seeded draw fills row by row: a smaller scene is the first particles of a larger one
    assert np.array_equal(small.model.x0, case.model.x0[:10])
    assert np.array_equal(large.model.x0[:1000], case.model.x0)
    box_lo, box_hi = np.array([-5.0, 0.51, 0.0]), np.array([5.0, 2.01, 0.0])  # the case file's
    assert np.all(large.model.x0 >= box_lo) and np.all(large.model.x0 <= box_hi)
    assert large.features == case.features and repr(large.model.planes) == repr(case.model.planes)
    assert np.all(large.model.mass == case.model.mass[0])


@pytest.mark.engine
def test_every_engine_method_and_size_is_a_row(table):
    expected = {
        (e, m, n)
        for e in ("reference", "pymunk")
        for m, n in itertools.product(get_adapter(e).methods, SIZES)
    }
    got = set(zip(table["engine"], table["method"], table["n"], strict=True))
    assert got == expected and len(table) == len(expected)
    assert list(table.columns) == bench.COLUMNS
    assert set(table["status"]) <= {"ok", "skipped", "unsupported"}
    run = table[
        ~table["status"].isin(["unsupported"])
        & ~table["note"].str.startswith(("adaptive", "the case skips it"))
    ]
    assert len(table.attrs["lines"]) == len(run)  # one progress line per row of a pair that ran
    for engine in ("reference", "pymunk"):
        assert ((table["engine"] == engine) & (table["status"] == "ok")).any()


@pytest.mark.engine
def test_rates_are_particle_steps_over_the_timed_wall(table):
    ok = table[table["status"] == "ok"]
    assert len(ok) and (ok["particle_steps_per_s"] > 0).all() and (ok["wall_s"] > 0).all()
    assert (ok["steps"] >= bench.MIN_STEPS).all() and (ok["steps"] <= 1000).all()  # the case's 1 s
    assert ((ok["repeats"] >= 1) & (ok["repeats"] <= bench.MAX_REPEATS)).all()
    recomputed = ok["n"] * ok["steps"].astype(float) / ok["wall_s"]
    np.testing.assert_allclose(ok["particle_steps_per_s"], recomputed, rtol=1e-12)
    bandwidth = table.attrs["bandwidth_bytes_per_s"]
    assert bandwidth > 1e8  # any machine that runs this moves more than 0.1 GB/s
    np.testing.assert_allclose(ok["bandwidth_fraction"], recomputed * 96 / bandwidth, rtol=1e-12)
    assert table.attrs["bytes_per_particle_step"] == 96


@pytest.mark.engine
def test_rows_not_run_say_why(table):
    idle = table[table["status"] != "ok"]
    assert (idle["note"].str.len() > 0).all()
    assert idle["wall_s"].isna().all() and idle["particle_steps_per_s"].isna().all()
    assert idle["steps"].isna().all() and idle["repeats"].isna().all()
    dopri = table[(table["engine"] == "reference") & (table["method"] == "dopri5")]
    assert (dopri["status"] == "skipped").all() and dopri["note"].str.contains("adaptive").all()
    implicit = table[table["method"] == "implicit-euler"]
    assert implicit["note"].str.startswith("the case skips it").all()  # the case file's [[run.skip]]


@pytest.mark.engine
def test_sizes_beyond_the_budget_are_skipped_with_the_numbers():
    """n = 1e9 would take hours by any extrapolation from n = 10 and 100."""
    out = bench.scaling_table(
        ["pymunk"], sizes=(10, 100, 10**9), budget_s=AMPLE_S, target_s=TARGET_S, progress=lambda line: None
    )
    assert list(out["n"]) == [10, 100, 10**9]
    assert out["status"].iloc[0] == "ok"  # the first size runs while any budget is left
    big = out.iloc[-1]
    assert big["status"] == "skipped" and big["note"].startswith("budget: the run at n=1,000,000,000")
    assert "share of the 600 s budget" in big["note"]


@pytest.mark.engine
def test_a_budget_spent_before_a_pair_skips_its_rows_saying_so():
    out = bench.scaling_table(
        ["pymunk"], sizes=(10, 100), budget_s=1e-3, target_s=TARGET_S, progress=lambda line: None
    )
    assert (out["status"] == "skipped").all()
    assert out["note"].str.startswith("budget: the 0.001 s budget ended").all()


def test_a_crash_a_raise_and_a_hang_are_rows(monkeypatch):
    monkeypatch.setattr(truestep.adapters, "_RESOLVED", dict(truestep.adapters._RESOLVED))
    monkeypatch.setattr(bench, "FIRST_TIMEOUT_S", 0.5)  # the hang is killed after 0.5 s
    name = resolve_engine("test_bench:CrashingAdapter")
    out = bench.scaling_table(
        [name], sizes=SIZES, budget_s=AMPLE_S, target_s=TARGET_S, progress=lambda line: None
    ).set_index(["method", "n"])
    assert out.loc[("dies", 10), "status"] == "crashed"
    assert "exit code 3" in out.loc[("dies", 10), "note"]
    assert out.loc[("raises", 10), "status"] == "crashed"
    assert "RuntimeError: engine exploded" in out.loc[("raises", 10), "note"]
    assert out.loc[("hangs", 10), "status"] == "timeout"
    assert out.loc[("dies", 10), "note"].startswith("in the warm-up (n=10, untimed)")
    for method in ("dies", "raises"):
        assert out.loc[(method, 100), "status"] == "skipped"
        assert out.loc[(method, 100), "note"] == "the warm-up at n=10 crashed"
    assert out.loc[("hangs", 100), "note"] == "the warm-up at n=10 timed out"


def test_the_figure_draws_what_ran_and_the_bandwidth_line(tmp_path):
    rows = [("reference", "euler", n, 4, 0.2, n * 4 / 0.2, "ok", "") for n in (100, 1000, 10000)]
    rows += [("reference", "lecture", n, 4, 0.1, n * 4 / 0.1, "ok", "") for n in (100, 1000)]
    rows += [
        ("pymunk", "default", 100, 8, 0.2, 4000.0, "ok", ""),
        ("pymunk", "default", 1000, None, None, None, "skipped", "budget: the run ..."),
        ("mujoco", "Euler", 100, None, None, None, "crashed", "engine process died"),
    ]
    table = pd.DataFrame(
        rows, columns=["engine", "method", "n", "steps", "wall_s", "particle_steps_per_s", "status", "note"]
    )
    path = bench.scaling_plot(table, 2e10, tmp_path / "figures" / "scaling.png")
    with Image.open(path) as img:
        assert img.format == "PNG" and img.width > 500


def test_extrapolation_follows_an_affine_cost_and_a_faster_one():
    affine = {n: 1e-3 + 1e-6 * n for n in (100, 1000)}
    assert bench._extrapolate(affine, 10_000) == pytest.approx(1e-3 + 1e-6 * 10_000)
    quadratic = {n: 1e-9 * n**2 for n in (100, 1000)}
    assert bench._extrapolate(quadratic, 10_000) == pytest.approx(1e-9 * 10_000**2)
    assert bench._extrapolate({100: 0.01}, 1000) == pytest.approx(0.1)  # one point: proportional


@pytest.mark.engine
def test_the_command_writes_the_table_and_the_figure(tmp_path, capsys):
    out = tmp_path / "bench"
    code = main(["bench", "--engines", "pymunk", "--sizes", "10,100", "--budget", "1", "--out", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    assert "copy bandwidth" in printed and "particle-steps/s" in printed
    csv = pd.read_csv(out / "scaling.csv")
    assert list(csv.columns) == bench.COLUMNS and list(csv["n"]) == [10, 100]
    with Image.open(out / "figures" / "scaling.png") as img:
        assert img.format == "PNG"


@pytest.mark.parametrize(
    "argv",
    [
        ["--sizes", "ten"],
        ["--sizes", "0,100"],
        ["--budget", "0"],
        # issue 37, item 11: these gave a traceback (NaN or infinity made a step count)
        ["--sizes", "nan"],
        ["--sizes", "10,inf"],
        ["--budget", "inf"],
        ["--budget", "1e308"],
        ["--budget", "nan"],
        ["--threads", "0"],
    ],
)
def test_the_command_rejects_bad_input_and_writes_nothing(tmp_path, capsys, argv):
    out = tmp_path / "bench"
    assert main(["bench", "--engines", "pymunk", "--out", str(out), *argv]) == 2
    assert "truestep: error: --" in capsys.readouterr().err
    assert not out.exists()


def _synthetic() -> pd.DataFrame:
    """Three engines; only two reach n = 1000; the numbers are chosen, not measured."""
    rows = [
        ("a", "fast", 100, 4e8),
        ("a", "slow", 100, 1e8),
        ("a", "fast", 1000, 3e8),
        ("b", "x", 100, 2e7),
        ("b", "x", 1000, 1.5e7),
        ("c", "y", 100, 1e6),
    ]
    table = pd.DataFrame(
        [
            {
                "engine": e,
                "method": m,
                "n": n,
                "particle_steps_per_s": r,
                "bandwidth_fraction": r * 96 / 1e10,
                "status": "ok",
                "note": "",
            }
            for e, m, n, r in rows
        ]
        + [{"engine": "c", "method": "y", "n": 1000, "status": "skipped", "note": "budget"}]
    )
    table.attrs.update(bandwidth_bytes_per_s=1e10, bytes_per_particle_step=96, budget_s=20.0)
    return table


def test_the_report_sentence_states_what_the_table_holds():
    [intro, compared] = report_scaling.scaling_lines(_synthetic())
    assert "10.0 GB/s" in intro and "1.04e+08 particle-steps/s" in intro  # 1e10 / 96
    assert "20 s budget" in intro
    # n = 1000 is the largest n two engines reached; each engine's fastest method there
    assert compared.startswith("At n = 1,000, the largest n that more than one engine reached")
    assert "a / fast 3e+08 (288% of the bandwidth)" in compared  # 3e8 * 96 / 1e10
    assert "b / x 1.5e+07 (14% of the bandwidth, 20.0x slower)" in compared  # 3e8 / 1.5e7
    assert "c / y" not in compared and "a / slow" not in compared
    assert report_scaling.percent(0.0028) == "0.28%" and report_scaling.percent(0.5) == "50%"
    assert "stayed in cache" in compared


@pytest.mark.engine
def test_the_report_section_recomputes_from_the_measured_table(table, tmp_path):
    n, shared = report_scaling.comparison_n(table)
    ok = table[(table["status"] == "ok") & (table["n"] == n)]
    assert shared and ok["engine"].nunique() == 2
    parts = report_scaling.scaling_section(table, tmp_path)
    text = "\n".join(parts)
    for engine, rows in ok.groupby("engine"):
        best = rows.loc[rows["particle_steps_per_s"].idxmax()]
        assert f"{engine} / {best.method} {best.particle_steps_per_s:.3g} (" in text
    assert (tmp_path / "scaling.png").is_file()
    assert f"{len(table)} rows of the scaling table" in text


def test_a_run_without_the_rain_case_says_so(tmp_path):
    parts = report_scaling.scaling_section(pd.DataFrame(), tmp_path)
    assert "Not run" in parts[1] and not list(tmp_path.iterdir())


def test_the_reference_on_several_threads_says_so_and_other_engines_run_as_they_do():
    """``threads=2``: the reference's rows run and say ``on 2 threads`` (its adapter takes
    the count), pymunk's run as they do and say nothing of threads; a count below 1 is
    refused."""
    compile_reference_loops()
    out = bench.scaling_table(
        ["reference", "pymunk"], sizes=[300, 600], budget_s=AMPLE_S, target_s=TARGET_S, threads=2
    )
    assert out.attrs["threads"] == 2
    ran = out[out.status == "ok"]
    reference, pymunk = ran[ran.engine == "reference"], ran[ran.engine == "pymunk"]
    assert len(reference) and len(pymunk)
    assert reference.note.str.startswith("on 2 threads").all()
    assert not out[out.engine == "pymunk"].note.str.contains("thread").any()
    assert bench.threaded("reference") and not bench.threaded("pymunk")
    with pytest.raises(ValueError, match="threads"):
        bench.scaling_table(["reference"], sizes=[10], threads=0)
