"""A sweep's measured runs and its timed runs in two processes give the rows one process
gives (runner.split_sweep, runner.joined, timing.merged): only the timing columns may move."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from truestep.adapters.base import Trajectory
from truestep.execution import runner
from truestep.execution.timing import NOT_REPEATABLE, End, TimedRuns, Timing, end_of, merged
from truestep.runtime.isolation import Outcome

SHORT = Timing(min_total_s=0.0, min_repeats=1, max_repeats=2, long_run_s=float("inf"))
"""Two timed runs a row, however long it takes (no verdict on the clock)."""


def _key(frame: pd.DataFrame) -> pd.DataFrame:
    keep = [c for c in frame.columns if c not in runner.MACHINE_COLUMNS]
    return frame[keep].sort_values(["engine", "method", "dt"]).reset_index(drop=True)


def test_rows_apart_are_the_rows_together(case_named):
    """reference, scipy and Drake (all three watch every step) on the harmonic oscillator:
    every non-timing cell is the same, bit for bit, with the measured runs apart or not (over
    1 s of the case: what is checked is how the rows are made, not the motion). Drake's
    watch is light: its sweeps are never split (tests/execution/test_timed_from_watched.py)."""
    case = dataclasses.replace(case_named("harmonic-oscillator"), duration=1.0)
    engines = ["reference", "scipy", "drake"]
    assert runner.split_sweep("reference", SHORT) and runner.split_sweep("scipy", SHORT)
    assert not runner.split_sweep("drake", SHORT)
    apart = runner.run_matrix([case], engines, quick=True, timing=SHORT, progress=lambda _: None)
    together_timing = Timing(**{**SHORT.__dict__, "apart": False})
    assert not runner.split_sweep("reference", together_timing)
    together = runner.run_matrix([case], engines, quick=True, timing=together_timing, progress=lambda _: None)
    pd.testing.assert_frame_equal(_key(apart), _key(together))
    ran = apart[apart.status == "ok"]
    assert len(ran) > 10 and (ran.repeats == 2).all() and (ran.wall_s > 0).all()


def _traj(x_end: float, status: str = "ok") -> Trajectory:
    t = np.array([0.0, 1.0])
    x = np.array([[[0.0, 0.0, 0.0]], [[x_end, 0.0, 0.0]]])
    v = np.zeros((2, 1, 3))
    return Trajectory(t=t, x=x, v=v, energy=None, status=status, wall_s=9.0, nfev=2, steps=1)


def test_the_row_takes_the_timed_runs_median_and_says_when_they_ended_elsewhere():
    same = merged(_traj(1.0), TimedRuns([0.3, 0.1, 0.2], [end_of(_traj(1.0))] * 3))
    assert same.wall_s == 0.2 and int(same.extra["repeats"]) == 3 and NOT_REPEATABLE not in same.message
    moved = merged(_traj(1.0), TimedRuns([0.1, 0.1], [end_of(_traj(1.0)), end_of(_traj(1.0 + 1e-15))]))
    assert NOT_REPEATABLE in moved.message
    failed_alike = End("unstable", (1, 1), ())
    assert NOT_REPEATABLE not in merged(_traj(1.0, "unstable"), TimedRuns([0.1], [failed_alike])).message


def test_a_failure_of_either_half_is_the_row():
    """A step whose measured run raised is that error; one whose timed runs ran out of time
    is that timeout; a half whose process died makes the whole sweep run again step by step."""
    runs = TimedRuns([0.1], [end_of(_traj(1.0))])
    timeout = Outcome("timeout", message="the run at 0.01 ran past 5 s")
    measured = Outcome("ok", [_traj(1.0), "ValueError: no such step", _traj(1.0)])
    timed = Outcome("ok", [runs, runs, timeout])
    steps = runner.joined(measured, timed).value
    assert isinstance(steps[0], Trajectory) and steps[0].wall_s == 0.1
    assert steps[1] == "ValueError: no such step" and steps[2] is timeout
    died = Outcome("crashed", message="engine process died (exit code 9)")
    assert runner.joined(measured, died) is died and runner.joined(died, timed) is died
