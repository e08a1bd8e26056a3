"""One answer on every machine: the floating-point environment, work-bounded timing, ties,
and the baseline that compares only what a run was asked for (issue 18)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import ClassVar

import numpy as np
import pandas as pd
import pytest

import truestep
from truestep import numerics
from truestep.cli import main
from truestep.execution.runner import MACHINE_COLUMNS, NOT_REPEATABLE, Timing, simulate_timed, spread
from truestep.measures.picks import TIE_NOISE, cheapest, noise_interval, scorecard, tied_with_fastest


def _python(code: str, **env: str) -> str:
    """Run ``code`` in a fresh interpreter with ``env`` added; its standard output."""
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        env={**os.environ, **env},
        check=True,
        timeout=120,
    )
    return out.stdout.strip()


NUMERICS_SEEN = """
    import json, numpy, scipy.linalg
    from threadpoolctl import threadpool_info
    from numpy._core._multiarray_umath import __cpu_features__ as f
    print(json.dumps({"threads": sorted({p["num_threads"] for p in threadpool_info()}),
                      "arch": sorted({p.get("architecture") for p in threadpool_info()}),
                      "v4": bool(f.get("X86_V4"))}))
"""
"""Prints what numpy and scipy's BLAS compute with in this process."""


def _clean_env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k not in numerics.environment() and k != numerics.OPT_OUT}


def test_the_command_pins_threads_kernels_and_dispatch():
    """What the ``truestep`` command's process computes with (its entry point,
    truestep.command.main, before the command loads numpy): one BLAS thread (the machine has
    more), the Haswell kernels, no AVX-512 dispatch in numpy."""
    code = "from truestep import command\ncommand.main(['env'])\n" + textwrap.dedent(NUMERICS_SEEN)
    env = _clean_env()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["threads"] == [1]
    if {"avx2", "fma"} <= numerics._cpu_flags():
        assert seen["arch"] == [numerics.OPENBLAS_CORE]
    assert seen["v4"] is False


def test_importing_truestep_and_its_plugin_changes_nothing_in_the_process():
    """A user's process (a pytest session with the plugin loaded): the same environment
    variables, BLAS threads and numpy dispatch with truestep imported as without."""
    probe = "import os, json; before = dict(os.environ)\nIMPORTS\n"
    probe += "assert dict(os.environ) == before, set(os.environ) ^ set(before)\n"
    probe += textwrap.dedent(NUMERICS_SEEN)

    def seen(imports: str) -> subprocess.CompletedProcess:
        code = probe.replace("IMPORTS", imports)
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=_clean_env())

    without = seen("")
    with_it = seen("import truestep, truestep.pytest_plugin, truestep.api, truestep.cli, truestep.execution")
    assert without.returncode == 0 and with_it.returncode == 0, with_it.stderr[-800:]
    assert json.loads(with_it.stdout.splitlines()[0]) == json.loads(without.stdout.splitlines()[0])


def test_the_suite_computes_as_the_command_does():
    """tests/conftest.py sets the command's environment before numpy loads: the suite's
    in-process runs compare bit for bit with the baselines the command wrote."""
    from numpy._core._multiarray_umath import __cpu_features__

    assert not __cpu_features__.get("X86_V4") and os.environ["OMP_NUM_THREADS"] == "1"


def test_a_run_holds_threads_to_one_while_it_runs_and_gives_them_back():
    """A library user who imported numpy with two BLAS threads: truestep's run computes on
    one (numerics.own_run), and the user's process has its two again afterwards, with its
    environment as it was."""
    code = """
        import os
        import numpy
        from threadpoolctl import threadpool_info
        from truestep.numerics import own_run
        before, env = max(p["num_threads"] for p in threadpool_info()), dict(os.environ)
        with own_run():
            during = max(p["num_threads"] for p in threadpool_info())
            set_during = os.environ.get("OMP_NUM_THREADS")
        after = max(p["num_threads"] for p in threadpool_info())
        print(before, during, set_during, after, dict(os.environ) == env)
    """
    env = {**_clean_env(), "OPENBLAS_NUM_THREADS": "2"}
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env, check=True
    ).stdout
    assert out.split() == ["2", "1", "1", "2", "True"]


