"""Inputs of the third hostile round (issue 37, item 11) that gave a traceback: each is now
one line on standard error and exit 2, and nothing is written where it should not be."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from truestep.cli import main

BASELINE = Path(__file__).parents[1] / "baselines" / "quick"


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("truestep: error: "), err
    return err[0]


@pytest.mark.parametrize(
    "item, said",
    [("~nosuchuser-truestep", "no such user to expand ~ for"), ("x" * 300, "File name too long")],
)
def test_a_case_item_the_system_cannot_look_up_is_one_line(capsys, item, said):
    assert main(["list", "--cases", item]) == 2
    assert said in _one_line(capsys)


def test_a_baseline_whose_run_record_is_garbled_is_refused_naming_it(tmp_path, capsys):
    bad = tmp_path / "bad"
    bad.mkdir()
    for table in BASELINE.glob("*.csv"):
        (bad / table.name).write_bytes(table.read_bytes())
    (bad / "run.json").write_text("{not json")
    results = str(BASELINE / "results.csv")
    for extra in ([], ["--identical"]):
        assert main(["gate", "--results", results, "--baseline", str(bad), "-q", *extra]) == 2
        line = _one_line(capsys)
        assert "bad/run.json" in line and "not a run record" in line
    (bad / "run.json").write_text("[1, 2]")
    assert main(["gate", "--results", results, "--baseline", str(bad), "-q"]) == 2
    assert "a JSON list, not an object" in _one_line(capsys)


def _command(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    with open(os.devnull, "w") as _, open("/dev/full", "w") as full:
        return subprocess.run(
            [sys.executable, "-m", "truestep", *args], cwd=cwd, stdout=full, stderr=subprocess.PIPE, text=True
        )


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full here")
def test_standard_output_on_a_full_device_is_one_line(tmp_path):
    listed = _command("list", cwd=tmp_path)
    assert listed.returncode == 2 and "Traceback" not in listed.stderr
    assert listed.stderr.strip().splitlines() == [
        "truestep: error: cannot write standard output: No space left on device"
    ]
    ran = _command(
        "run", "--quick", "--cases", "free-fall", "--engines", "reference", "--out", "rep", cwd=tmp_path
    )
    assert ran.returncode == 2 and "Traceback" not in ran.stderr
    said = [line for line in ran.stderr.splitlines() if line.startswith("truestep:")]
    assert said == [
        "truestep: error: the new report is in rep/, but standard output could not be written: "
        "No space left on device"
    ]
    assert (tmp_path / "rep" / "results.csv").is_file()
    for asked in (("--help",), ("gate", "--help"), ("--version",)):  # argparse would pass in silence
        helped = _command(*asked, cwd=tmp_path)
        assert helped.returncode == 2 and helped.stderr.strip().splitlines() == [
            "truestep: error: cannot write standard output: No space left on device"
        ], asked


def test_bench_sizes_over_the_particle_limit_are_one_line_about_sizes(capsys, tmp_path):
    assert main(["bench", "--sizes", "100,1e12", "--out", str(tmp_path / "b")]) == 2
    line = _one_line(capsys)
    assert line.startswith("truestep: error: --sizes: 1e+12 particles is over the 1e+06")
    assert "particle-rain.toml" not in line and not (tmp_path / "b").exists()


def test_a_case_run_under_a_raised_limit_is_gated_under_it(tmp_path, capsys, monkeypatch):
    """A case over the default steps limit, run with ``--limit``: ``gate`` refuses it
    without the limit in one line that says how to raise it, and gates it with
    ``--limit`` as ``run`` took it."""
    from truestep.cases.loader import CASE_DIR

    text = (CASE_DIR / "free-fall.toml").read_text()
    assert "dt = [0.1, 0.05, 0.02, 0.01]\n" in text
    (tmp_path / "big.toml").write_text(
        text.replace("dt = [0.1, 0.05, 0.02, 0.01]\n", "dt = [0.1, 0.05, 0.02, 0.01, 1e-8]\n", 1)
    )
    monkeypatch.chdir(tmp_path)
    run = ["run", "--quick", "--engines", "reference", "--cases", "big.toml", "--out", "rep"]
    assert main(run) == 2 and "--limit steps=N" in _one_line(capsys)
    assert main([*run, "--limit", "steps=2e8"]) == 0
    capsys.readouterr()
    assert main(["gate", "--results", "rep/results.csv", "-q"]) == 2
    assert "big.toml" in _one_line(capsys)
    assert main(["gate", "--results", "rep/results.csv", "-q", "--limit", "steps=2e8"]) == 0
