"""Check each case's gates against the tables ``truestep run`` wrote."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from truestep.cases.case import Case, Gate
from truestep.metrics import fit_order


@dataclass
class GateResult:
    """One gate's verdict: what it read, what it needed, and whether it held."""

    case: str
    gate: Gate
    passed: bool
    measured: str
    required: str
    evaluated: bool = True

    def line(self) -> str:
        g = self.gate
        dt = f" dt={g.dt:g}" if g.dt is not None else ""
        verdict = "SKIP" if not self.evaluated else "ok  " if self.passed else "FAIL"
        return (f"{verdict} {self.case} {g.where} {g.kind} {g.engine}/{g.method}{dt}: "
                f"measured {self.measured}, required {self.required}")


def _rows(results: pd.DataFrame, case: str, g: Gate) -> pd.DataFrame:
    r = results[(results["case"] == case) & (results["engine"] == g.engine)
                & (results["method"] == g.method)]
    if g.dt is not None:
        r = r[np.isclose(r["dt"].astype(float), g.dt, rtol=1e-9, atol=0)]
    return r


def _within(value: float, lo: float | None, hi: float | None) -> bool:
    return bool(np.isfinite(value) and (lo is None or value >= lo) and (hi is None or value <= hi))


def check_gate(case: Case, g: Gate, results: pd.DataFrame,
               stability: pd.DataFrame | None = None) -> GateResult:
    """Evaluate one gate; a gate with no row to read fails, saying so.

    A gate whose case or engine the run left out altogether (``--cases``, ``--engines``)
    is not evaluated and says so.
    """
    p = g.params
    ran = results[(results["case"] == case.name) & (results["engine"] == g.engine)]
    if not len(ran):
        return GateResult(case.name, g, True, "not run", "a run of this case and engine",
                          evaluated=False)
    rows = _rows(results, case.name, g)
    if g.kind == "stability-limit":
        s = pd.DataFrame() if stability is None else stability
        s = s[(s["case"] == case.name) & (s["engine"] == g.engine) & (s["method"] == g.method)] \
            if len(s) else s
        if not len(s):
            return GateResult(case.name, g, False, "no stability row", f"within {p['rel_tol']:g} of exact")
        limit, exact = float(s["dt_limit"].iloc[0]), float(s["dt_limit_exact"].iloc[0])
        rel = abs(limit - exact) / exact if np.isfinite(exact) and exact > 0 else np.nan
        return GateResult(case.name, g, _within(rel, None, p["rel_tol"]),
                          f"dt_limit {limit:.6g} (exact {exact:.6g}, off by {rel:.3%})",
                          f"within {p['rel_tol']:.3%}")
    if not len(rows):
        return GateResult(case.name, g, False, "no result row", "a row to read")
    if g.kind == "order":
        ok = rows[(rows["status"] == "ok") & (rows["dt_kind"] == "step")]
        order = fit_order(ok["dt"].astype(float), ok["error"].astype(float), scale=case.error_scale)
        return GateResult(case.name, g, _within(abs(order - p["expect"]), None, p["tol"]),
                          f"order {order:.3f}", f"{p['expect']:g} +- {p['tol']:g}")
    row = rows.iloc[0]
    if g.kind == "status":
        return GateResult(case.name, g, row["status"] == p["expect"], str(row["status"]),
                          str(p["expect"]))
    if row["status"] != "ok":
        return GateResult(case.name, g, False, f"status {row['status']}", "status ok")
    if g.kind in ("error", "energy_drift"):
        value = float(row[g.kind])
        return GateResult(case.name, g, _within(value, None, p["max"]), f"{g.kind} {value:.3g}",
                          f"<= {p['max']:g}")
    if g.kind == "property":
        name = p["name"]
        value = float(row[name]) if name in row else np.nan
        lo, hi = p.get("min"), p.get("max")
        bounds = " and ".join(s for s in (f">= {lo:g}" if lo is not None else "",
                                          f"<= {hi:g}" if hi is not None else "") if s)
        return GateResult(case.name, g, _within(value, lo, hi), f"{name} {value:.4g}", bounds)
    if g.kind == "speedup":
        ratios = []
        for other in p["over"]:
            o = results[(results["case"] == case.name) & (results["engine"] == other)
                        & (results["status"] == "ok")
                        & np.isclose(results["dt"].astype(float), g.dt, rtol=1e-9, atol=0)]
            if len(o):
                ratios.append(float(o["wall_s"].min()) / float(row["wall_s"]))
        value = min(ratios) if ratios else np.nan
        return GateResult(case.name, g, _within(value, p["min"], None),
                          f"speed-up {value:.3g}x over {', '.join(p['over'])}", f">= {p['min']:g}x")
    raise ValueError(f"{case.file}: {g.where}.kind: unknown gate kind {g.kind!r}")


def check_gates(cases: list[Case], results: pd.DataFrame,
                stability: pd.DataFrame | None = None) -> list[GateResult]:
    """Every gate of every case, in case order."""
    return [check_gate(c, g, results, stability) for c in cases for g in c.gates]