def test_radau_gives_the_same_bits_whatever_the_blas_threads_asked(tmp_path):
    """spring-chain with scipy's Radau (an LU per Newton step) was 1.973156e-10 with two
    BLAS threads and 1.973537e-10 with one; now the same bits either way."""
    code = """
        import truestep
        t = truestep.run("spring-chain", engines=["scipy"], quick=True, analyses=False,
                         progress=lambda m: None)
        r = t.results[t.results["method"] == "Radau"]
        print(" ".join(float(e).hex() for e in r["error"]))
    """
    one = _python(code, OPENBLAS_NUM_THREADS="1")
    two = _python(code, OPENBLAS_NUM_THREADS="2")
    assert one == two and "nan" not in one


def test_fingerprint_differences_name_what_moved():
    fp = numerics.fingerprint()
    assert fp["packages"]["numpy"] == np.__version__ and fp["blas"]
    other = json.loads(json.dumps(fp))
    other["packages"]["numpy"] = "0.0"
    other["numpy_simd"] = ["X86_V3", "X86_V4"]
    lines = numerics.differences(fp, other)
    assert f"numpy {np.__version__} -> 0.0" in lines
    assert any(line.startswith("numpy_simd:") for line in lines)
    assert numerics.differences(fp, fp) == []


def test_a_scheduling_package_s_version_is_recorded_and_decides_no_comparison():
    """A fresh install takes the newest distributed; a cluster run's tables are a local
    run's, so its version is recorded but does not make two runs incomparable (it did,
    and CI's quick gate fell back to tolerances when Dask released)."""
    fp = numerics.fingerprint()
    assert "distributed" in numerics.PACKAGES and "distributed" in numerics.SCHEDULING_ONLY
    other = json.loads(json.dumps(fp))
    other["packages"]["distributed"] = "9999.1.0"
    assert numerics.differences(fp, other) == []
    other["packages"]["scipy"] = "0.0"
    assert numerics.differences(fp, other) == [f"scipy {fp['packages']['scipy']} -> 0.0"]


def test_timing_repeats_short_runs_and_times_long_ones_once():
    t = Timing()
    assert t.runs_after(1e-5) == t.max_repeats
    assert t.runs_after(0.01) == 5 and t.runs_after(0.02) == t.min_repeats
    assert t.runs_after(0.1) == 2 and t.runs_after(t.long_run_s) == 1
    assert np.isnan(spread([1.0])) and spread([1.0, 1.4]) == pytest.approx(0.2)
    assert spread([1.0, 1.1, 1.2, 1.3, 9.0]) == pytest.approx(0.1)  # an outlier is not noise


class Jittery:
    """An engine whose end state depends on the run: not repeatable."""

    name = "jittery"
    methods = ("euler",)
    adaptive_methods = ()
    capabilities = frozenset({"point-masses", "3d", "uniform-gravity"})
    runs: ClassVar[list[int]] = [0]

    def missing(self, case, method):
        return set()

    def simulate(self, case, method, dt):
        from truestep.adapters.base import Trajectory

        Jittery.runs[0] += 1
        t = np.array([0.0, case.duration])
        x = np.zeros((2, 1, 3)) + 1e-12 * Jittery.runs[0]
        return Trajectory(t=t, x=x, v=np.zeros((2, 1, 3)), energy=np.zeros(2), wall_s=1e-4, nfev=1, steps=1)


def test_an_engine_that_is_not_repeatable_says_so(monkeypatch, case_named):
    import truestep.execution.timing as timing

    monkeypatch.setattr(timing, "get_adapter", lambda name: Jittery())
    traj = simulate_timed("jittery", case_named("free-fall"), "euler", 0.01, Timing())
    assert NOT_REPEATABLE in traj.message and int(traj.extra["repeats"]) > 1


def _rows(*runs):
    cols = ["case", "engine", "method", "dt", "dt_kind", "status", "error", "nfev", "wall_s", "wall_s_spread"]
    return pd.DataFrame([("harmonic-oscillator", *r) for r in runs], columns=cols)


