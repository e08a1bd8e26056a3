"""Which run to pick, read off the tables: the cheapest run that reaches an accuracy, and
the largest step that survives a hard case with its accuracy intact.

Both are pure functions of ``results.csv`` and the cases; the report's summary sentences
and its scorecard are made from them.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from truestep.cases.case import Case
from truestep.measures.metrics import energy_behaviour

ACCURACY_TARGETS = (1e-2, 1e-4, 1e-6)
"""Accuracy targets, as fractions of each case's error scale (``[reference] scale``)."""
SURVIVAL_ERROR = 0.1
"""A run survives a hard case only if its error is at most this fraction of the case's
scale: a tenth of an orbit's radius, of a cloth's size. Beyond it the run is garbage
however stable it stayed (close-encounter at 1 ms: errors of 3 to 43 scales)."""
SURVIVAL_ENERGY = 1.0
"""... and its relative energy error is at most this: a bound three-body system whose
energy went from -2.4 J to +525 J has been blown apart, whatever its positions say."""
PICK_COLUMNS = [
    "case",
    "target",
    "error_needed",
    "by",
    "engine",
    "method",
    "dt",
    "dt_kind",
    "error",
    "wall_s",
    "nfev",
    "runs_reaching",
    "tied",
]
TIE_NOISE = 0.15
"""The least relative noise of a wall time: two runs of the same revision on one machine
move single rows (a shared machine's load, caches, frequency) by more than the spread of
one row's repeats shows. Wall times closer than their noise bands are a tie."""
TIMER_FLOOR_S = 1e-5
"""The least absolute noise of a wall time, s: timings of a few microseconds move by more
than themselves between two runs of one revision (caches, interrupts, the call around the
stepping; ``tools/experiments/aa_timing.py``), whatever their spread within a run."""


def _num(frame: pd.DataFrame, column: str) -> np.ndarray:
    return pd.to_numeric(frame[column], errors="coerce").to_numpy(float)


def speed_claims(frame: pd.DataFrame) -> pd.DataFrame:
    """The rows whose wall time is a speed claim: all but those run once, untimed
    (``repeats`` 0: an engine that makes no speed claim on its device,
    :func:`truestep.execution.runner.makes_speed_claim`). A table without ``repeats``
    (an earlier release's) is taken as all timed."""
    if "repeats" not in frame:
        return frame
    return frame[pd.to_numeric(frame["repeats"], errors="coerce").fillna(1.0).to_numpy(float) != 0]


def noise_band(wall: np.ndarray, spread: np.ndarray | None = None) -> np.ndarray:
    """Half-widths (s) of the intervals wall times (s) are known to: a row's own spread
    (``wall_s_spread``), at least :data:`TIE_NOISE` of the time and :data:`TIMER_FLOOR_S`."""
    wall = np.asarray(wall, float)
    band = np.maximum(TIE_NOISE * wall, TIMER_FLOOR_S)
    if spread is not None:
        band = np.fmax(band, np.asarray(spread, float))
    return band


