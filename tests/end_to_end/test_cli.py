"""The command line as a user (or CI) calls it, and gates that can fail."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from truestep.cases import load_case
from truestep.cases.loader import CASE_DIR
from truestep.ci.gates import check_gates
from truestep.cli import main
from truestep.execution.runner import run_matrix
from truestep.reference_impl.solvers import RK4


@pytest.fixture(scope="module")
def quick_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    assert (
        main(["run", "--quick", "--cases", "circle-field", "--engines", "reference", "--out", str(out)]) == 0
    )
    return out


def test_run_writes_every_contracted_file(quick_report):
    for name in ("results.csv", "stability.csv", "restitution.csv", "index.md", "index.html"):
        assert (quick_report / name).is_file(), name
    results = pd.read_csv(quick_report / "results.csv")
    for col in (
        "case",
        "engine",
        "method",
        "dt",
        "dt_kind",
        "status",
        "error",
        "energy_drift",
        "nfev",
        "wall_s",
    ):
        assert col in results.columns
    # Methods that need a position/velocity split are rows that say why, not gaps.
    verlet = results[results["method"] == "verlet"]
    assert list(verlet["status"]) == ["unsupported"]
    assert verlet["missing"].iloc[0] == "second-order"
    assert set(results.loc[results["method"] == "dopri5", "dt_kind"]) == {"tolerance"}


def test_gate_passes_on_a_good_run(quick_report, capsys):
    code = main(["gate", "--results", str(quick_report / "results.csv"), "--cases", "circle-field"])
    assert code == 0, capsys.readouterr().out


def test_gate_fails_naming_measured_and_required(quick_report, tmp_path, capsys):
    results = pd.read_csv(quick_report / "results.csv")
    rk4 = (results["method"] == "rk4") & (results["status"] == "ok")
    results.loc[rk4, "error"] *= results.loc[rk4, "dt"] ** -2.0  # order 4 -> order 2
    path = tmp_path / "results.csv"
    results.to_csv(path, index=False)
    assert main(["gate", "--results", str(path), "--cases", "circle-field"]) == 1
    out = capsys.readouterr().out
    assert "FAIL circle-field/order/reference/rk4 (gates[2]" in out
    assert "measured order 2.0" in out and "required 4 +- 0.2" in out


def test_bad_input_exits_2_with_one_line_and_loses_nothing(quick_report, tmp_path, capsys):
    before = (quick_report / "results.csv").read_bytes()
    bad = CASE_DIR / "zz-broken-for-test.toml"
    bad.write_text('kind = "particles"\n[run]\nduration = -1\ndt = [0.1]\n')
    try:
        code = main(["run", "--quick", "--cases", "zz-broken-for-test", "--out", str(quick_report)])
    finally:
        bad.unlink()
    err = capsys.readouterr().err
    assert code == 2
    assert err.strip().count("\n") == 0
    assert "zz-broken-for-test.toml: run.duration: must be positive" in err
    assert "Traceback" not in err
    assert (quick_report / "results.csv").read_bytes() == before
    assert main(["gate", "--results", str(tmp_path / "nope.csv")]) == 2
    assert main(["run", "--engines", "nosuch", "--out", str(tmp_path)]) == 2


def test_a_wrong_tableau_entry_fails_the_order_gate(monkeypatch):
    case = load_case(CASE_DIR / "circle-field.toml")
    good = run_matrix([case], ["reference"], quick=False, progress=lambda _: None)
    assert all(v.passed for v in check_gates([case], good) if v.gate.method == "rk4")
    # Swap weight between stages 2 and 3: B still sums to 1 (consistent), order drops.
    monkeypatch.setattr(RK4, "B", np.array([1.0, 1.0, 3.0, 1.0]) / 6.0)
    broken = run_matrix([case], ["reference"], quick=False, progress=lambda _: None)
    verdicts = [v for v in check_gates([case], broken) if v.gate.method == "rk4"]
    assert verdicts and not any(v.passed for v in verdicts)


def test_list_prints_cases_engines_and_methods(capsys):
    assert main(["list", "--engines", "reference,scipy"]) == 0
    out = capsys.readouterr().out
    assert "harmonic-oscillator" in out and "dopri5" in out and "Radau" in out


def test_a_finite_run_whose_energy_explodes_is_an_unstable_row():
    """Explicit Euler on the stiff spring (omega = 1000 rad/s) at 1 ms stays below the
    1e12 blow-up bound over 0.05 s but multiplies its energy by (1 + 1)^50: the row must
    say unstable, with the time. Symplectic Euler at the same step (omega dt = 1) is
    inaccurate, its energy swinging by as much as its start, but bounded: an ok row."""
    from truestep.execution.runner import Timing, run_one

    case = load_case(CASE_DIR / "stiff-spring.toml")
    timing = Timing(long_run_s=0.0)
    bad = run_one(case, "reference", "euler", 1e-3, adaptive=False, timing=timing)
    assert bad["status"] == "unstable"
    assert 0 < bad["t_fail"] < case.duration and bad["energy_drift"] > 1
    assert "energy grew" in bad["message"]
    good = run_one(case, "reference", "symplectic-euler", 1e-3, adaptive=False, timing=timing)
    # over every step, the swing reaches its start's size to within a step's sampling
    assert good["status"] == "ok" and 0.5 < good["energy_drift"] <= 1.0 + 1e-4
