"""An isolated child's result crosses back as data (issue 37, item 4): an object in it that
would run code while truestep reads it (``os._exit``, a sleep, a file written) is refused,
and its row says which name it used; truestep's own records and arrays come back whole."""

from __future__ import annotations

import dataclasses
import os
import pickle
import time
from pathlib import Path

import numpy as np
import pytest

from truestep.adapters.base import Trajectory
from truestep.adapters.reference import ReferenceAdapter
from truestep.execution.timing import TimedRuns
from truestep.runtime import plain_data
from truestep.runtime.isolation import run_isolated


class ExitsWhenRead:
    """Unpickled, it ends the reading process at once. The attack used status 0 (``truestep
    run`` then exits 0 with no report); 97 here, so that a regression fails the suite instead
    of ending it quietly."""

    def __reduce__(self):
        return (os._exit, (97,))


class SleepsWhenRead:
    def __reduce__(self):
        return (time.sleep, (600,))


class WritesWhenRead:
    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):
        return (Path.write_text, (Path(self.path), "written by a result"))


def _returns(value):
    return value


@pytest.mark.parametrize(
    "hostile, name",
    [
        (ExitsWhenRead(), "posix._exit"),
        (SleepsWhenRead(), "time.sleep"),
        ([1.0, {"extra": ExitsWhenRead()}], "posix._exit"),
        (np.array([ExitsWhenRead()], dtype=object), "posix._exit"),
    ],
)
def test_a_result_that_runs_code_when_read_is_a_crashed_outcome_naming_it(hostile, name):
    began = time.monotonic()
    out = run_isolated(_returns, (hostile,), 30.0)
    assert out.status == "crashed" and name in out.message, out
    assert "does not build" in out.message
    assert time.monotonic() - began < 20  # the sleep never ran


def test_a_refused_result_writes_nothing(tmp_path):
    target = tmp_path / "victim.txt"
    out = run_isolated(_returns, (WritesWhenRead(str(target)),), 30.0)
    assert out.status == "crashed" and "write_text" in out.message
    assert not target.exists()


def test_truestep_s_records_and_arrays_come_back_whole():
    traj = Trajectory(
        t=np.linspace(0, 1, 5),
        x=np.random.default_rng(1).normal(size=(5, 2, 3)),
        v=None,
        energy=None,
        status="ok",
        extra={"repeats": 3, "alive": np.ones((5, 2), bool), "z": 1 + 2j, "n": np.int64(7)},
    )
    back = run_isolated(_returns, ((traj, TimedRuns([0.1, 0.2], []), "text", {1, 2}),), 30.0)
    assert back.status == "ok", back.message
    got, timed, text, numbers = back.value
    assert np.array_equal(got.x, traj.x) and got.extra["z"] == 1 + 2j and got.extra["n"] == 7
    assert np.array_equal(got.extra["alive"], traj.extra["alive"])
    assert timed == TimedRuns([0.1, 0.2], []) and text == "text" and numbers == {1, 2}


def test_only_truestep_s_dataclasses_are_built_not_its_functions():
    with pytest.raises(plain_data.Refused, match=r"truestep\.runtime\.process_tree\.kill_tree"):
        plain_data.loads(pickle.dumps(_Named("truestep.runtime.process_tree", "kill_tree", (os.getpid(),))))
    assert dataclasses.is_dataclass(plain_data.loads(pickle.dumps(TimedRuns([1.0], []))))


def test_truestep_s_enumeration_members_come_back_by_value():
    """An adapter's ``missing()`` answers with :class:`~truestep.Feature` members, asked in a
    forked process when the adapter is a plugin's: they come back as the same members."""
    from truestep.reference_impl.features import Feature

    asked = {Feature.POINT_MASSES, Feature.ODE}
    back = plain_data.loads(pickle.dumps(asked))
    assert back == asked and all(type(f) is Feature for f in back)


class _Named:
    """Pickles as a call of ``module.name(*args)``."""

    def __init__(self, module: str, name: str, args: tuple) -> None:
        self.module, self.name, self.args = module, name, args

    def __reduce__(self):
        import importlib

        return (getattr(importlib.import_module(self.module), self.name), self.args)


class Hostile(ReferenceAdapter):
    """The reference, whose rows at the finest quick step carry an object that ends the
    reading process when unpickled."""

    name = "hostile-result-test"
    methods = ("rk4",)
    adaptive_methods = ()

    def simulate(self, case, method, dt, *, monitor=False):
        traj = super().simulate(case, method, dt, monitor=monitor)
        if dt == min(case.quick_dts):
            traj.extra["gift"] = ExitsWhenRead()
        return traj


def test_a_run_whose_adapter_returns_such_an_object_goes_on_and_says_so(tmp_path):
    from truestep.adapters import resolve_engine
    from truestep.cases import load_cases
    from truestep.execution.runner import Timing, run_sweep

    resolve_engine("test_result_as_data:Hostile")
    case = load_cases("free-fall")[0]
    rows = run_sweep(
        case, "hostile-result-test", "rk4", case.quick_dts, adaptive=False, timing=Timing(max_repeats=1)
    )
    assert {r["status"] for r in rows} <= {"ok", "crashed"} and rows[-1]["status"] == "crashed"
    assert "posix._exit" in rows[-1]["message"]
    assert all(r["status"] == "ok" for r in rows[:-1])


def test_complex_positions_read_back_are_a_crashed_row_not_their_real_part():
    """An adapter whose ``read()`` returns complex numbers: a cast to float would keep the
    real part without a word and the rows would read ``ok``; the run is refused instead."""
    from truestep.adapters.base import _real

    assert _real(np.ones(3), "positions").dtype == np.float64
    with pytest.raises(TypeError, match="complex positions"):
        _real(np.ones(3) + 1e-3j, "positions")
