"""One stability search for two methods that step a scene bit for bit alike (Adapter
protocol item 12): MuJoCo's ``implicitfast`` without a velocity-dependent force is its
``Euler``. The rule is checked on the engines themselves, on every case of the repository
it covers, and the table's shared row against its twin's."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from truestep.adapters import get_adapter
from truestep.adapters.mujoco_adapter import same_steps
from truestep.cases.loader import CASE_DIR, load_case
from truestep.execution import analyses
from truestep.execution.runner import left_out

pytestmark = pytest.mark.engine

CASES = [load_case(p) for p in sorted(CASE_DIR.glob("*.toml"))]
COVERED = [c for c in CASES if same_steps(c, "implicitfast") is not None]


def test_the_rule_covers_the_undamped_scenes_and_no_other():
    names = {c.name for c in COVERED}
    assert {"harmonic-oscillator", "rope-pendulum", "spring-chain", "stiff-spring"} <= names
    assert not names & {"damped-oscillator", "hanging-cloth", "stiff-cloth", "bouncing-ball"}
    assert all(same_steps(c, m) is None for c in CASES for m in ("Euler", "implicit", "RK4"))


@pytest.mark.parametrize("engine", ["mujoco", "mujoco-warp"])
@pytest.mark.parametrize("case", COVERED, ids=lambda c: c.name)
def test_implicitfast_steps_as_euler_does_where_the_rule_says_so(engine, case):
    """Both methods from the same start, at two steps, every step recorded: the same
    positions and velocities bit for bit (the engine's own answer, not the rule's)."""
    adapter = get_adapter(engine)
    if adapter.missing(case, "Euler") or left_out(adapter, case, "Euler"):
        pytest.skip("the engine does not run this case")
    assert adapter.same_steps(case, "implicitfast")[0] == "Euler"
    for dt in (case.stability.dt_lo * 3, case.stability.dt_hi / 3) if case.stability else (0.01,):
        short = dataclasses.replace(case, duration=min(case.duration, 300 * dt), max_records=300)
        a, b = adapter.simulate(short, "Euler", dt), adapter.simulate(short, "implicitfast", dt)
        assert a.status == b.status and a.steps == b.steps
        assert np.array_equal(a.x, b.x, equal_nan=True) and np.array_equal(a.v, b.v, equal_nan=True), dt


def test_the_shared_row_is_its_twins_search_and_says_so(monkeypatch):
    """The table searches Euler once and gives implicitfast its result; a damped scene's
    implicitfast keeps its own search."""
    calls = []

    def run_in_process(todo, workers, done):
        from truestep.runtime.isolation import Outcome

        for k, (fn, args, _timeout) in enumerate(todo):
            calls.append(args[:3])
            done(k, Outcome("ok", fn(*args)))

    cases = []
    for name in ("harmonic-oscillator", "damped-oscillator"):
        case = load_case(CASE_DIR / f"{name}.toml")
        cases.append(dataclasses.replace(case, stability=dataclasses.replace(case.stability, quick=True)))
    monkeypatch.setattr(analyses, "run_untimed", run_in_process)
    table = analyses.stability_table(cases, ["mujoco"], quick=True, workers=1)
    rows = {(r.case, r.method): r for r in table.itertuples()}
    searched = {(c.name, m) for _e, c, m in calls}
    assert ("harmonic-oscillator", "implicitfast") not in searched
    assert ("damped-oscillator", "implicitfast") in searched
    euler, fast = rows[("harmonic-oscillator", "Euler")], rows[("harmonic-oscillator", "implicitfast")]
    assert (fast.dt_limit, fast.dt_unstable, fast.runs, fast.status) == (
        euler.dt_limit,
        euler.dt_unstable,
        euler.runs,
        euler.status,
    )
    assert fast.note.startswith("the same steps as Euler's, bit for bit (no velocity-dependent force")
    assert not str(rows[("damped-oscillator", "implicitfast")].note).startswith("the same steps")
