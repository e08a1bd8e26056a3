"""What an adapter returns is checked before it is measured: a breach is that row's
``crashed``, a non-finite state under ``ok`` is ``unstable`` at its time."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from truestep.adapters import get_adapter
from truestep.execution.runner import row_from


@pytest.fixture(scope="module")
def good(case_named):
    case = case_named("bouncing-ball")
    return case, get_adapter("reference").simulate(case, "rk4", case.dts[0])


def _row(case, traj):
    return row_from(case, "bad", "m", case.dts[0], adaptive=False, outcome=traj)


def test_a_good_trajectory_is_measured(good):
    case, traj = good
    row = _row(case, dataclasses.replace(traj))
    assert row["status"] == "ok" and np.isfinite(row["error"])


@pytest.mark.parametrize(
    "change",
    [
        {"status": "splendid"},
        {"x": "not an array"},
        {"x": np.zeros((3, 1, 3))},  # records that do not match t
        {"x": np.zeros((626, 2, 3))},  # the wrong number of particles
        {"energy": np.zeros(5)},
        {"t": np.zeros((2, 2))},
    ],
)
def test_a_breach_of_the_contract_is_that_row_crashed(good, change):
    case, traj = good
    row = _row(case, dataclasses.replace(traj, **change))
    assert row["status"] == "crashed" and row["message"].startswith("adapter returned")
    assert len(row["message"]) < 200


def test_complex_positions_are_a_crashed_row_not_ok(good):
    """Issue 37, item 10: complex positions were cast to their real part and measured
    (``ok``); the imaginary part is a breach, whatever its size."""
    case, traj = good
    for name in ("x", "v"):
        row = _row(case, dataclasses.replace(traj, **{name: getattr(traj, name) + 1e-30j}))
        assert row["status"] == "crashed" and f"complex {name}" in row["message"]


def test_one_record_is_not_ok(good):
    case, traj = good
    one = dataclasses.replace(
        traj,
        t=traj.t[:1],
        x=traj.x[:1],
        v=traj.v[:1],
        energy=None if traj.energy is None else traj.energy[:1],
    )
    assert _row(case, one)["status"] == "crashed"


def test_a_non_finite_state_is_unstable_at_its_time_whatever_the_adapter_said(good):
    case, traj = good
    x = traj.x.copy()
    x[400:, 0, 1] = np.nan
    row = _row(case, dataclasses.replace(traj, x=x, status="ok"))
    assert row["status"] == "unstable" and row["t_fail"] == traj.t[400]


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        (lambda t: {"t": t.t - 10.0}, "not from the case's start"),
        (lambda t: {"t": np.zeros_like(t.t)}, "do not increase"),
        (lambda t: {"t": t.t[::-1].copy()}, "not from the case's start"),
        (lambda t: {"t": t.t * 1e6}, "past the case's"),
        (lambda t: {"wall_s": -5.0}, "wall time of -5 s"),
        (lambda t: {"wall_s": float("nan")}, "wall time of nan"),
        (lambda t: {"wall_s": float("inf")}, "wall time of inf"),
        (lambda t: {"wall_s": 0.0}, "wall time of 0"),
        (lambda t: {"nfev": -3}, "nfev = -3"),
    ],
)
def test_clocks_that_do_not_start_at_the_start_and_advance_are_crashed_rows(good, change, reason):
    case, traj = good
    row = _row(case, dataclasses.replace(traj, **change(traj)))
    assert row["status"] == "crashed" and reason in row["message"], row["message"]


@pytest.fixture(scope="module")
def ode_run(case_named):
    case = case_named("circle-field")
    return case, get_adapter("reference").simulate(case, "rk4", case.dts[-1])


def test_an_ode_run_in_the_layout_before_y_is_measured_the_same_with_a_warning(ode_run):
    """An adapter written before ``Trajectory.y`` returns an ODE's states as ``x`` (T, 1,
    dim): its row is the one the new layout gives, and it is told where states belong."""
    case, traj = ode_run
    new = _row(case, dataclasses.replace(traj))
    with pytest.warns(DeprecationWarning, match="Trajectory.of_ode"):
        old = _row(case, dataclasses.replace(traj, x=traj.y[:, None, :].copy(), y=None))
    assert new["status"] == old["status"] == "ok"
    assert new["error"] == old["error"] and np.isfinite(new["error"])


@pytest.mark.parametrize("y", [np.zeros((3, 2)), np.zeros((2,)), np.zeros((1, 1, 1, 1))])
def test_ode_states_of_the_wrong_shape_are_a_crashed_row(ode_run, y):
    case, traj = ode_run
    row = _row(case, dataclasses.replace(traj, y=y))
    assert row["status"] == "crashed" and row["message"].startswith("adapter returned y of shape")
