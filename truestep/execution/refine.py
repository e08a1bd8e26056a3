"""Sweeps carried on to finer steps where a method's declared order is not reached yet.

A declared-order gate (``truestep gate --declared-orders``) fits an order to a method's
errors over the case's sweep. Some correct methods are not yet in their asymptotic range
there: Drake's third-order ``runge_kutta3`` and ``radau3`` on arenstorf-orbit fall well
below their order over the case's sweep (the orbit's close approaches), and reach it only
at finer steps. Judged on the case's sweep alone they would fail; a method that is
wrong (a flipped sign, a lost half step) stays below its order however fine the step.

:func:`refine` carries on to finer steps, halving the finest step of the case's sweep
each time, each method of a run (rows ``ok`` at every step) whose fit falls short of its
declared order, where either

- its error falls with the step at the sweep's finest steps (the ones the gate would
  fail), or
- its error does not fall there at all, well above the engine's round-off
  (:func:`~truestep.measures.metrics.flat_above_floor`): the gate could not judge such a
  sweep, and a user's solver with a rest length 1 % off (a flat error on
  spring-damper-pair) passed it; only finer steps tell a method that has not yet begun
  to converge (implicit Euler on mass-ratio-chain, flat over the sweep, falling only at
  finer steps) from one that converges to something else. A ``--quick`` run carries on
  only these, from half the finest step of the case's full sweep.

It adds the rows to the results, and stops once the fit reaches the declared order, once
the local order of a converging method stops rising (:func:`still_rising`: a method
converging at a lower order stays there), or after :data:`MAX_HALVINGS` halvings (a
method whose error does not fall yet is run at every one). The gate then reads the finer
errors: a method that reaches its order passes; one whose error stays flat however fine
the step, well above round-off, fails; one still rising at the last halving is not
evaluated, saying so. The work is bounded: at most ``MAX_HALVINGS`` runs of up to
``2 ** MAX_HALVINGS`` times the finest row's steps, for each method that needs them.
Which methods were carried on, and to which steps, goes to ``run.json`` (``refined``)
and the report.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from truestep.cases.case import Case
from truestep.measures.declared import declared_order_pairs
from truestep.measures.metrics import (
    CONVERGING,
    RISING,
    finest_local_order,
    fit_order,
    flat_above_floor,
    local_orders,
    round_off_floor,
)

if TYPE_CHECKING:
    from truestep.runtime.isolation import Lanes

MAX_HALVINGS = 4
"""The most finer steps a method short of its declared order is run at: the finest step
of the case's sweep halved, then halved again, ... (at most ``2 ** MAX_HALVINGS`` times
the finest row's steps)."""


@dataclasses.dataclass(frozen=True)
class Refinement:
    """One method carried on to finer steps: the case, engine and method, the order the
    case's sweep gave and the one declared, and the steps added (s)."""

    case: str
    engine: str
    method: str
    order: float
    declared: float
    tol: float
    dts: tuple[float, ...]

    def record(self) -> dict:
        """As ``run.json`` keeps it."""
        return {
            "case": self.case,
            "engine": self.engine,
            "method": self.method,
            "order": round(self.order, 4),
            "declared": self.declared,
            "dts": list(self.dts),
        }


def _rows(results: pd.DataFrame, case: str, engine: str, method: str) -> pd.DataFrame:
    return results[
        (results["case"] == case)
        & (results["engine"] == engine)
        & (results["method"] == method)
        & (results["dt_kind"] == "step")
    ]


def short_of_order(
    cases: list[Case], engines: list[str], results: pd.DataFrame, *, quick: bool = False
) -> list[Refinement]:
    """The methods whose rows (all ``ok``, on a case's fixed steps) fit an order below the
    declared one less its tolerance, and whose error at the sweep's finest steps either
    falls (:func:`_converging`: the gate would fail them) or does not fall at all, well
    above round-off (:func:`~truestep.measures.metrics.flat_above_floor`: the gate could not
    judge them, and only finer steps tell a method that has not started to converge from
    one that converges to something else). ``quick``: only the flat ones (a ``--quick``
    sweep's gates judge a short converging order as it is). ``dts`` empty: the steps are
    chosen as they run."""
    by_name = {c.name: c for c in cases}
    out = []
    for names, gate in declared_order_pairs(cases, engines, quick=quick):
        case = by_name[names[0]]
        rows = _rows(results, case.name, gate.engine, gate.method)
        if not len(rows) or not (rows["status"] == "ok").all():
            continue  # a failed row is a verdict of its own; finer steps do not change it
        order = _order(case, gate.engine, rows)
        expect, tol = float(gate.params["expect"]), float(gate.params["tol"])
        if not (np.isfinite(order) and order < expect - tol):
            continue
        if _flat(case, gate.engine, rows) or (not quick and _converging(rows)):
            out.append(Refinement(case.name, gate.engine, gate.method, order, expect, tol, ()))
    return out


