"""What a run found, computed once from its tables beside the analyses, for the report to
render (it recomputes nothing): the fitted orders of convergence, the cheapest run to each
accuracy, the scorecard, how true each engine's restitution is, the largest step each
engine/method survives on the hard cases, the speed tables of the speed-up gates, and
each case's conclusion.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pandas as pd

from truestep.cases.case import Case
from truestep.cases.gate_kinds import GATE_KINDS
from truestep.measures.metrics import finest_local_order, fit_order, round_off_floor
from truestep.measures.peers import PEER_COLUMNS, same_scheme
from truestep.measures.picks import (
    cheapest,
    costly_rows,
    restitution_fidelity,
    scene_set_error,
    scorecard,
    shared_error_methods,
    speed_claims,
    survival,
)
from truestep.measures.reference_floor import ReferenceFloor, reference_floor
from truestep.measures.restitution import phase_contact
from truestep.measures.twins import TWIN_COLUMNS, twin_rows


@dataclass(frozen=True)
class Findings:
    """What a run found.

    orders : :func:`orders_table`
    cheapest : :func:`truestep.measures.picks.cheapest` at every accuracy target
    scorecard : :func:`truestep.measures.picks.scorecard`
    fidelity : :func:`truestep.measures.picks.restitution_fidelity`
    survival : case name -> :func:`truestep.measures.picks.survival`, for the hard cases
    speed : (case name, the gate's ``where``) -> :func:`speed_table`, for each ``speedup`` gate
    conclusions : case name -> :class:`Conclusion`
    notes : (engine, method) -> what the method is, in a line (the adapter's
    ``method_notes``), for every pair in the results whose adapter says
    peers : :func:`truestep.measures.peers.same_scheme`: each engine method beside the
    reference method it names as its scheme, their errors' ratio at the same steps
    """

    orders: pd.DataFrame
    cheapest: pd.DataFrame
    scorecard: pd.DataFrame
    fidelity: pd.DataFrame
    survival: dict[str, pd.DataFrame]
    speed: dict[tuple[str, str], pd.DataFrame]
    conclusions: dict[str, Conclusion] = dataclasses.field(default_factory=dict)
    notes: dict[tuple[str, str], str] = dataclasses.field(default_factory=dict)
    peers: pd.DataFrame = dataclasses.field(default_factory=lambda: pd.DataFrame(columns=list(PEER_COLUMNS)))
    scene_set: dict[str, str] = dataclasses.field(default_factory=dict)
    """case name -> why the reference's integrators do not set its error
    (:func:`truestep.measures.picks.scene_set_error`)."""
    costly: pd.DataFrame = dataclasses.field(default_factory=pd.DataFrame)
    """The rows of over :data:`truestep.measures.picks.LONG_ROW_S` of stepping, each beside its
    next coarser step (:func:`truestep.measures.picks.costly_rows`)."""
    shared_methods: dict[str, list[str]] = dataclasses.field(default_factory=dict)
    """case name -> the reference's methods that share that error there
    (:func:`truestep.measures.picks.shared_error_methods`)."""
    phase_contact: pd.DataFrame = dataclasses.field(default_factory=pd.DataFrame)
    """The restitution sweep's rows whose restitution depends on where in a step the ball
    arrives beyond the band (:func:`truestep.measures.restitution.phase_contact`)."""
    floors: dict[str, ReferenceFloor] = dataclasses.field(default_factory=dict)
    """case name -> its reference run's own error, for a case measured against a run
    (:func:`truestep.measures.reference_floor.reference_floor`)."""
    twins: pd.DataFrame = dataclasses.field(default_factory=lambda: pd.DataFrame(columns=list(TWIN_COLUMNS)))
    """An engine's rows off the CPU beside its rows on the CPU (:func:`truestep.measures.twins.twin_rows`)."""


Run = tuple[str, str, float, str, float]
"""(engine, method, dt, dt_kind, value): one row's value of a measure."""


@dataclass(frozen=True)
class Conclusion:
    """What one case's rows say, none of it timing (the same on every machine).

    runs : the rows that ran (not unsupported or skipped);  ok : those that ended ok
    most_accurate : the row of least error among the ok ones (``None`` without errors)
    least_drift, most_drift : the ok rows of least and greatest energy drift (up to three
    each, least first / greatest first), for a case whose energy is conserved
    failed : (engine, method, status, rows) for each engine/method with rows not ok
    """

    runs: int
    ok: int
    most_accurate: Run | None
    least_drift: list[Run]
    most_drift: list[Run]
    failed: list[tuple[str, str, str, int]]


def conclude(case: Case, results: pd.DataFrame) -> Conclusion:
    """The :class:`Conclusion` of ``case`` from its rows of ``results``."""
    rows = results[(results["case"] == case.name) & ~results["status"].isin(["unsupported", "skipped"])]
    ok = rows[rows["status"] == "ok"]

    def run(r: pd.Series, column: str) -> Run:
        return (str(r["engine"]), str(r["method"]), float(r["dt"]), str(r["dt_kind"]), float(r[column]))

    error = pd.to_numeric(ok["error"], errors="coerce")
    best = ok.loc[error.idxmin()] if error.notna().any() else None
    least: list[Run] = []
    most: list[Run] = []
    if case.conservative and "energy_drift" in ok:
        drift = ok.assign(d=pd.to_numeric(ok["energy_drift"], errors="coerce")).dropna(subset=["d"])
        drift = drift.sort_values(["d", "engine", "method", "dt"], kind="stable")
        least = [run(r, "d") for _, r in drift.head(3).iterrows()]
        rest = drift.iloc[len(least) :]
        most = [run(r, "d") for _, r in rest.iloc[::-1].head(3).iterrows()]
    failed = [
        (str(e), str(m), str(st), len(g))
        for (e, m, st), g in rows[rows["status"] != "ok"].groupby(["engine", "method", "status"], sort=False)
    ]
    return Conclusion(
        runs=len(rows),
        ok=len(ok),
        most_accurate=None if best is None else run(best, "error"),
        least_drift=least,
        most_drift=most,
        failed=failed,
    )


def find(cases: list[Case], results: pd.DataFrame, tables: dict[str, pd.DataFrame]) -> Findings:
    """The findings of a run: its cases, its results table and the analyses' ``tables``
    (``stability``, ``restitution``; either may be missing)."""
    return Findings(
        orders=orders_table(results, cases),
        cheapest=cheapest(results, cases),
        scorecard=scorecard(results, cases, tables.get("stability")),
        fidelity=restitution_fidelity(tables.get("restitution")),
        survival={c.name: survival(c, results) for c in cases if c.hard},
        speed=speed_tables(cases, results),
        conclusions={c.name: conclude(c, results) for c in cases},
        notes=method_notes(results),
        peers=same_scheme(results, cases),
        scene_set={c.name: why for c in cases if (why := scene_set_error(c, results)) is not None},
        shared_methods={c.name: m for c in cases if (m := shared_error_methods(c, results))},
        costly=costly_rows(results),
        phase_contact=phase_contact(tables.get("restitution")),
        floors={c.name: f for c in cases if (f := reference_floor(c)) is not None},
        twins=twin_rows(results, cases),
    )


def method_notes(results: pd.DataFrame) -> dict[tuple[str, str], str]:
    """(engine, method) -> its one-line ``method_notes`` entry, for every pair in
    ``results``: what the judged run recorded (:func:`~truestep.measures.engine_facts.take`),
    else what its installed adapter says (an engine not installed here, or whose adapter
    says nothing, has none)."""
    from truestep.adapters import EngineNotInstalled, UnknownEngine, adapter_class
    from truestep.measures.engine_facts import recorded_words

    notes: dict[tuple[str, str], str] = {}
    for engine, methods in results.groupby("engine", sort=False)["method"]:
        said = recorded_words(str(engine), "method_notes")
        try:
            if said is None:
                said = getattr(adapter_class(str(engine)), "method_notes", None) or {}
        except (UnknownEngine, EngineNotInstalled):
            continue
        for method in dict.fromkeys(methods.astype(str)):
            if isinstance(said.get(method), str):
                notes[(str(engine), method)] = said[method]
    return notes


def speed_tables(cases: list[Case], results: pd.DataFrame) -> dict[tuple[str, str], pd.DataFrame]:
    """(case name, the gate's ``where``) -> :func:`speed_table`, for each ``speedup`` gate."""
    return {
        (c.name, g.where): speed_table(c, results, g.engine, g.method)
        for c in cases
        for g in c.gates
        if GATE_KINDS[g.kind].speed
    }


def orders_table(results: pd.DataFrame, cases: list[Case]) -> pd.DataFrame:
    """Fitted order of convergence per case, engine and fixed-step method, beside the
    order its engine declares there (:mod:`truestep.measures.declared`; empty where none is
    declared: non-smooth scenes, no exact solution, a method exact on the case) and
    whether the fit is within the declared-order gates' tolerance of it. The declared orders
    are those ``truestep gate --declared-orders`` checks
    (:func:`~truestep.measures.declared.run_order_pairs`): the facts the run recorded where
    it recorded them, else the installed adapter's."""
    from truestep.measures.declared import DECLARED_ORDER_TOL, run_order_pairs

    declared = {
        (names[0], g.engine, g.method): g.params["expect"] for names, g in run_order_pairs(cases, results)
    }
    rows = []
    scales = {c.name: c.error_scale for c in cases}
    steps = results[(results["dt_kind"] == "step") & (results["status"] == "ok")]
    for (case, engine, method), g in steps.groupby(["case", "engine", "method"], sort=False):
        order = fit_order(
            g["dt"].astype(float),
            g["error"].astype(float),
            scale=scales.get(case, 1.0),
            floor=round_off_floor(str(engine)),
        )
        expect = declared.get((case, engine, method), np.nan)
        agrees = (
            ""
            if not (np.isfinite(expect) and np.isfinite(order))
            else ("yes" if order >= expect - DECLARED_ORDER_TOL else "no")
        )
        rows.append(
            {
                "case": case,
                "engine": engine,
                "method": method,
                "order": order,
                "declared": expect,
                "agrees": agrees,
                "points": int(g["error"].notna().sum()),
                "finest": finest_local_order(g["dt"].to_numpy(float), g["error"].to_numpy(float)),
            }
        )
    return pd.DataFrame(
        rows, columns=["case", "engine", "method", "order", "declared", "agrees", "points", "finest"]
    )


def speed_table(case: Case, results: pd.DataFrame, engine: str, method: str) -> pd.DataFrame:
    """Particle-steps per second of every engine/method beside ``engine/method``'s, per step.

    Columns: ``dt`` (s), ``engine``, ``method``, ``wall_s`` (s), ``particle_steps_per_s``
    (particles x steps / wall time), ``error`` and ``slower_by`` (that row's wall time over
    ``engine/method``'s at the same step). Rows with status ok, fixed steps only, whose wall
    time is a speed claim (:func:`truestep.measures.picks.speed_claims`).
    """
    n = case.bodies
    d = speed_claims(
        results[(results["case"] == case.name) & (results["dt_kind"] == "step") & (results["status"] == "ok")]
    ).dropna(subset=["wall_s"])
    rows = []
    for dt, g in d.groupby(d["dt"].astype(float)):
        base = g[(g["engine"] == engine) & (g["method"] == method)]
        base_wall = float(base["wall_s"].iloc[0]) if len(base) else np.nan
        for r in g.sort_values("wall_s").itertuples(index=False):
            rows.append(
                {
                    "dt": dt,
                    "engine": r.engine,
                    "method": r.method,
                    "wall_s": r.wall_s,
                    "particle_steps_per_s": n * r.steps / r.wall_s,
                    "error": r.error,
                    "slower_by": r.wall_s / base_wall,
                }
            )
    return pd.DataFrame(
        rows, columns=["dt", "engine", "method", "wall_s", "particle_steps_per_s", "error", "slower_by"]
    )