def test_runs_within_noise_are_tied_and_the_fewest_evaluations_is_named(case_named):
    """rk4 at 1.00 ms and heun at 1.10 ms (within 15% of each other) tie; the one named is
    heun's, which needs fewer evaluations; euler at 2 ms is not in the tie."""
    case = case_named("harmonic-oscillator")
    rows = _rows(
        ("reference", "rk4", 0.01, "step", "ok", 1e-9, 4000, 1.00e-3, 1e-5),
        ("reference", "heun", 0.001, "step", "ok", 1e-9, 2000, 1.10e-3, 1e-5),
        ("reference", "euler", 1e-5, "step", "ok", 1e-9, 99999, 2.0e-3, 1e-5),
    )
    assert tied_with_fastest(rows).tolist() == [True, True, False]
    pick = cheapest(rows, [case], targets=(1e-4,)).set_index("by")
    assert pick.loc["wall_s", "method"] == "heun"
    assert pick.loc["wall_s", "tied"] == "reference / rk4 (dt 0.01)"
    apart = rows.assign(wall_s=[1e-3, 1e-3 * (1 + 2.5 * TIE_NOISE), 2e-3])
    assert cheapest(apart, [case], targets=(1e-4,)).set_index("by").loc["wall_s", "tied"] == ""


def test_a_row_whose_repeats_spread_past_their_median_is_not_tied_with_one_far_faster(case_named):
    """Stop 72's finding: circle-field scipy / RK45 at tol 1e-3 timed at a median 1.569 ms
    with half its interquartile range 2.111 ms, so ``wall - band`` fell below 0 and the row
    was "tied" with a run 122 times faster: the scorecard gave RK45 a cost ratio of 1 there
    and made it the orbit family's pick. Noise is a factor: that row is known to lie
    between 1.569 / 2.345 = 0.669 ms and 3.68 ms, nowhere near 0.0128 ms."""
    case = case_named("harmonic-oscillator")
    rows = _rows(
        ("scipy", "RK45", 1e-3, "tolerance", "ok", 1e-9, 300, 1.569e-3, 2.111e-3),
        ("reference", "rk4", 0.01, "step", "ok", 1e-9, 4000, 1.28e-5, 1e-7),
    )
    assert tied_with_fastest(rows).tolist() == [False, True]
    low, high = noise_interval(np.array([1.569e-3]), np.array([2.111e-3]))
    assert low[0] == pytest.approx(1.569e-3 / (1 + 2.111 / 1.569)) and high[0] == pytest.approx(3.68e-3)
    pick = cheapest(rows, [case], targets=(1e-4,)).set_index("by")
    assert pick.loc["wall_s", "method"] == "rk4" and pick.loc["wall_s", "tied"] == ""
    card = scorecard(rows, [case]).set_index(["engine", "method"])
    assert card.loc[("scipy", "RK45"), "cost_ratio"] == pytest.approx(1.569e-3 / 1.28e-5)
    assert card.loc[("reference", "rk4"), "cost_ratio"] == 1.0


def _gateless(tmp_path: Path) -> str:
    """harmonic-oscillator without its gates: the baseline alone decides these runs."""
    from truestep.cases.loader import CASE_DIR

    text = (CASE_DIR / "harmonic-oscillator.toml").read_text().split("[[gates]]")[0]
    path = tmp_path / "cases" / "harmonic-oscillator.toml"
    path.parent.mkdir()
    path.write_text(text)
    return str(path)


def _gate_run_against_base(tmp_path: Path, option: str) -> list[str]:
    """``truestep gate``'s arguments for ``tmp_path``'s ``run`` against its ``base``, the
    case without its gates (:func:`_gateless`), with ``option``."""
    results, base = str(tmp_path / "run" / "results.csv"), str(tmp_path / "base")
    return ["gate", "--results", results, "--cases", _gateless(tmp_path), "--baseline", base, option]


def _gateless_again(tmp_path: Path) -> str:
    """The case file :func:`_gateless` wrote."""
    return str(tmp_path / "cases" / "harmonic-oscillator.toml")


