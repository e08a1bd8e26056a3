"""A long row of long steps of an engine whose watch is light is timed from its watched run
(timing.light_watch, timing.timed_from_watched): one stepping instead of two, the same
numbers. The thresholds are set here (no verdict on the clock): what is checked is which
runs are made and that the row is the row the two runs give."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from truestep.adapters.base import COPY_HIDDEN_STEP_S
from truestep.adapters.drake_adapter import DrakeAdapter
from truestep.adapters.reference import ReferenceAdapter
from truestep.execution import runner, timing
from truestep.execution.timing import Timing, light_watch, measured_run, merged, simulate_timed, timed_runs
from truestep.reporting.sections import methods_section

pytestmark = pytest.mark.engine

LONG = Timing(min_total_s=0.0, min_repeats=2, max_repeats=2, long_run_s=0.0)
"""Every run counts as long (timed once) unless the step rule says otherwise."""


def _every_step(step_s: float) -> dict[str, float]:
    """Drake's ``watched_step_s`` set to ``step_s`` for every method."""
    return dict.fromkeys(DrakeAdapter.methods, step_s)


def _spied(monkeypatch, cls) -> list[bool]:
    """Each run of adapter class ``cls`` made from now on, as its ``monitor`` flag."""
    made: list[bool] = []
    plain = cls.simulate

    def spy(self, case, method, dt, *, monitor=False):
        made.append(monitor)
        return plain(self, case, method, dt, monitor=monitor)

    monkeypatch.setattr(cls, "simulate", spy)
    return made


@pytest.fixture
def runs(monkeypatch) -> list[bool]:
    """Each Drake run made, as its ``monitor`` flag."""
    return _spied(monkeypatch, DrakeAdapter)