def noise_interval(wall: np.ndarray, spread: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The intervals (s) wall times (s) are known to: ``wall / (1 + r)`` to ``wall * (1 + r)``
    with ``r`` the relative :func:`noise_band`. Timing noise multiplies (a loaded core, a
    lower clock slow every step alike), so the interval is symmetric in the logarithm and
    its lower end stays above 0 however wide a row's spread: a row whose repeats spread
    wider than their median is known to a factor, not to within 0 of anything."""
    wall = np.asarray(wall, float)
    grow = 1.0 + noise_band(wall, spread) / wall
    return wall / grow, wall * grow


def _bands(frame: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    spread = _num(frame, "wall_s_spread") if "wall_s_spread" in frame else None
    return noise_interval(_num(frame, "wall_s"), spread)


def tied_with_fastest(frame: pd.DataFrame) -> np.ndarray:
    """Which rows' wall times cannot be told from the fastest's: the bottoms of their
    intervals (:func:`noise_interval`) reach down to the top of the fastest's. Rows
    without a wall time are not tied."""
    wall = _num(frame, "wall_s")
    low, high = _bands(frame)
    if not np.isfinite(wall).any():
        return np.zeros(len(frame), bool)
    k = int(np.nanargmin(wall))
    return np.isfinite(wall) & (low <= high[k])


def _label(r: pd.Series) -> str:
    kind = "tol" if r["dt_kind"] == "tolerance" else "dt"
    return f"{r['engine']} / {r['method']} ({kind} {float(r['dt']):.3g})"


def _pick_by_wall(reach: pd.DataFrame) -> tuple[pd.Series, str]:
    """The run to name as the fastest of ``reach`` and the others tied with it.

    Among the runs tied with the fastest (:func:`tied_with_fastest`), the one named is
    the one with the fewest evaluations (then the first in the table's order): timing
    noise never decides which run is named, only whether a run is in the tie."""
    tied = reach[tied_with_fastest(reach)]
    order = np.lexsort((np.arange(len(tied)), np.nan_to_num(_num(tied, "nfev"), nan=np.inf)))
    named = tied.iloc[int(order[0])]
    others = [_label(tied.iloc[int(k)]) for k in order[1:]]
    return named, "; ".join(others)


SHARED_REL = 1e-6
"""Errors of two methods that agree this closely (relative) at every step are one error."""
ROUND_OFF_ERROR = 1e-9
"""Errors below this fraction of a case's scale are round-off (a method exact on the scene)."""


def scene_set_error(case: Case, results: pd.DataFrame) -> str | None:
    """Why ``case``'s error is set by something every method shares rather than by the
    integrator, or ``None``: the reference's fixed-step method of the highest declared
    order and one of a lower order have the same error, to :data:`SHARED_REL`, at every
    step both ran (at least two steps, each error above round-off: a method exact on the
    scene is not this). A fourth-order method's truncation error would be far below a
    second-order one's; when they agree, events that land on step ends (contacts,
    spawns), not the integration, set the error. particle-fountain: midpoint, heun, rk4,
    verlet and the lecture's update all at 0.012410 m and 0.005822 m, halving with the
    step. The report says so beside the picks, which still compare the engines (whose
    event handling differs); the scorecard leaves the case out of the cost ratios of the
    methods that share the error (:func:`shared_error_methods`)."""
    shared = _shared(case, results)
    if shared is None:
        return None
    best, other, orders, errors = shared
    steps = sorted(set(errors[best]) & set(errors[other]))
    shown = ", ".join(f"{errors[best][h]:.5g} at {h:.4g} s" for h in steps)
    return (
        f"the reference's {best} (order {orders[best]}) and {other} (order {orders[other]}) have "
        f"the same error at every step ({shown}): something every method shares sets it, not the "
        "integrator"
    )


def shared_error_methods(case: Case, results: pd.DataFrame) -> list[str]:
    """The reference's fixed-step methods whose error on ``case`` is the one its methods
    share (:func:`scene_set_error`: the same as its highest-order method's, to
    :data:`SHARED_REL`, at every step both ran, at least two), sorted; empty where they
    share none. A method that does worse there (explicit Euler's first-order flight) or
    that locates the events (an adaptive one) keeps an error of its own."""
    shared = _shared(case, results)
    if shared is None:
        return []
    best, _, _, errors = shared
    return sorted(m for m in errors if m == best or _same_errors(errors[best], errors[m]))


def _same_errors(a: dict[float, float], b: dict[float, float]) -> bool:
    """Whether two methods' errors (step -> error) are one at every step both ran (at
    least two)."""
    steps = set(a) & set(b)
    return len(steps) >= 2 and all(abs(a[h] - b[h]) <= SHARED_REL * a[h] for h in steps)


def _shared(
    case: Case, results: pd.DataFrame
) -> tuple[str, str, dict[str, int], dict[str, dict[float, float]]] | None:
    """The reference's highest-order fixed-step method and one of a lower order with the
    same errors (see :func:`scene_set_error`), the methods' orders and their errors
    (method -> step -> error); ``None`` where there are none."""
    from truestep.adapters import get_adapter
    from truestep.adapters.base import facts_of

    ok = results[
        (results["case"] == case.name)
        & (results["engine"] == "reference")
        & (results["status"] == "ok")
        & (results["dt_kind"] == "step")
    ]
    if not len(ok):
        return None
    adapter = get_adapter("reference")
    floor = ROUND_OFF_ERROR * case.error_scale
    errors: dict[str, dict[float, float]] = {}
    for r in ok.itertuples(index=False):
        errors.setdefault(str(r.method), {})[round(float(r.dt), 12)] = float(r.error)
    orders = {m: f.order for m in errors if (f := facts_of(adapter, m)) is not None}
    if not orders:
        return None
    top = max(orders.values())
    for best in sorted(m for m, o in orders.items() if o == top):
        if not all(np.isfinite(x) and x > floor for x in errors[best].values()):
            continue
        for other in sorted(m for m, o in orders.items() if o < top):
            if _same_errors(errors[best], errors[other]):
                return best, other, orders, errors
    return None


def cheapest(
    results: pd.DataFrame, cases: list[Case], targets: tuple[float, ...] = ACCURACY_TARGETS
) -> pd.DataFrame:
    """For each case with measured errors and each target: the cheapest ``ok`` run whose
    error is at most ``target x scale``, by wall time (``by = wall_s``) and by derivative
    evaluations (``by = nfev``). A target no run reaches is a row with an empty engine
    and ``runs_reaching`` 0; by wall time, only runs whose wall time is a speed claim
    compete (:func:`speed_claims`). Columns :data:`PICK_COLUMNS`; ``error_needed`` in the
    case's error units. By wall time, runs within timing noise of the fastest are a tie
    (:func:`_pick_by_wall`): ``tied`` lists the others, ``engine / method (dt ...)``
    separated by ``;``."""
    rows = []
    for case in cases:
        d = results[(results["case"] == case.name) & (results["status"] == "ok")]
        error = _num(d, "error")
        if not np.isfinite(error).any():
            continue
        for target in targets:
            needed = target * case.error_scale
            reach = d[error <= needed]
            for by in ("wall_s", "nfev"):
                among = speed_claims(reach) if by == "wall_s" else reach
                base = {
                    "case": case.name,
                    "target": target,
                    "error_needed": needed,
                    "by": by,
                    "runs_reaching": len(reach),
                    "tied": "",
                }
                cost = _num(among, by)
                if not np.isfinite(cost).any():
                    rows.append({**base, "engine": "", "method": ""})
                    continue
                if by == "wall_s":
                    r, base["tied"] = _pick_by_wall(among)
                else:
                    r = among.iloc[int(np.nanargmin(cost))]
                rows.append(
                    {
                        **base,
                        **{k: r[k] for k in ("engine", "method", "dt", "dt_kind", "error", "wall_s", "nfev")},
                    }
                )
    return pd.DataFrame(rows, columns=PICK_COLUMNS)


def outcome(case: Case, row: pd.Series) -> str:
    """Why a run does not survive the case, or ``""`` when it does: its status
    (``unstable``...), a failure the scene tests (``tunnelled``), ``inaccurate`` (error
    above :data:`SURVIVAL_ERROR` of the scale) or ``energy`` (relative energy error above
    :data:`SURVIVAL_ENERGY` in a scene without energy sources)."""
    from truestep.measures.properties import FAILURES

    if row["status"] != "ok":
        return str(row["status"])
    for prop, word in FAILURES.items():
        if prop in row and float(pd.to_numeric(row[prop], errors="coerce")) > 0:
            return word
    error = float(pd.to_numeric(row.get("error"), errors="coerce"))
    if np.isfinite(error) and error > SURVIVAL_ERROR * case.error_scale:
        return "inaccurate"
    drift = float(pd.to_numeric(row.get("energy_drift"), errors="coerce"))
    if energy_behaviour(case) != "source" and np.isfinite(drift) and drift > SURVIVAL_ENERGY:
        return "energy"
    return ""


def survival(case: Case, results: pd.DataFrame) -> pd.DataFrame:
    """Per engine/method of a case's fixed-step sweep: the largest step survived
    (:func:`outcome` empty) and what became of the run at the largest step.

    Columns ``engine, method, dt_survived`` (s, NaN if none) and ``failure`` (the outcome
    at the largest step of the sweep, empty if it survived).
    """
    d = results[(results["case"] == case.name) & (results["dt_kind"] == "step")]
    d = d[np.isfinite(_num(d, "dt"))]
    out = []
    for (engine, method), g in d.groupby(["engine", "method"], sort=False):
        outcomes = [outcome(case, r) for _, r in g.iterrows()]
        dts = _num(g, "dt")
        survived = [dt for dt, o in zip(dts, outcomes, strict=True) if not o]
        out.append(
            {
                "engine": engine,
                "method": method,
                "dt_survived": max(survived) if survived else np.nan,
                "failure": outcomes[int(np.argmax(dts))],
            }
        )
    return pd.DataFrame(out, columns=["engine", "method", "dt_survived", "failure"])


SCORECARD_TARGET = 1e-4
"""The accuracy the scorecard's cost column asks for, as a fraction of each case's scale."""
SCORECARD_COLUMNS = [
    "engine",
    "method",
    "family",
    "cases_run",
    "cases_reached",
    "cost_ratio",
    "stability_cases",
    "stability_ratio",
    "cases_measured",
    "stability_zero",
    "stability_ratio_high",
]


def scorecard_table(
    card: pd.DataFrame, fidelity: pd.DataFrame, *, target: float = SCORECARD_TARGET
) -> pd.DataFrame:
    """The scorecard (:func:`scorecard`) with each engine and method's restitution
    (:func:`restitution_fidelity`) beside it: ``scorecard.csv``
    (:data:`truestep.tables.spec.SCORECARD`), in the scorecard's order."""
    from truestep.tables.spec import SCORECARD

    gaps = {(r["engine"], r["method"]): r for r in fidelity.to_dict("records")}
    rows = []
    for r in card.to_dict("records"):
        gap = gaps.get((r["engine"], r["method"]))
        rows.append(
            {
                **{k: r[k] for k in SCORECARD_COLUMNS},
                "target": target,
                "restitution_bounces": 0 if gap is None else int(gap["bounces"]),
                "restitution_gap": np.nan if gap is None else float(gap["median"]),
                "restitution_gap_worst": np.nan if gap is None else float(gap["worst"]),
            }
        )
    return SCORECARD.frame(rows)


def _limit_reference(stability: pd.DataFrame) -> pd.Series:
    """Per stability row: the exact limit where one exists (finite, positive), else the
    best limit any engine/method reached on that case."""
    limit = pd.to_numeric(stability["dt_limit"], errors="coerce")
    exact = pd.to_numeric(stability["dt_limit_exact"], errors="coerce")
    best = limit.groupby(stability["case"]).transform("max")
    return exact.where(np.isfinite(exact) & (exact > 0), best)


def scorecard(
    results: pd.DataFrame,
    cases: list[Case],
    stability: pd.DataFrame | None = None,
    *,
    target: float = SCORECARD_TARGET,
) -> pd.DataFrame:
    """One row per engine, method and family of scenes (:data:`SCORECARD_COLUMNS`).

    ``cost_ratio``: over the family's cases this engine/method reached ``target x scale``
    on, the median of its cheapest wall time there over the cheapest of all runs (1: the
    fastest, or within timing noise of it: the bottom of its :func:`noise_interval` reaches
    the top of the fastest's, as in :func:`tied_with_fastest`); NaN if it reached
    none. A case whose error the reference's integrators do not set (:func:`scene_set_error`:
    the same error for its methods of different orders) is left out of the ratios of the
    reference's methods that share that error (:func:`shared_error_methods`), and stays in
    the other engines' (their handling of the events it measures differs) and in those of
    the reference's methods with an error of their own there.
    ``cases_run`` / ``cases_measured`` / ``cases_reached``: the family's cases it
    ran / ran that have an error measure (an exact solution or reference run) / reached
    the target on (and counted, as above).
    ``stability_ratio``: over the family's cases with a stability search whose exact
    limit is not 0 (whether or not the sweep ran the method there: a search of a case
    whose sweep skips it still tells its largest stable step), the median of its largest
    stable step over the exact limit (or, with no exact one, the best any method
    reached); NaN without such searches. ``stability_ratio_high``: the same median over
    the searches' smallest unstable steps (a search's limit where it found none): the
    median's interval, wide where round-off decides limits.
    ``stability_zero``: the searches whose exact limit is 0 (the method is unstable at
    every step there, as theory says: no ratio to take).
    """
    measured = {c.name for c in cases if c.exact is not None}
    family = {c.name: c.family for c in cases}
    scale = {c.name: c.error_scale for c in cases}
    ran = results[~results["status"].isin(["unsupported", "skipped"]) & results["case"].isin(list(family))]
    ok = ran[ran["status"] == "ok"].copy()
    shared = {c.name: shared_error_methods(c, results) for c in cases if c.name in family}
    ok["reaches"] = _num(ok, "error") <= target * ok["case"].map(scale).to_numpy(float)
    ok["low"], ok["high"] = _bands(ok) if len(ok) else (np.zeros(0), np.zeros(0))
    reached = ok[ok["reaches"] & np.isfinite(_num(ok, "wall_s"))]
    fastest = {
        case: g.iloc[int(np.argmin(_num(g, "wall_s")))] for case, g in reached.groupby("case", sort=False)
    }
    stab = None
    if stability is not None and len(stability):
        stab = stability[stability["status"] == "ok"].copy()
        stab["zero"] = pd.to_numeric(stab["dt_limit_exact"], errors="coerce").to_numpy(float) == 0
        reference = _limit_reference(stab)
        limit = pd.to_numeric(stab["dt_limit"], errors="coerce")
        unstable = pd.to_numeric(stab["dt_unstable"], errors="coerce") if "dt_unstable" in stab else limit
        stab["ratio"] = (limit / reference).where(~stab["zero"])
        stab["ratio_high"] = (unstable.where(np.isfinite(unstable), limit) / reference).where(~stab["zero"])
    rows = []
    for (engine, method), mine in ran.groupby(["engine", "method"], sort=False):
        for fam in dict.fromkeys(family[c] for c in mine["case"]):
            names = [c for c in dict.fromkeys(mine["case"]) if family[c] == fam]
            ratios = []
            for case in names:
                if engine == "reference" and method in shared[case]:
                    continue  # one error with the others there: it is no cheaper than they are
                hit = reached[
                    (reached["case"] == case) & (reached["engine"] == engine) & (reached["method"] == method)
                ]
                if len(hit):
                    mine_best = hit.iloc[int(np.argmin(_num(hit, "wall_s")))]
                    top = fastest[case]
                    tied = mine_best["low"] <= top["high"]
                    ratios.append(1.0 if tied else float(mine_best["wall_s"] / top["wall_s"]))
            searched = [c for c in family if family[c] == fam]  # a search counts, run in the sweep or not
            s = (
                stab[(stab["engine"] == engine) & (stab["method"] == method) & stab["case"].isin(searched)]
                if stab is not None
                else pd.DataFrame()
            )
            s_ratio = _num(s, "ratio") if len(s) else np.array([])
            s_high = _num(s, "ratio_high") if len(s) else np.array([])
            s_high, s_ratio = s_high[np.isfinite(s_ratio)], s_ratio[np.isfinite(s_ratio)]
            zero = int(s["zero"].sum()) if len(s) else 0
            rows.append(
                {
                    "engine": engine,
                    "method": method,
                    "family": fam,
                    "cases_run": len(names),
                    "cases_reached": len(ratios),
                    "cost_ratio": float(np.median(ratios)) if ratios else np.nan,
                    "stability_cases": len(s_ratio),
                    "stability_ratio": float(np.median(s_ratio)) if len(s_ratio) else np.nan,
                    "cases_measured": sum(c in measured for c in names),
                    "stability_zero": zero,
                    "stability_ratio_high": float(np.median(s_high)) if len(s_high) else np.nan,
                }
            )
    order = {
        pair: k
        for k, pair in enumerate(dict.fromkeys(zip(results["engine"], results["method"], strict=True)))
    }
    card = pd.DataFrame(rows, columns=SCORECARD_COLUMNS)
    return card.iloc[
        sorted(range(len(card)), key=lambda k: order[(card["engine"].iloc[k], card["method"].iloc[k])])
    ].reset_index(drop=True)


def restitution_fidelity(restitution: pd.DataFrame | None) -> pd.DataFrame:
    """Per engine and method: the median and the largest ``|e_measured - e_set|`` over every
    bounce of the restitution sweep (columns ``engine, method, bounces, median, worst``)."""
    cols = ["engine", "method", "bounces", "median", "worst"]
    if restitution is None or not len(restitution):
        return pd.DataFrame(columns=cols)
    r = restitution[restitution["status"] == "ok"].copy()
    r["gap"] = (
        pd.to_numeric(r["e_measured"], errors="coerce") - pd.to_numeric(r["e_set"], errors="coerce")
    ).abs()
    r = r.dropna(subset=["gap"])
    out = [
        {
            "engine": e,
            "method": m,
            "bounces": len(g),
            "median": float(g["gap"].median()),
            "worst": float(g["gap"].max()),
        }
        for (e, m), g in r.groupby(["engine", "method"], sort=False)
    ]
    return pd.DataFrame(out, columns=cols)


LONG_ROW_S = 5.0
"""Seconds of timed stepping (a row's ``wall_s``) beyond which the report lists the row
with what it buys (:func:`costly_rows`)."""
COSTLY_COLUMNS = [
    "case",
    "engine",
    "method",
    "dt",
    "dt_kind",
    "wall_s",
    "error",
    "coarser_dt",
    "coarser_wall_s",
    "coarser_error",
]


def costly_rows(results: pd.DataFrame, threshold: float = LONG_ROW_S) -> pd.DataFrame:
    """The rows that ran (any status) whose wall time (s, the median timed stepping, or the
    one untimed run of an engine without a speed claim) is over ``threshold``, longest
    first, each beside the same engine and method's next coarser step (or looser
    tolerance) of the case (the ``coarser_*`` columns; NaN where the row is the coarsest it
    ran): what the longer run buys is its error against that one's. Columns
    :data:`COSTLY_COLUMNS`. Which rows pass the threshold is a timing: a row near it may be
    listed on one machine and not another."""
    ran = results[~results["status"].isin(["unsupported", "skipped"])]
    long = ran[_num(ran, "wall_s") > threshold]
    rows = []
    for r in long.itertuples(index=False):
        same = ran[(ran["case"] == r.case) & (ran["engine"] == r.engine) & (ran["method"] == r.method)]
        coarser = same[(_num(same, "dt") > float(r.dt)) & (same["dt_kind"] == r.dt_kind)]
        c = coarser.iloc[int(np.argmin(_num(coarser, "dt")))] if len(coarser) else None
        rows.append(
            {
                "case": r.case,
                "engine": r.engine,
                "method": r.method,
                "dt": float(r.dt),
                "dt_kind": r.dt_kind,
                "wall_s": float(r.wall_s),
                "error": float(pd.to_numeric(r.error, errors="coerce")),
                "coarser_dt": np.nan if c is None else float(c["dt"]),
                "coarser_wall_s": np.nan if c is None else float(c["wall_s"]),
                "coarser_error": np.nan if c is None else float(pd.to_numeric(c["error"], errors="coerce")),
            }
        )
    frame = pd.DataFrame(rows, columns=COSTLY_COLUMNS)
    return frame.sort_values("wall_s", ascending=False, kind="stable").reset_index(drop=True)
