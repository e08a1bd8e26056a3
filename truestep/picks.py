"""Which run to pick, read off the tables: the cheapest run that reaches an accuracy, and
the largest step that survives a hard case with its accuracy intact.

Both are pure functions of ``results.csv`` and the cases; the report's summary sentences
and its scorecard are made from them.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from truestep.cases.case import Case
from truestep.metrics import energy_behaviour

ACCURACY_TARGETS = (1e-2, 1e-4, 1e-6)
"""Accuracy targets, as fractions of each case's error scale (``[reference] scale``)."""
SURVIVAL_ERROR = 0.1
"""A run survives a hard case only if its error is at most this fraction of the case's
scale: a tenth of an orbit's radius, of a cloth's size. Beyond it the run is garbage
however stable it stayed (close-encounter at 1 ms: errors of 3 to 43 scales)."""
SURVIVAL_ENERGY = 1.0
"""... and its relative energy error is at most this: a bound three-body system whose
energy went from -2.4 J to +525 J has been blown apart, whatever its positions say."""
PICK_COLUMNS = ["case", "target", "error_needed", "by", "engine", "method", "dt", "dt_kind",
                "error", "wall_s", "nfev", "runs_reaching"]


def _num(frame: pd.DataFrame, column: str) -> np.ndarray:
    return pd.to_numeric(frame[column], errors="coerce").to_numpy(float)


def cheapest(results: pd.DataFrame, cases: list[Case],
             targets: tuple[float, ...] = ACCURACY_TARGETS) -> pd.DataFrame:
    """For each case with measured errors and each target: the cheapest ``ok`` run whose
    error is at most ``target x scale``, by wall time (``by = wall_s``) and by derivative
    evaluations (``by = nfev``). A target no run reaches is a row with an empty engine
    and ``runs_reaching`` 0. Columns :data:`PICK_COLUMNS`; ``error_needed`` in the
    case's error units."""
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
                base = {"case": case.name, "target": target, "error_needed": needed, "by": by,
                        "runs_reaching": len(reach)}
                cost = _num(reach, by)
                if not np.isfinite(cost).any():
                    rows.append({**base, "engine": "", "method": ""})
                    continue
                r = reach.iloc[int(np.nanargmin(cost))]
                rows.append({**base, **{k: r[k] for k in ("engine", "method", "dt", "dt_kind",
                                                          "error", "wall_s", "nfev")}})
    return pd.DataFrame(rows, columns=PICK_COLUMNS)


def outcome(case: Case, row: pd.Series) -> str:
    """Why a run does not survive the case, or ``""`` when it does: its status
    (``unstable``...), a failure the scene tests (``tunnelled``), ``inaccurate`` (error
    above :data:`SURVIVAL_ERROR` of the scale) or ``energy`` (relative energy error above
    :data:`SURVIVAL_ENERGY` in a scene without energy sources)."""
    from truestep.properties import FAILURES

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
        out.append({"engine": engine, "method": method,
                    "dt_survived": max(survived) if survived else np.nan,
                    "failure": outcomes[int(np.argmax(dts))]})
    return pd.DataFrame(out, columns=["engine", "method", "dt_survived", "failure"])
