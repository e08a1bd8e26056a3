"""The report's picks on tables whose answer is known: the cheapest run per accuracy, and
survival that needs accuracy as well as stability."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from truestep.measures.findings import conclude
from truestep.measures.picks import cheapest, scorecard, shared_error_methods, survival

COLUMNS = ["case", "engine", "method", "dt", "dt_kind", "status", "error", "energy_drift", "nfev", "wall_s"]


def test_the_cheapest_run_per_target_is_not_the_most_accurate(case_named):
    """Radau reaches 1e-9 in 0.6 s, DOP853 1e-5 in 0.03 s: for 1e-2 and 1e-4 of the scale the
    pick is DOP853 (error x time would pick Radau: 6e-10 against 3e-7); only Radau reaches
    1e-6 (and 1e-10 nobody). By evaluations a fixed-step run can win instead."""
    case = case_named("earth-orbit")  # scale 7e6 m
    s = case.error_scale
    rows = [
        (case.name, "scipy", "Radau", 1e-10, "tolerance", "ok", 1e-9 * s, 0, 9000, 0.6),
        (case.name, "scipy", "DOP853", 1e-6, "tolerance", "ok", 1e-5 * s, 0, 700, 0.03),
        (case.name, "reference", "rk4", 30.0, "step", "ok", 5e-3 * s, 0, 400, 0.05),
        (case.name, "reference", "euler", 30.0, "step", "unstable", np.nan, np.nan, 100, 0.01),
    ]
    picks = cheapest(pd.DataFrame(rows, columns=COLUMNS), [case], targets=(1e-2, 1e-4, 1e-6, 1e-10))
    pick = picks.set_index(["target", "by"])
    assert pick.loc[(1e-2, "wall_s"), "method"] == "DOP853"
    assert pick.loc[(1e-2, "nfev"), "method"] == "rk4"
    assert pick.loc[(1e-4, "wall_s"), "method"] == "DOP853"
    assert pick.loc[(1e-6, "wall_s"), "method"] == "Radau"
    assert pick.loc[(1e-10, "wall_s"), "engine"] == "" and pick.loc[(1e-10, "wall_s"), "runs_reaching"] == 0


def test_a_run_whose_wall_time_is_no_speed_claim_is_never_the_fastest(case_named):
    """A row run once, untimed (``repeats`` 0: an engine with no speed claim on its device)
    is picked by evaluations as any other, never by wall time, however small its time."""
    case = case_named("earth-orbit")
    s = case.error_scale
    rows = [
        (case.name, "scipy", "DOP853", 1e-6, "tolerance", "ok", 1e-5 * s, 0, 700, 0.03),
        (case.name, "mujoco-warp", "RK4", 30.0, "step", "ok", 1e-5 * s, 0, 400, 0.001),
    ]
    frame = pd.DataFrame(rows, columns=COLUMNS).assign(repeats=[3, 0])
    pick = cheapest(frame, [case], targets=(1e-2,)).set_index("by")
    assert (pick.loc["wall_s", "engine"], pick.loc["nfev", "engine"]) == ("scipy", "mujoco-warp")
    assert pick.loc["wall_s", "tied"] == ""


def test_survival_needs_accuracy_and_a_physical_energy(case_named):
    """close-encounter at 1 ms: finishing ok with an error of 43 scales, or with the
    energy of a bound system gone positive (drift 222), is not surviving."""
    case = case_named("close-encounter")
    s = case.error_scale
    rows = [
        (case.name, "reference", "euler", 1e-3, "step", "ok", 43 * s, 222.0, 0, 0),
        (case.name, "reference", "euler", 5e-4, "step", "ok", 0.05 * s, 0.2, 0, 0),
        (case.name, "reference", "rk4", 1e-3, "step", "ok", 0.01 * s, 5.0, 0, 0),
        (case.name, "reference", "rk4", 5e-4, "step", "ok", 0.001 * s, 0.01, 0, 0),
        (case.name, "reference", "verlet", 1e-3, "step", "unstable", np.nan, np.nan, 0, 0),
    ]
    table = survival(case, pd.DataFrame(rows, columns=COLUMNS)).set_index("method")
    assert table.loc["euler", "dt_survived"] == 5e-4 and table.loc["euler", "failure"] == "inaccurate"
    assert table.loc["rk4", "dt_survived"] == 5e-4 and table.loc["rk4", "failure"] == "energy"
    assert np.isnan(table.loc["verlet", "dt_survived"]) and table.loc["verlet", "failure"] == "unstable"


def test_scorecard_cost_and_stability_ratios(case_named):
    """Two orbit cases, target 1e-4 of the scale: A reaches it in 1 s and 2 s (the fastest
    on both), B only on earth-orbit, in 3 s: A's cost ratio is 1 on 2 cases, B's 3 on 1.
    Stability: A's limit 0.19 s against an exact 0.2 s reads 0.95; C, no exact limit,
    0.1 s against the best 0.4 s reads 0.25."""
    from truestep.measures.picks import restitution_fidelity, scorecard

    kepler, earth = case_named("kepler-orbit"), case_named("earth-orbit")
    rows = [
        (kepler.name, "e", "A", 0.1, "step", "ok", 1e-5 * kepler.error_scale, 0, 10, 1.0),
        (earth.name, "e", "A", 0.1, "step", "ok", 1e-5 * earth.error_scale, 0, 10, 2.0),
        (earth.name, "e", "B", 0.1, "step", "ok", 1e-5 * earth.error_scale, 0, 10, 6.0),
        (kepler.name, "e", "B", 0.1, "step", "ok", 1e-2 * kepler.error_scale, 0, 10, 0.1),
        (kepler.name, "e", "C", 0.1, "step", "ok", 1.0, 0, 10, 0.1),
    ]
    stab = pd.DataFrame(
        [
            (earth.name, "e", "A", 0.19, 0.2, "ok"),
            (kepler.name, "e", "C", 0.1, np.nan, "ok"),
            (kepler.name, "e", "D", 0.4, np.nan, "ok"),
        ],
        columns=["case", "engine", "method", "dt_limit", "dt_limit_exact", "status"],
    )
    card = scorecard(pd.DataFrame(rows, columns=COLUMNS), [kepler, earth], stab).set_index("method")
    assert card.loc["A", "cost_ratio"] == 1.0 and card.loc["A", "cases_reached"] == 2
    assert card.loc["B", "cost_ratio"] == 3.0 and card.loc["B", "cases_reached"] == 1
    assert card.loc["A", "stability_ratio"] == pytest.approx(0.95)
    assert card.loc["C", "stability_ratio"] == pytest.approx(0.25)
    assert np.isnan(card.loc["C", "cost_ratio"]) and card.loc["C", "cases_run"] == 1
    rest = pd.DataFrame(
        [("e", "A", 0.5, 0.48, "ok"), ("e", "A", 0.8, 0.86, "ok")],
        columns=["engine", "method", "e_set", "e_measured", "status"],
    )
    fid = restitution_fidelity(rest).iloc[0]
    assert fid["median"] == pytest.approx(0.04) and fid["worst"] == pytest.approx(0.06)


def test_the_scorecard_counts_the_cases_it_rests_on_and_sets_exact_zero_limits_apart(case_named):
    """Of a family's cases a method ran, those with an error measure are counted apart from
    those reached (the sentences rank by them); a stability search whose exact limit is 0
    gives no ratio (the method is unstable at every step, as theory says) but is counted."""
    osc, chain = case_named("harmonic-oscillator"), case_named("spring-chain")
    rows = [
        (osc.name, "reference", "euler", 1e-3, "step", "ok", 1.0, 0.1, 100, 1e-3),
        (chain.name, "reference", "euler", 1e-3, "step", "ok", 1e-9, 0.1, 100, 1e-3),
        (osc.name, "reference", "rk4", 1e-3, "step", "ok", 1e-9, 0.0, 400, 2e-3),
    ]
    stab = pd.DataFrame(
        [
            (osc.name, "reference", "euler", 0.0, 0.0, "ok"),
            (osc.name, "reference", "rk4", 0.0278, 0.0278, "ok"),
        ],
        columns=["case", "engine", "method", "dt_limit", "dt_limit_exact", "status"],
    )
    card = scorecard(pd.DataFrame(rows, columns=COLUMNS), [osc, chain], stab).set_index(["method", "family"])
    euler = card.loc[("euler", osc.family)]
    assert (euler.cases_run, euler.cases_measured, euler.cases_reached) == (1, 1, 0)
    assert np.isnan(euler.stability_ratio) and euler.stability_zero == 1
    assert card.loc[("rk4", osc.family)].stability_ratio == pytest.approx(1.0)


def test_a_conclusion_names_what_the_rows_say(case_named):
    """The most accurate run, the least and greatest energy drift (a conserved-energy
    case; the two lists never share a run) and the runs that failed, read off the rows."""
    case = case_named("harmonic-oscillator")
    rows = [
        (case.name, "reference", m, dt, "step", st, err, drift, 100, 1e-3)
        for m, dt, st, err, drift in [
            ("rk4", 1e-3, "ok", 1e-9, 1e-10),
            ("verlet", 1e-3, "ok", 1e-5, 1e-6),
            ("euler", 1e-3, "unstable", np.nan, np.nan),
            ("midpoint", 1e-3, "ok", 1e-6, 1e-3),
            ("heun", 1e-3, "ok", 2e-6, 2e-3),
        ]
    ]
    c = conclude(case, pd.DataFrame(rows, columns=COLUMNS))
    assert (c.runs, c.ok) == (5, 4)
    assert c.most_accurate[:2] == ("reference", "rk4") and c.most_accurate[4] == 1e-9
    assert [r[1] for r in c.least_drift] == ["rk4", "verlet", "midpoint"]
    assert [r[1] for r in c.most_drift] == ["heun"]
    assert c.failed == [("reference", "euler", "unstable", 1)]


def test_a_case_whose_error_the_reference_s_methods_share_leaves_their_cost_ratios(case_named):
    """bouncing-ball: the reference's rk4 and heun have one error at both steps (the
    contact's), so neither is cheaper there than the other: their cost ratios leave the
    case out (NaN, reached on none). Its euler, worse there, and its dopri5, which locates
    the impact, keep errors of their own and the case; pymunk, whose contact differs, is
    compared with the fastest run too, the reference's heun (2 ms against its 1 ms)."""
    ball = case_named("bouncing-ball")
    s = ball.error_scale
    rows = [
        (ball.name, "reference", "rk4", 4e-3, "step", "ok", 1e-3 * s, 0, 40, 0.002),
        (ball.name, "reference", "rk4", 2e-3, "step", "ok", 5e-4 * s, 0, 80, 0.004),
        (ball.name, "reference", "heun", 4e-3, "step", "ok", 1e-3 * s, 0, 20, 0.001),
        (ball.name, "reference", "heun", 2e-3, "step", "ok", 5e-4 * s, 0, 40, 0.002),
        (ball.name, "reference", "euler", 4e-3, "step", "ok", 4e-3 * s, 0, 10, 0.002),
        (ball.name, "reference", "euler", 2e-3, "step", "ok", 2e-3 * s, 0, 20, 0.004),
        (ball.name, "reference", "dopri5", 1e-6, "tolerance", "ok", 1e-9 * s, 0, 200, 0.003),
        (ball.name, "pymunk", "default", 2e-3, "step", "ok", 2e-3 * s, 0, 10, 0.002),
    ]
    results = pd.DataFrame(rows, columns=COLUMNS)
    assert shared_error_methods(ball, results) == ["heun", "rk4"]
    card = scorecard(results, [ball], target=1e-2).set_index("method")
    for method in ("rk4", "heun"):
        assert np.isnan(card.loc[method, "cost_ratio"]) and card.loc[method, "cases_reached"] == 0
    for method, ratio in (("default", 2.0), ("euler", 2.0), ("dopri5", 3.0)):
        assert (
            card.loc[method, "cost_ratio"] == pytest.approx(ratio) and card.loc[method, "cases_reached"] == 1
        )
