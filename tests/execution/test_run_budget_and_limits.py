"""The whole run has a wall-clock budget, and the cost limits can be set for a run."""

from __future__ import annotations

import pandas as pd

from truestep.cli import main
from truestep.runtime.isolation import BUDGET_SPENT


def test_a_spent_budget_makes_timeout_rows_and_the_report_is_still_written(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(
        [
            "run",
            "--quick",
            "--cases",
            "free-fall,harmonic-oscillator",
            "--engines",
            "reference",
            "--budget",
            "0.5",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    results = pd.read_csv(out / "results.csv")
    spent = results[results["message"] == BUDGET_SPENT]
    assert len(spent) and set(spent["status"]) == {"timeout"}
    assert (out / "index.html").is_file()
    stability = pd.read_csv(out / "stability.csv")
    searched = stability[stability["status"] != "skipped"]
    assert len(searched) and set(searched["status"]) == {"timeout"}  # not started after the end


def test_limits_on_the_command_line_refuse_a_case_with_exit_2(tmp_path, capsys):
    code = main(
        [
            "run",
            "--quick",
            "--cases",
            "free-fall",
            "--engines",
            "reference",
            "--limit",
            "steps=10",
            "--out",
            str(tmp_path / "out"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "steps, over the limit of 10" in err and "Traceback" not in err
    code = main(
        [
            "run",
            "--quick",
            "--cases",
            "free-fall",
            "--engines",
            "reference",
            "--limit",
            "stepz=10",
            "--out",
            str(tmp_path / "out"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "--limit" in err and len(err.strip().splitlines()) == 1
    code = main(
        [
            "run",
            "--quick",
            "--cases",
            "free-fall",
            "--engines",
            "reference",
            "--budget",
            "-1",
            "--out",
            str(tmp_path / "out"),
        ]
    )
    assert code == 2 and "--budget" in capsys.readouterr().err
    assert not (tmp_path / "out" / "results.csv").exists()


def test_a_step_that_runs_past_its_timeout_is_its_own_row_and_the_sweep_goes_on(tmp_path):
    """An oscillator made 1e13 times stiffer: scipy's explicit RK45 needs ~1e8 steps at
    any tolerance. Each step of the sweep stops at the case's timeout (1 s) as its own
    ``timeout`` row, inside the one sweep process: not the whole sweep's time, twice."""
    import re
    import time

    from truestep.cases.loader import CASE_DIR, load_case
    from truestep.execution.runner import Timing, run_sweep

    text = (CASE_DIR / "harmonic-oscillator.toml").read_text()
    text = re.sub(r"^stiffness = .*$", "stiffness = 1e14", text, count=1, flags=re.M)
    text = re.sub(r"^duration = (.*)$", r"duration = \1\ntimeout = 1.0", text, count=1, flags=re.M)
    text = re.sub(r"^\[stability\]\n(.+\n)+", "", text, flags=re.M)
    text = re.sub(r"^\[\[gates\]\]\n(.+\n)+", "", text, flags=re.M)
    path = tmp_path / "stiff-oscillator.toml"
    path.write_text(text)
    case = load_case(path)
    started = time.perf_counter()
    rows = run_sweep(case, "scipy", "RK45", [1e-4, 1e-6], adaptive=True, timing=Timing())
    assert [r["status"] for r in rows] == ["timeout", "timeout"]
    assert all("longer than 1 s" in r["message"] for r in rows)
    assert time.perf_counter() - started < 6.0


def test_too_little_space_beside_out_fails_before_the_sweep(tmp_path, capsys, monkeypatch):
    import shutil
    from collections import namedtuple

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10**9, 10**9 - 2**20, 2**20))
    code = main(
        ["run", "--quick", "--cases", "free-fall", "--engines", "reference", "--out", str(tmp_path / "out")]
    )
    err = capsys.readouterr().err
    assert code == 2 and "MiB free beside" in err and "sweep" not in err
    assert not (tmp_path / "out").exists()