def _same_numbers(a, b) -> None:
    assert a.status == b.status and (a.nfev, a.steps) == (b.nfev, b.steps)
    for name in ("t", "x", "v", "energy", "step_t", "step_energy"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.extremes == b.extremes


def test_drake_says_its_watch_is_light_and_its_sweeps_are_not_split():
    assert light_watch(DrakeAdapter())
    assert not runner.split_sweep("drake", Timing())
    assert runner.split_sweep("reference", Timing())  # its watch is not light for every method


def test_the_reference_says_its_watch_is_light_for_its_numpy_path_methods_alone():
    """Implicit Euler and Dormand-Prince step on the numpy path (a Python call a step): their
    sweeps run whole, timed from a long watched run; the compiled methods' sweeps stay
    split, their measured runs on the untimed cores."""
    reference = ReferenceAdapter()
    assert not light_watch(reference)
    for method in ("implicit-euler", "dopri5"):
        assert light_watch(reference, method) and not runner.split_sweep("reference", Timing(), method)
    for method in ("rk4", "lecture", "verlet"):
        assert not light_watch(reference, method) and runner.split_sweep("reference", Timing(), method)


def test_each_engine_s_watched_step_is_the_one_the_report_states():
    """The report's methods section names these thresholds without importing an engine:
    a state copy's (COPY_HIDDEN_STEP_S) for fixed steps, none where the plain run keeps
    every step too; a plugin that says nothing keeps the millisecond."""
    reference, drake = ReferenceAdapter(), DrakeAdapter()
    assert timing.watched_step_s(reference, "implicit-euler") == COPY_HIDDEN_STEP_S
    assert timing.watched_step_s(reference, "dopri5") == 0.0
    for method in drake.methods:
        said = timing.watched_step_s(drake, method)
        assert said == (0.0 if method in drake.adaptive_methods else COPY_HIDDEN_STEP_S), method
    assert timing.watched_step_s(object(), "any") == timing.WATCHED_STEP_S
    text = methods_section([])[1]
    assert f"at steps of {1000 * COPY_HIDDEN_STEP_S:g} ms or more" in text


@pytest.mark.parametrize(
    ("name", "method", "dt"),
    [
        ("earth-orbit", "bogacki_shampine3", 1e-5),
        ("stiff-spring", "radau3-ec", 1e-6),
        ("kepler-orbit", "runge_kutta5", 1e-7),
    ],
)
def test_drake_s_error_controlled_watched_run_is_its_plain_run(case_named, name, method, dt):
    """An error-controlled Drake run keeps every step its monitor sees, watched or not: the
    same steps, evaluations and end, bit for bit."""
    drake = DrakeAdapter()
    watched = drake.simulate(case_named(name), method, dt, monitor=True)
    plain = drake.simulate(case_named(name), method, dt)
    assert watched.status == plain.status == "ok"
    assert (watched.nfev, watched.steps) == (plain.nfev, plain.steps)
    np.testing.assert_array_equal(watched.x[-1], plain.x[-1])
    np.testing.assert_array_equal(watched.t, plain.t)


@pytest.mark.parametrize(
    ("name", "method", "dt"),
    [
        ("stiff-cloth", "implicit-euler", 0.004),
        ("mass-ratio-chain", "implicit-euler", 0.01),
        ("bouncing-ball", "dopri5", 1e-6),
        ("kepler-orbit", "dopri5", 1e-7),
    ],
)
def test_the_reference_s_watched_run_steps_as_its_plain_run(case_named, name, method, dt):
    """What the light watch promises, held: the watched run makes the plain run's steps and
    evaluations and ends in its state, bit for bit; it only keeps more of them (every step
    of a fixed-step run; Dormand-Prince keeps every accepted step in both)."""
    case = case_named(name)
    reference = ReferenceAdapter()
    watched = reference.simulate(case, method, dt, monitor=True)
    plain = reference.simulate(case, method, dt)
    assert watched.status == plain.status == "ok"
    assert (watched.nfev, watched.steps) == (plain.nfev, plain.steps)
    assert (watched.v is None) == (plain.v is None)
    for name_ in ("t", "x") if plain.v is None else ("t", "x", "v"):
        np.testing.assert_array_equal(getattr(watched, name_)[-1], getattr(plain, name_)[-1], err_msg=name_)
    assert watched.extremes is not None


def test_a_long_reference_row_of_long_steps_is_its_watched_run_timed_once(case_named, monkeypatch):
    """The row timed from its watched run is the row the watched run and a plain timed run
    give apart; steps shorter than the reference's threshold are timed by a plain run."""
    made = _spied(monkeypatch, ReferenceAdapter)
    case = case_named("mass-ratio-chain")
    monkeypatch.setattr(ReferenceAdapter, "watched_step_s", {"implicit-euler": 1e-12})
    row = simulate_timed("reference", case, "implicit-euler", 0.01, LONG, warm_up=False)
    assert made == [True] and int(row.extra["repeats"]) == 1
    apart = merged(
        measured_run(ReferenceAdapter(), case, "implicit-euler", 0.01),
        timed_runs(ReferenceAdapter(), case, "implicit-euler", 0.01, LONG, warm_up=False, lean=True)[1],
    )
    _same_numbers(row, apart)
    made.clear()
    monkeypatch.setattr(ReferenceAdapter, "watched_step_s", {"implicit-euler": float("inf")})
    simulate_timed("reference", case, "implicit-euler", 0.01, LONG, warm_up=False)
    assert made == [True, False]


def test_a_long_row_of_long_steps_is_its_watched_run_timed_once(case_named, monkeypatch, runs):
    monkeypatch.setattr(DrakeAdapter, "watched_step_s", _every_step(1e-12))
    case = dataclasses.replace(case_named("harmonic-oscillator"), duration=1.0)
    row = simulate_timed("drake", case, "runge_kutta2", 0.01, LONG, warm_up=False)
    assert runs == [True]
    assert int(row.extra["repeats"]) == 1 and row.wall_s > 0
    apart = merged(
        measured_run(DrakeAdapter(), case, "runge_kutta2", 0.01),
        timed_runs(DrakeAdapter(), case, "runge_kutta2", 0.01, LONG, warm_up=False, lean=True)[1],
    )
    _same_numbers(row, apart)


def test_the_first_row_of_a_process_is_warmed_up_first(case_named, monkeypatch, runs):
    monkeypatch.setattr(DrakeAdapter, "watched_step_s", _every_step(1e-12))
    case = dataclasses.replace(case_named("harmonic-oscillator"), duration=1.0)
    simulate_timed("drake", case, "runge_kutta2", 0.01, LONG, warm_up=True)
    assert runs == [False, True]


def test_short_steps_are_timed_by_plain_runs_after_the_watched_one(case_named, monkeypatch, runs):
    """Steps shorter than the watched step (here every step): the watched run warms the
    process up, and plain runs are timed, each checked to end where it did."""
    monkeypatch.setattr(DrakeAdapter, "watched_step_s", _every_step(float("inf")))
    case = dataclasses.replace(case_named("harmonic-oscillator"), duration=1.0)
    row = simulate_timed("drake", case, "runge_kutta2", 0.01, LONG, warm_up=True)
    assert runs == [False, True, False]  # the warm-up, the watched run, the timed run
    assert int(row.extra["repeats"]) == 1 and timing.NOT_REPEATABLE not in row.message


def test_a_row_that_did_not_end_ok_is_timed_as_any_row(case_named, monkeypatch, runs):
    """An explicit Euler run far past its limit blows up: its time to the blow-up is not a
    long row's, and a plain run is timed after it, as for every engine."""
    monkeypatch.setattr(DrakeAdapter, "watched_step_s", _every_step(1e-12))
    case = dataclasses.replace(case_named("harmonic-oscillator"), duration=50.0)
    row = simulate_timed("drake", case, "explicit_euler", 0.5, LONG, warm_up=False)
    assert row.status == "unstable"
    assert runs == [True, False]


def test_a_long_error_controlled_row_that_failed_is_its_watched_run_timed_once(case_named, monkeypatch, runs):
    """Drake's error-controlled run keeps every step watched or not (its watched step is 0):
    a run stopped by truestep's bound on work stops at the same step either way, so a long
    one is timed from its watched run, where a fixed-step method's failed row is timed by
    a plain run (the test above)."""
    from truestep.adapters import drake_adapter

    monkeypatch.setattr(drake_adapter, "MAX_EVALUATIONS", 2000)
    case = case_named("earth-orbit")
    watched = DrakeAdapter().simulate(case, "bogacki_shampine3", 1e-8, monitor=True)
    plain = DrakeAdapter().simulate(case, "bogacki_shampine3", 1e-8)
    assert watched.status == plain.status == "solver-failed"
    assert (watched.t_fail, watched.nfev, watched.steps) == (plain.t_fail, plain.nfev, plain.steps)
    runs.clear()
    row = simulate_timed("drake", case, "bogacki_shampine3", 1e-8, LONG, warm_up=False)
    assert row.status == "solver-failed" and runs == [True] and int(row.extra["repeats"]) == 1
