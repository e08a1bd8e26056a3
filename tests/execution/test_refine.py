"""Sweeps carried on to finer steps where a method's declared order is not reached yet
(issue 35, item 8): a correct method whose case sweep is pre-asymptotic is judged where
it converges, and passes its declared-order gate; a wrong one still fails there, and so
does one whose error is flat (it converges to the wrong motion), in a ``--quick`` run too."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from truestep.adapters.reference import ReferenceAdapter
from truestep.api import run
from truestep.cli import main
from truestep.execution.refine import MAX_HALVINGS, short_of_order

OFFSET = 0.02
"""A constant error added to positions (m): it hides a first-order error at coarse steps."""


class LateEuler(ReferenceAdapter):
    """The reference's explicit Euler, with an error that is there only at the case's own
    steps (>= 0.5 ms) and gone at finer ones: a correct method, pre-asymptotic on the
    sweep (as Drake's third-order methods are on arenstorf-orbit)."""

    name = "late-euler-test"
    methods = ("euler",)
    adaptive_methods = ()

    def simulate(self, case, method, dt, **kw):
        traj = super().simulate(case, method, dt, **kw)
        if dt >= 4.9e-4:  # an error term of order 1/2 there (the sweep fits 0.73, short of 1)
            drift = OFFSET * np.sqrt(dt / 2e-3)
            traj.x = traj.x + drift * np.linspace(0.0, 1.0, len(traj.t))[:, None, None]
        return traj


class HalfMidpoint(ReferenceAdapter):
    """Explicit Euler under the midpoint's name (declared second order): a method that
    converges, at first order, and never reaches its declared one."""

    name = "half-midpoint-test"
    methods = ("midpoint",)
    adaptive_methods = ()

    def simulate(self, case, method, dt, **kw):
        return super().simulate(case, "euler", dt, **kw)


class Misplaced(ReferenceAdapter):
    """The reference's velocity Verlet with every position :data:`OFFSET` off: a method that
    converges, to the wrong motion (as a spring's rest length 1 % off moves its
    equilibrium), so that its error is flat at every step, far above round-off."""

    name = "misplaced-test"
    methods = ("verlet",)
    adaptive_methods = ()

    def simulate(self, case, method, dt, **kw):
        traj = super().simulate(case, method, dt, **kw)
        traj.x = traj.x + OFFSET
        return traj


def _run(tmp_path, engine: str, *quick: str) -> tuple[pd.DataFrame, dict, int]:
    """The sweep of harmonic-oscillator (the refinement runs after it, with or without the
    analyses, which the declared-order gate does not read), published, and that gate."""
    out = tmp_path / engine.split(":")[1]
    run("harmonic-oscillator", engine, quick=bool(quick), analyses=False, out=out, progress=lambda line: None)
    gate = main(["gate", "--results", str(out / "results.csv"), "--declared-orders", "-q"])
    return pd.read_csv(out / "results.csv"), json.loads((out / "run.json").read_text()), gate


def test_a_pre_asymptotic_sweep_is_carried_on_and_a_correct_method_passes(tmp_path, capsys):
    results, record, gate = _run(tmp_path, "test_refine:LateEuler")
    rows = results[(results.engine == "late-euler-test") & (results.dt_kind == "step")]
    (refined,) = record["refined"]
    assert refined["method"] == "euler" and refined["declared"] == 1.0 and refined["order"] < 0.75
    added = refined["dts"]
    assert 1 <= len(added) <= MAX_HALVINGS and added == [5e-4 / 2**k for k in range(1, len(added) + 1)]
    assert list(rows.dt) == [2e-3, 1e-3, 5e-4, *added]  # the sweep, then the halvings, in its rows
    assert gate == 0, capsys.readouterr().out


def test_a_method_that_never_reaches_its_order_still_fails(tmp_path, capsys):
    results, record, gate = _run(tmp_path, "test_refine:HalfMidpoint")
    (refined,) = record["refined"]  # one halving shows the order flat at 1: no more are run
    assert refined["dts"] == [2.5e-4] and len(results[results.engine == "half-midpoint-test"]) == 4
    assert gate == 1
    out = capsys.readouterr().out
    assert "FAIL harmonic-oscillator/order/half-midpoint-test/midpoint/declared" in out
    assert "measured order 1.0" in out


def test_only_methods_short_of_their_order_with_every_row_ok_are_carried_on(case_named):
    case = case_named("harmonic-oscillator")
    dts = [2e-3, 1e-3, 5e-4]

    def rows(method: str, errors: list[float], status: str = "ok") -> list[dict]:
        return [
            {
                "case": case.name,
                "engine": "reference",
                "method": method,
                "dt": d,
                "dt_kind": "step",
                "status": status,
                "error": e,
            }
            for d, e in zip(dts, errors, strict=True)
        ]

    table = pd.DataFrame(
        rows("euler", [4e-3, 2e-3, 1e-3])  # at its order: left alone
        + rows("midpoint", [1.6e-3, 8e-4, 4e-4])  # first order, short of 2: carried on
        + rows("rk4", [1e-3, 9e-4, 8e-4])  # not falling, far above round-off: carried on
        + rows("verlet", [5e-11, 5e-11, 5e-11])  # flat, but within 100x round-off: left alone
        + rows("heun", [1.6e-3, 8e-4, 4e-4], status="unstable")  # a failed row is its own verdict
    )
    wanted = short_of_order([case], ["reference"], table)
    assert [(w.method, w.declared, w.dts) for w in wanted] == [("midpoint", 2.0, ()), ("rk4", 4.0, ())]
    quick = short_of_order([case], ["reference"], table, quick=True)  # a quick run: the flat one only
    assert [w.method for w in quick] == ["rk4"]


@pytest.mark.parametrize("quick", [(), ("--quick",)], ids=["full", "quick"])
def test_an_error_flat_at_every_step_is_carried_on_and_fails(tmp_path, capsys, quick):
    results, record, gate = _run(tmp_path, "test_refine:Misplaced", *quick)
    (refined,) = record["refined"]
    assert refined["method"] == "verlet" and refined["order"] < 0.5
    assert refined["dts"] == [5e-4 / 2**k for k in range(1, MAX_HALVINGS + 1)]  # every halving
    rows = results[(results.engine == "misplaced-test") & (results.dt_kind == "step")]
    errors = rows.error.to_numpy(float)
    assert np.all(np.abs(errors / OFFSET - np.sqrt(3)) < 0.01)  # |(d, d, d)|: flat at every step
    assert gate == 1
    out = capsys.readouterr().out
    assert "FAIL harmonic-oscillator/order/misplaced-test/verlet/declared" in out
    assert "finer than the case's sweep (the method does not converge as declared)" in out


def test_a_run_carried_on_that_timed_out_is_a_cost_limit_not_the_gate_s_verdict(case_named):
    """A method flat over the case's sweep, carried on: its first finer run flat too, the
    next one past its time limit. The declared-order gate judges the runs that ended (flat:
    failed, the method converges to something else), not the one that timed out; a timeout
    within the case's own sweep still fails the gate as a row not measured."""
    from truestep.ci.gates import check_gates
    from truestep.measures.declared import declared_order_gates

    case = case_named("harmonic-oscillator")

    def table(statuses: list[str]) -> pd.DataFrame:
        dts = [2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4]
        return pd.DataFrame(
            {
                "case": case.name,
                "engine": "reference",
                "method": "rk4",
                "dt": dts,
                "dt_kind": "step",
                "status": statuses,
                "error": [1e-3 if s == "ok" else np.nan for s in statuses],
                "message": ["" if s == "ok" else "ran past its limit" for s in statuses],
            }
        )

    gates = [g for g in declared_order_gates([case], ["reference"]) if g.method == "rk4"]

    def verdict(statuses: list[str]):
        (v,) = [
            v
            for v in check_gates([case], table(statuses), extra=[(["*"], g) for g in gates])
            if v.gate.method == "rk4" and v.gate in gates
        ]
        return v

    finer = verdict(["ok", "ok", "ok", "ok", "timeout"])
    assert not finer.passed and "does not converge as declared" in finer.measured, finer.measured
    within = verdict(["ok", "timeout", "ok", "ok", "ok"])
    assert not within.passed and "timeout" in within.measured, within.measured
