"""``scorecard.csv`` (issue 36, item 9): the report's scorecard as a table a tool reads,
each count and ratio recomputed here from the published tables by their own route."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from truestep.cases import load_cases
from truestep.runtime.folder import REPORT_FILES

REPORTS = Path(__file__).resolve().parents[2] / "reports"


def _read(name: str) -> pd.DataFrame:
    return pd.read_csv(REPORTS / f"{name}.csv", keep_default_na=False, na_values=[""])


@pytest.fixture(scope="module")
def published():
    card = _read("scorecard")
    cases = {c.name: c for c in load_cases("*")}
    return card, _read("results"), _read("stability"), _read("restitution"), cases


def test_the_report_writes_its_scorecard_as_a_table():
    assert "scorecard.csv" in REPORT_FILES
    assert (REPORTS / "scorecard.csv").is_file()


def _sharing_rk4_s_error(results: pd.DataFrame, case) -> set[str]:
    """The reference's fixed-step methods whose error is rk4's (its highest-order
    fixed-step method) to 1e-6 at two or more steps and at every step both ran, rk4
    included, where rk4's is above round-off (1e-9 of the scale) and another method's is it."""
    mine = results[
        (results["case"] == case.name)
        & (results["engine"] == "reference")
        & (results["status"] == "ok")
        & (results["dt_kind"] == "step")
    ]
    error = {m: dict(zip(g["dt"].round(12), g["error"], strict=True)) for m, g in mine.groupby("method")}
    rk4 = error.get("rk4", {})
    if not rk4 or min(rk4.values()) <= 1e-9 * case.error_scale:
        return set()
    same = {
        method
        for method, other in error.items()
        if len(set(rk4) & set(other)) >= 2
        and all(abs(rk4[h] - other[h]) <= 1e-6 * rk4[h] for h in set(rk4) & set(other))
    }
    return same if len(same) > 1 else set()


def test_counts_of_cases_run_and_reached(published):
    """``cases_run``: the family's cases with a row that ran; ``cases_reached``: those where
    some ok row's error is within ``target`` of the case's error scale, the reference's
    methods leaving out the cases where they share one error (a contact's or a spawn's)."""
    card, results, _, _, cases = published
    shared = {name: _sharing_rk4_s_error(results, c) for name, c in cases.items()}
    assert {name for name, methods in shared.items() if methods} == {
        "bouncing-ball",
        "particle-fountain",
        "particle-rain",
        "sliding-contact",
    }
    assert {"midpoint", "heun", "rk4", "verlet", "lecture"} <= shared["particle-fountain"]
    assert not {"euler", "dopri5"} & shared["particle-fountain"]
    ran = results[~results["status"].isin(["unsupported", "skipped"])]
    for r in card.itertuples():
        mine = ran[(ran["engine"] == r.engine) & (ran["method"] == r.method)]
        names = {c for c in mine["case"] if cases[c].family == r.family}
        assert r.cases_run == len(names), (r.engine, r.method, r.family)
        assert r.cases_measured == sum(cases[c].exact is not None for c in names)
        reached = 0
        for c in names:
            if r.engine == "reference" and r.method in shared[c]:
                continue
            ok = mine[(mine["case"] == c) & (mine["status"] == "ok")]
            errors = pd.to_numeric(ok["error"], errors="coerce").dropna()
            reached += bool(len(errors)) and errors.min() <= r.target * cases[c].error_scale
        assert r.cases_reached == reached, (r.engine, r.method, r.family)
        assert np.isnan(r.cost_ratio) == (reached == 0)


def test_stability_ratio_over_the_exact_limit_or_the_best(published):
    card, _, stability, _, cases = published
    ok = stability[stability["status"] == "ok"]
    family = ok["case"].map({name: c.family for name, c in cases.items()})
    for r in card.itertuples():
        mine = ok[(ok["engine"] == r.engine) & (ok["method"] == r.method) & (family == r.family)]
        ratios, highs, zero = [], [], 0
        for row in mine.itertuples():
            if row.dt_limit_exact == 0:
                zero += 1
                continue
            known = np.isfinite(row.dt_limit_exact) and row.dt_limit_exact > 0
            best = ok[ok["case"] == row.case]["dt_limit"].max()
            ratio = row.dt_limit / (row.dt_limit_exact if known else best)
            # the interval's top: the smallest unstable step (the limit where none was found)
            top = row.dt_unstable if np.isfinite(row.dt_unstable) else row.dt_limit
            if np.isfinite(ratio):
                ratios.append(ratio)
                highs.append(top / (row.dt_limit_exact if known else best))
        assert r.stability_zero == zero and r.stability_cases == len(ratios), (r.engine, r.method)
        if ratios:
            assert r.stability_ratio == pytest.approx(np.median(ratios), rel=1e-12)
            assert r.stability_ratio_high == pytest.approx(np.median(highs), rel=1e-12)
            assert r.stability_ratio_high >= r.stability_ratio
        else:
            assert np.isnan(r.stability_ratio) and np.isnan(r.stability_ratio_high)


def test_restitution_gap_from_the_bounces(published):
    card, _, _, restitution, _ = published
    ok = restitution[restitution["status"] == "ok"].dropna(subset=["e_measured"])
    for r in card.itertuples():
        mine = ok[(ok["engine"] == r.engine) & (ok["method"] == r.method)]
        gaps = (mine["e_measured"] - mine["e_set"]).abs()
        assert r.restitution_bounces == len(gaps)
        if len(gaps):
            assert r.restitution_gap == pytest.approx(gaps.median(), rel=1e-12)
            assert r.restitution_gap_worst == pytest.approx(gaps.max(), rel=1e-12)
        else:
            assert np.isnan(r.restitution_gap)
