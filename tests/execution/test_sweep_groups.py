"""A built-in engine's sweeps of one case share one process (runner._LocalSweeps,
sweep_groups.group_sweeps), and give the rows each sweep gives in a process of its own:
only the timing columns may move. A group whose process dies, or one of whose sweeps says
a run crashed, has those sweeps made again alone."""

from __future__ import annotations

import dataclasses
import os

import pandas as pd
import pytest

from truestep.execution import runner
from truestep.execution.sweep_groups import GROUP_BYTES, group_sweeps, weight
from truestep.execution.timing import Timing

SHORT = Timing(min_total_s=0.0, min_repeats=1, max_repeats=2, long_run_s=float("inf"))
"""Two timed runs a row, however long it takes (no verdict on the clock)."""
ENGINES = ["reference", "scipy"]


def test_sweeps_of_one_key_share_a_group_within_the_cap_in_the_order_planned():
    keys = ["a", "a", None, "b", "a", "a", None]
    runs = [10, 10, 5, 30, 4, 1, 2]
    shares = [weight(n, 1e3) for n in runs]
    assert group_sweeps(keys, shares) == [[0, 1, 4], [2], [3], [5], [6]]
    assert group_sweeps(["a", "a"], [0.6, 0.6]) == [[0], [1]]
    assert group_sweeps([], []) == []


def test_a_group_holds_at_most_its_bytes_of_records():
    """particle-rain's runs (1000 particles, 1002 records: 48 MB each): two sweeps of two
    steps a group, where 24 runs of a small scene share one."""
    rain = weight(2, 1000 * 1002 * 48.0)
    assert 0.5 > rain > 0.3 and group_sweeps(["r"] * 3, [rain] * 3) == [[0, 1], [2]]
    assert weight(24, 1e3) == 1.0 and weight(2, GROUP_BYTES) == 2.0


def _key(frame: pd.DataFrame) -> pd.DataFrame:
    keep = [c for c in frame.columns if c not in runner.MACHINE_COLUMNS]
    return frame[keep].sort_values(["engine", "method", "dt"]).reset_index(drop=True)


@pytest.fixture(scope="module")
def alone(case_named):
    """The rows with every sweep in a process of its own, over 1 s of the oscillator."""
    case = dataclasses.replace(case_named("harmonic-oscillator"), duration=1.0)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(runner, "group_sweeps", lambda keys, rows: [[i] for i in range(len(keys))])
        table = runner.run_matrix([case], ENGINES, quick=True, timing=SHORT, progress=lambda _: None)
    return case, _key(table)


def _calls_logged(monkeypatch, tmp_path, change=None):
    """Wrap the grouped call: each child appends the number of sweeps it ran to a file
    (and ``change`` may alter what it hands back); returns the file."""
    log = tmp_path / "calls"
    real = runner.simulate_sweeps

    def logged(sweeps):
        with open(log, "a") as f:
            f.write(f"{len(sweeps)}\n")
        got = real(sweeps)
        return change(got) if change else got

    monkeypatch.setattr(runner, "simulate_sweeps", logged)
    return log


def test_a_built_in_engine_s_sweeps_of_a_case_share_a_process_and_give_the_same_rows(
    alone, monkeypatch, tmp_path
):
    case, rows_alone = alone
    log = _calls_logged(monkeypatch, tmp_path)
    table = runner.run_matrix([case], ENGINES, quick=True, timing=SHORT, progress=lambda _: None)
    spent = table.attrs["sweep_seconds"]
    pd.testing.assert_frame_equal(_key(table), rows_alone)
    sizes = [int(n) for n in log.read_text().split()]
    methods = rows_alone.groupby("engine").method.nunique()
    # the reference's measured halves, its timed halves, scipy's likewise: at most a few processes
    assert len(sizes) >= 2 and max(sizes) > 1 and sum(sizes) >= methods.sum()
    assert spent["sweep reference"] > 0 and spent["sweep scipy"] > 0


def test_a_group_whose_process_dies_has_each_sweep_made_again_alone(alone, monkeypatch):
    case, rows_alone = alone
    monkeypatch.setattr(runner, "simulate_sweeps", lambda sweeps: os._exit(9))
    table = runner.run_matrix([case], ENGINES, quick=True, timing=SHORT, progress=lambda _: None)
    pd.testing.assert_frame_equal(_key(table), rows_alone)


def test_a_sweep_of_a_group_that_says_a_run_crashed_is_made_again_alone(alone, monkeypatch, tmp_path):
    """Its rows are then those it gives alone (a crashed row's message carries its own
    process's output, not its group's)."""
    case, rows_alone = alone

    def first_run_crashed(got):
        got[0][0] = "RuntimeError: made up for the test"
        return got

    log = _calls_logged(monkeypatch, tmp_path, first_run_crashed)
    table = runner.run_matrix([case], ENGINES, quick=True, timing=SHORT, progress=lambda _: None)
    assert log.exists()
    pd.testing.assert_frame_equal(_key(table), rows_alone)
    assert "made up" not in " ".join(table.message.fillna(""))
