"""A method whose facts make it exact on a case (a constant acceleration: Verlet, RK4, the
lecture's update on free-fall) gets a declared gate of exactness, where it got none (a new
user's trial: "free-fall Verlet gets no declared-order verdict and is not counted as not
evaluated"): every run's error at round-off holds it, an error above round-off fails it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from truestep.cli import main

CASE = "free-fall"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("run")
    assert main(["run", "--quick", "--cases", CASE, "--engines", "reference", "--out", str(out)]) == 0
    return out


def _declared(out: str, method: str) -> str:
    return next(x for x in out.splitlines() if f"{CASE}/order/reference/{method}/declared" in x)


def test_exact_methods_are_gated_exact_and_hold(run_dir, capsys):
    results = pd.read_csv(run_dir / "results.csv")
    code = main(["gate", "--results", str(run_dir / "results.csv"), "--declared-orders", "-v"])
    out = capsys.readouterr().out
    assert code == 0, out
    for method in ("verlet", "rk4", "midpoint", "heun", "lecture"):
        line = _declared(out, method)
        assert line.startswith("ok") and "required exact" in line, line
        errors = results.loc[(results["method"] == method) & (results["dt_kind"] == "step"), "error"]
        assert len(errors) >= 2 and (errors < 1e-13).all()  # the closed form, to round-off
    for method in ("euler", "symplectic-euler", "implicit-euler"):  # first order there: an order
        assert "measured order 1.0" in _declared(out, method)


def test_a_method_that_loses_its_exactness_fails(run_dir, tmp_path, capsys):
    """Verlet with a lost half step: its error on free-fall is first order, g t h / 2 (here
    planted as that value), far above round-off; the order it shows (1) is not what is
    declared (2), but an exact method has no order gate to fail, so exactness must."""
    dest = tmp_path / "planted"
    shutil.copytree(run_dir, dest, ignore=shutil.ignore_patterns("figures", "index.*"))
    record = json.loads((dest / "run.json").read_text())
    record.pop("rows", None)
    (dest / "run.json").write_text(json.dumps(record))
    results = pd.read_csv(dest / "results.csv")
    rows = (results["method"] == "verlet") & (results["dt_kind"] == "step")
    results.loc[rows, "error"] = 9.81 * 1.0 * results.loc[rows, "dt"] / 2
    results.to_csv(dest / "results.csv", index=False)
    code = main(["gate", "--results", str(dest / "results.csv"), "--declared-orders", "-v"])
    line = _declared(capsys.readouterr().out, "verlet")
    assert code == 1 and line.startswith("FAIL") and "required exact" in line, line
    assert f"largest error {float(np.max(results.loc[rows, 'error'])):.3g}" in line