def _write_run(out: Path, rows: pd.DataFrame, cases: list[str], engines: list[str]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    rows.to_csv(out / "results.csv", index=False)
    (out / "run.json").write_text(
        json.dumps({"truestep": "x", "cases": cases, "engines": engines, "numerics": numerics.fingerprint()})
    )


def test_a_narrowed_run_compares_with_only_what_it_asked_for(tmp_path, capsys):
    """The baseline ran free-fall and harmonic-oscillator with two engines; the run only
    harmonic-oscillator with the reference: nothing vanished. An edited cell differs."""
    full = _rows(
        ("reference", "rk4", 0.01, "step", "ok", 1e-9, 400, 1e-3, 0),
        ("scipy", "RK45", 1e-6, "tolerance", "ok", 1e-7, 90, 1e-3, 0),
    )
    both = pd.concat([full, full.assign(case="free-fall")])
    _write_run(tmp_path / "base", both, ["harmonic-oscillator", "free-fall"], ["reference", "scipy"])
    _write_run(tmp_path / "run", full.iloc[:1], ["harmonic-oscillator"], ["reference"])
    argv = [
        "gate",
        "--results",
        str(tmp_path / "run" / "results.csv"),
        "--baseline",
        str(tmp_path / "base"),
        "--identical",
        "--cases",
        _gateless(tmp_path),
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "0 vanished" in out and "0 cells differ" in out
    (tmp_path / "run" / "results.csv").write_text(
        full.iloc[:1].assign(error=1.0000000001e-9).to_csv(index=False)
    )
    assert main(argv) == 1
    assert "DIFFERS results harmonic-oscillator reference rk4 dt=0.01 error" in capsys.readouterr().out


def test_identical_does_not_apply_across_package_versions(tmp_path, capsys):
    rows = _rows(("reference", "rk4", 0.01, "step", "ok", 1e-9, 400, 1e-3, 0))
    _write_run(tmp_path / "base", rows, ["harmonic-oscillator"], ["reference"])
    record = json.loads((tmp_path / "base" / "run.json").read_text())
    record["numerics"]["packages"]["scipy"] = "0.1"
    (tmp_path / "base" / "run.json").write_text(json.dumps(record))
    _write_run(tmp_path / "run", rows.assign(error=1.0000001e-9), ["harmonic-oscillator"], ["reference"])
    assert main(_gate_run_against_base(tmp_path, "--identical")) == 0
    assert "not comparable bit for bit (scipy 0.1 ->" in capsys.readouterr().out


@pytest.mark.parametrize("missing", [False, True], ids=["other-versions", "no-run-json"])
def test_require_identical_fails_where_the_runs_cannot_be_compared_bit_for_bit(tmp_path, capsys, missing):
    """``--require-identical`` is ``--identical`` that does not fall back: a baseline made
    with another scipy (or without its ``run.json``) fails the gate (exit 1), one line
    saying why, though its tolerances hold; the same runs under one environment pass, and a
    cell one ulp off fails as under ``--identical``. The API says the same."""
    rows = _rows(("reference", "rk4", 0.01, "step", "ok", 1e-9, 400, 1e-3, 0))
    _write_run(tmp_path / "base", rows, ["harmonic-oscillator"], ["reference"])
    _write_run(tmp_path / "run", rows, ["harmonic-oscillator"], ["reference"])
    argv = _gate_run_against_base(tmp_path, "--require-identical")
    assert main(argv) == 0
    assert "--identical: 8 non-timing cells compared, 0 differ" in capsys.readouterr().out.splitlines()[0]

    record_path = tmp_path / "base" / "run.json"
    if missing:
        record_path.unlink()
        why = "run.json is missing"
    else:
        record = json.loads(record_path.read_text())
        record["numerics"]["packages"]["scipy"] = "0.1"
        record_path.write_text(json.dumps(record))
        why = "not comparable bit for bit (scipy 0.1 ->"
    assert main(argv) == 1
    out = capsys.readouterr().out.splitlines()
    failed = [line for line in out if line.startswith("FAIL --require-identical: ")]
    assert len(failed) == 1 and why in failed[0], out
    assert "0 worse" in out[-1]  # the tolerances held: only the requirement failed
    report = truestep.gate(
        tmp_path / "run" / "results.csv",
        cases=_gateless_again(tmp_path),
        baseline=tmp_path / "base",
        require_identical=True,
    )
    assert not report.passed and report.reasons == [failed[0].removeprefix("FAIL ")]
    assert truestep.gate(
        tmp_path / "run" / "results.csv",
        cases=_gateless_again(tmp_path),
        baseline=tmp_path / "base",
        identical=True,
    ).passed

    _write_run(tmp_path / "base", rows, ["harmonic-oscillator"], ["reference"])
    one_ulp_off = rows.assign(error=np.nextafter(1e-9, 1.0))
    _write_run(tmp_path / "run", one_ulp_off, ["harmonic-oscillator"], ["reference"])
    assert main(argv) == 1
    out = capsys.readouterr().out  # the two doubles as they read back, not alike to 6 figures
    cell = "DIFFERS results harmonic-oscillator reference rk4 dt=0.01 error"
    assert f"{cell}: 1e-09 -> {float(np.nextafter(1e-9, 1.0))!r}" in out, out


def test_require_identical_without_a_baseline_is_bad_input(tmp_path, capsys):
    rows = _rows(("reference", "rk4", 0.01, "step", "ok", 1e-9, 400, 1e-3, 0))
    _write_run(tmp_path / "run", rows, ["harmonic-oscillator"], ["reference"])
    assert main(["gate", "--results", str(tmp_path / "run" / "results.csv"), "--require-identical"]) == 2
    assert "add --baseline DIR" in capsys.readouterr().err


def test_machine_columns_are_the_only_ones_left_out():
    from truestep.execution.runner import RESULT_COLUMNS

    assert set(MACHINE_COLUMNS) <= set(RESULT_COLUMNS)
    assert {"error", "energy_drift", "nfev", "status", "steps", "t_fail"}.isdisjoint(MACHINE_COLUMNS)


def test_a_gate_on_a_step_the_sweep_never_runs_is_refused(tmp_path):
    from truestep.cases import CaseError, load_case
    from truestep.cases.loader import CASE_DIR

    text = (CASE_DIR / "triangle-impulse.toml").read_text()
    assert "dt = [0.01, 0.005, 0.0025" in text
    bad = tmp_path / "triangle-impulse.toml"
    bad.write_text(text.replace("dt = [0.01, 0.005, 0.0025", "dt = [0.01, 0.005, 0.00125", 1))
    with pytest.raises(CaseError, match=r"gates\[2\]\.dt: 0.0025 is not a step .* sweep"):
        load_case(bad)


class HeldUpOnce:
    """An engine whose first timed run the machine held up: 10 ms, where every other run
    of the row (the measured one too) takes 50 us."""

    name = "held-up"
    walls: ClassVar[list[float]] = []

    def simulate(self, case, method, dt):
        from truestep.adapters.base import Trajectory

        wall = 0.01 if len(HeldUpOnce.walls) == 1 else 5e-5  # the warm-up, then the first timed run
        HeldUpOnce.walls.append(wall)
        t = np.array([0.0, case.duration])
        return Trajectory(
            t=t, x=np.zeros((2, 1, 3)), v=None, energy=None, status="ok", wall_s=wall, nfev=1, steps=1
        )


def test_a_first_timed_run_held_up_is_not_the_row_s_only_sample():
    """A new user's A/A on a busy CI: rows of 35-65 us timed once at 8-16 ms (a first run
    of 2 ms or more is timed once in --quick) made wall ratios 250x "worse". With the
    row's measured run known (the same steps, watched, 50 us), the runs are counted from
    the faster of the two: five of them, whose median is the row's 50 us."""
    from truestep.cases import library, load_case
    from truestep.execution.timing import QUICK_TIMING, timed_runs

    case = load_case(library()["free-fall"])
    HeldUpOnce.walls.clear()
    _, once = timed_runs(HeldUpOnce(), case, "euler", 0.01, QUICK_TIMING, warm_up=True)
    assert once.walls == [0.01]  # alone, the held-up run decides: timed once
    HeldUpOnce.walls.clear()
    _, runs = timed_runs(HeldUpOnce(), case, "euler", 0.01, QUICK_TIMING, warm_up=True, known_s=5e-5)
    assert runs.walls == [0.01, 5e-5, 5e-5, 5e-5, 5e-5] and float(np.median(runs.walls)) == 5e-5