def _converging(rows: pd.DataFrame) -> bool:
    """Whether the error falls with the step at the sweep's finest steps (a local order of
    :data:`~truestep.measures.metrics.CONVERGING` or more)."""
    return bool(finest_local_order(rows["dt"].to_numpy(float), rows["error"].to_numpy(float)) >= CONVERGING)


def _flat(case: Case, engine: str, rows: pd.DataFrame) -> bool:
    """Whether the error does not fall at the sweep's finest steps, well above the engine's
    round-off (:func:`~truestep.measures.metrics.flat_above_floor`): a rest length 1 %
    off gives a flat 1.3e-2 m on spring-damper-pair; implicit Euler on mass-ratio-chain a
    flat 0.04 m (it damps the chain's fast mode away at every swept step, and starts to
    converge at finer ones)."""
    return flat_above_floor(
        rows["dt"].to_numpy(float),
        rows["error"].to_numpy(float),
        scale=case.error_scale,
        floor=round_off_floor(engine),
    )


def _order(case: Case, engine: str, rows: pd.DataFrame) -> float:
    dts, errors = rows["dt"].to_numpy(float), rows["error"].to_numpy(float)
    return fit_order(dts, errors, scale=case.error_scale, floor=round_off_floor(engine))


def still_rising(dts: np.ndarray, errors: np.ndarray) -> bool:
    """Whether the local orders (:func:`~truestep.measures.metrics.local_orders`) of the
    two finest pairs grow by :data:`RISING` or more: a method on its way to its order."""
    ok = np.isfinite(errors) & (errors > 0)
    local = local_orders(dts[ok], errors[ok])
    return len(local) >= 2 and local[-1] >= local[-2] + RISING


def refine(
    cases: list[Case],
    engines: list[str],
    results: pd.DataFrame,
    *,
    quick: bool,
    say: Callable[[str], None] | None = None,
    lanes: Lanes | None = None,
) -> tuple[pd.DataFrame, list[Refinement]]:
    """``results`` with rows at finer steps for every method :func:`short_of_order` names
    (each after its own rows), and those methods; in a ``--quick`` run only the flat ones
    (:func:`short_of_order`), timed as the quick run times. The first finer step is half
    the finest of the case's full sweep (in a ``--quick`` run too, so that the gate knows
    those rows for steps finer than any sweep of the case). The runs go through ``lanes``
    where it is given (:func:`~truestep.execution.runner.run_sweep`)."""
    from truestep.execution.runner import Timing, run_sweep, tidy
    from truestep.execution.sweep_job import host_name
    from truestep.execution.timing import QUICK_TIMING

    wanted = short_of_order(cases, engines, results, quick=quick)
    if not wanted:
        return results, []
    by_name, here = {c.name: c for c in cases}, host_name()
    parts, done = [results], []
    for r in wanted:
        case, added = by_name[r.case], []
        rows = _rows(results, r.case, r.engine, r.method)
        finest = min([float(rows["dt"].min()), *(float(d) for d in getattr(case, "dts", ()))])
        for _ in range(MAX_HALVINGS):
            dt = min(float(rows["dt"].min()), finest) / 2
            if say is not None:
                say(
                    f"refining {r.case} {r.engine}/{r.method}: order {_order(case, r.engine, rows):.3g} "
                    f"so far, declared {r.declared:g}; running dt {dt:.4g}"
                )
            timing = QUICK_TIMING if quick else Timing()
            swept = run_sweep(case, r.engine, r.method, [dt], adaptive=False, timing=timing, lanes=lanes)
            new = tidy([{**row, "host": here} for row in swept], cases)
            added.append(dt)
            parts.append(new)
            rows = pd.concat([rows, new], ignore_index=True)
            if (rows["status"] != "ok").any():
                break  # its own verdict
            if _order(case, r.engine, rows) >= r.declared - r.tol:
                break  # reached
            dts, errors = rows["dt"].to_numpy(float), rows["error"].to_numpy(float)
            if finest_local_order(dts, errors) < CONVERGING:
                continue  # not falling yet: every halving, to tell late from never
            if not still_rising(dts, errors):
                break  # converging short of its order: finer steps would not change the verdict
        done.append(dataclasses.replace(r, dts=tuple(added)))
    merged = pd.concat(parts, ignore_index=True)
    merged = merged.assign(_i=np.arange(len(merged)))
    first = merged.groupby(["case", "engine", "method"], sort=False)["_i"].transform("min")
    merged = merged.assign(_f=first).sort_values(["_f", "_i"], kind="stable")
    out = merged.drop(columns=["_i", "_f"]).reset_index(drop=True)
    out.attrs = dict(results.attrs)
    return out, done
