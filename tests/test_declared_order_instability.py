"""A declared-order gate whose sweep goes unstable on a scene with no exact stability limit
(issue 35, item 8; a new user's flipped damper on spring-damper-pair was "not evaluated",
exit 0): it fails where a method no more stable on undamped modes ran ok at that step or a
larger one, and stays not evaluated where none did (a chaotic encounter)."""

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

CASE = "spring-damper-pair"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("run")
    assert main(["run", "--quick", "--cases", CASE, "--engines", "reference", "--out", str(out)]) == 0
    return out


def _planted(run_dir: Path, tmp_path: Path, unstable: list[str]) -> Path:
    """A copy of the run with every fixed-step row of ``unstable`` methods made ``unstable``
    (no error), as a flipped damper makes them; its record keeps no row counts."""
    dest = tmp_path / "planted"
    shutil.copytree(run_dir, dest, ignore=shutil.ignore_patterns("figures", "index.*"))
    record = json.loads((dest / "run.json").read_text())
    record.pop("rows", None)
    (dest / "run.json").write_text(json.dumps(record))
    results = pd.read_csv(dest / "results.csv")
    rows = results["method"].isin(unstable) & (results["dt_kind"] == "step")
    results.loc[rows, ["status", "error"]] = ["unstable", np.nan]
    results.to_csv(dest / "results.csv", index=False)
    return dest


def _line(out: str, method: str) -> str:
    return next(x for x in out.splitlines() if f"{CASE}/order/reference/{method}/declared" in x)


def test_the_scene_s_exact_limit_is_unknown_so_only_its_peers_can_tell():
    """The spring has a rest length: no exact stability limit, so the check by the method's
    own facts (``unstable where its facts say stable``) cannot fire here."""
    case = load_case(library()[CASE])
    assert stability_limit(case, "verlet") is None


def test_unstable_where_a_method_no_more_stable_ran_ok_fails(run_dir, tmp_path, capsys):
    planted = _planted(run_dir, tmp_path, ["verlet"])
    code = main(["gate", "--results", str(planted / "results.csv"), "--declared-orders", "-v"])
    out = capsys.readouterr().out
    line = _line(out, "verlet")
    assert code == 1 and line.startswith("FAIL"), out
    assert "unstable at the sweep's finest step" in line and "no more stable on undamped modes" in line
    # the method that ran ok: symplectic Euler, the reach of Verlet's (2 / omega) and ok at every step
    assert "reference/symplectic-euler" in line and "(its reach 2 against 2)" in line


def test_unstable_where_no_method_as_weak_ran_ok_stays_not_evaluated(run_dir, tmp_path, capsys):
    """Every method of at most Verlet's reach unstable too (as on a chaotic close encounter,
    where round-off decides): nothing says the step was not too large, so not evaluated."""
    weak = ["verlet", "symplectic-euler", "lecture", "euler", "midpoint", "heun"]
    planted = _planted(run_dir, tmp_path, weak)
    main(["gate", "--results", str(planted / "results.csv"), "--declared-orders", "-v"])
    line = _line(capsys.readouterr().out, "verlet")
    assert line.startswith("SKIP") and "fewer than two errors" in line, line
