"""The declared gates of ``truestep gate --declared-orders`` at their edges, each planted on
a copy of a real quick run of the reference:

- a sweep unstable on a scene with no exact stability limit (issue 35, item 8; a new user's
  flipped damper on spring-damper-pair was "not evaluated", exit 0): it fails where a method
  no more stable on undamped modes ran ok at that step or a larger one, and stays not
  evaluated where none did (a chaotic encounter);
- a method whose facts make it exact on a case (a constant acceleration: Verlet, RK4, the
  lecture's update on free-fall) is gated on exactness, where it got no gate at all (a new
  user's trial: "free-fall Verlet gets no declared-order verdict and is not counted as not
  evaluated"): every run's error at round-off holds it, an error above round-off fails it.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from truestep.cases import library, load_case
from truestep.cases.exact import stability_limit
from truestep.cli import main

DAMPED, FALLING = "spring-damper-pair", "free-fall"


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """A quick run of the reference on each case, by case name."""
    out = {}
    for case in (DAMPED, FALLING):
        out[case] = tmp_path_factory.mktemp(case)
        assert (
            main(["run", "--quick", "--cases", case, "--engines", "reference", "--out", str(out[case])]) == 0
        )
    return out


def _planted(run: Path, dest: Path, plant) -> Path:
    """A copy of ``run`` in ``dest`` whose results ``plant(results)`` altered in place; its
    record keeps no row counts (those of the run copied would refuse the altered table)."""
    shutil.copytree(run, dest, ignore=shutil.ignore_patterns("figures", "index.*"))
    record = json.loads((dest / "run.json").read_text())
    record.pop("rows", None)
    (dest / "run.json").write_text(json.dumps(record))
    results = pd.read_csv(dest / "results.csv")
    plant(results)
    results.to_csv(dest / "results.csv", index=False)
    return dest


def _unstable(methods: list[str]):
    """Every fixed-step row of ``methods`` made ``unstable`` (no error), as a flipped damper makes them."""

    def plant(results: pd.DataFrame) -> None:
        rows = results["method"].isin(methods) & (results["dt_kind"] == "step")
        results.loc[rows, ["status", "error"]] = ["unstable", np.nan]

    return plant


def _declared(out: str, case: str, method: str) -> str:
    return next(x for x in out.splitlines() if f"{case}/order/reference/{method}/declared" in x)


def test_the_damped_scene_s_exact_limit_is_unknown_so_only_its_peers_can_tell():
    """The spring has a rest length: no exact stability limit, so the check by the method's
    own facts (``unstable where its facts say stable``) cannot fire here."""
    assert stability_limit(load_case(library()[DAMPED]), "verlet") is None


def test_unstable_where_a_method_no_more_stable_ran_ok_fails(runs, tmp_path, capsys):
    planted = _planted(runs[DAMPED], tmp_path / "planted", _unstable(["verlet"]))
    code = main(["gate", "--results", str(planted / "results.csv"), "--declared-orders", "-v"])
    out = capsys.readouterr().out
    line = _declared(out, DAMPED, "verlet")
    assert code == 1 and line.startswith("FAIL"), out
    assert "unstable at the sweep's finest step" in line and "no more stable on undamped modes" in line
    # the method that ran ok: symplectic Euler, the reach of Verlet's (2 / omega) and ok at every step
    assert "reference/symplectic-euler" in line and "(its reach 2 against 2)" in line


def test_unstable_where_no_method_as_weak_ran_ok_stays_not_evaluated(runs, tmp_path, capsys):
    """Every method of at most Verlet's reach unstable too (as on a chaotic close encounter,
    where round-off decides): nothing says the step was not too large, so not evaluated."""
    weak = ["verlet", "symplectic-euler", "lecture", "euler", "midpoint", "heun"]
    planted = _planted(runs[DAMPED], tmp_path / "planted", _unstable(weak))
    main(["gate", "--results", str(planted / "results.csv"), "--declared-orders", "-v"])
    line = _declared(capsys.readouterr().out, DAMPED, "verlet")
    assert line.startswith("SKIP") and "fewer than two errors" in line, line


def test_exact_methods_are_gated_exact_and_hold(runs, capsys):
    run = runs[FALLING]
    results = pd.read_csv(run / "results.csv")
    code = main(["gate", "--results", str(run / "results.csv"), "--declared-orders", "-v"])
    out = capsys.readouterr().out
    assert code == 0, out
    for method in ("verlet", "rk4", "midpoint", "heun", "lecture"):
        line = _declared(out, FALLING, method)
        assert line.startswith("ok") and "required exact" in line, line
        errors = results.loc[(results["method"] == method) & (results["dt_kind"] == "step"), "error"]
        assert len(errors) >= 2 and (errors < 1e-13).all()  # the closed form, to round-off
    for method in ("euler", "symplectic-euler", "implicit-euler"):  # first order there: an order
        assert "measured order 1.0" in _declared(out, FALLING, method)


def test_a_method_that_loses_its_exactness_fails(runs, tmp_path, capsys):
    """Verlet with a lost half step: its error on free-fall is first order, g t h / 2 (here
    planted as that value), far above round-off; the order it shows (1) is not what is
    declared (2), but an exact method has no order gate to fail, so exactness must."""

    def lost_half_step(results: pd.DataFrame) -> None:
        rows = (results["method"] == "verlet") & (results["dt_kind"] == "step")
        results.loc[rows, "error"] = 9.81 * 1.0 * results.loc[rows, "dt"] / 2

    planted = _planted(runs[FALLING], tmp_path / "planted", lost_half_step)
    code = main(["gate", "--results", str(planted / "results.csv"), "--declared-orders", "-v"])
    line = _declared(capsys.readouterr().out, FALLING, "verlet")
    errors = pd.read_csv(planted / "results.csv").query("method == 'verlet' and dt_kind == 'step'")["error"]
    assert code == 1 and line.startswith("FAIL") and "required exact" in line, line
    assert f"largest error {float(errors.max()):.3g}" in line
