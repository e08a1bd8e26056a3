"""Check gates (from case files and gates files) against the tables ``truestep run`` wrote.

A gate names the rows it reads by case, engine, method and step; ``*`` for the engine or
the method stands for every engine (every method) that ran the case, and the gate is
checked once for each. Each check is a :class:`GateResult`: held, failed, or not
evaluated (the run left that case or engine out). A row the gate reads that ``crashed``
or timed out fails the gate: a gate that checked nothing has not passed.
"""

from __future__ import annotations

import dataclasses
import fnmatch
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import PurePath

import numpy as np
import pandas as pd

from truestep.cases.case import Case, Gate
from truestep.cases.gate_kinds import GATE_KINDS
from truestep.measures.metrics import (
    ABOVE_FLOOR,
    CONVERGING,
    RISING,
    ROUND_OFF,
    fit_order,
    flat_above_floor,
    precision_of,
    round_off_floor,
)

NOT_RUN = frozenset({"unsupported", "skipped"})
"""Row statuses of pairs the run did not simulate."""
BROKEN = frozenset({"crashed", "timeout"})
"""Row statuses of runs that produced nothing to measure."""
DECLARED = "declared"
"""The ``where`` of the gates :mod:`truestep.measures.declared` makes from the methods' facts. A
sweep that gives no fittable order (unstable, or not yet converged, at every step) leaves
such a gate not evaluated: the case's own gates and the baseline say what went wrong."""
GATE_COLUMNS = [
    "case",
    "source",
    "gate",
    "kind",
    "engine",
    "method",
    "dt",
    "verdict",
    "measured",
    "required",
    "id",
    "value",
]
"""The columns of :func:`verdict_table` (and of ``truestep gate --json``'s gates): ``id``
(:attr:`GateResult.id`, the same from run to run), ``value`` (the measured number, or
empty where the gate reads a status or found nothing to measure)."""


@dataclass
class GateResult:
    """One gate's verdict on one engine and method: what it read, what it needed, and
    whether it held (``evaluated`` is false when the run has no rows for it)."""

    case: str
    gate: Gate
    passed: bool
    measured: str
    required: str
    evaluated: bool = True
    value: float | None = None
    """The measured number the verdict rests on (the error, the fitted order, the limit,
    the speed-up ...), ``None`` where there is none."""
    id: str = ""
    """Set by :func:`check_gates`: see :func:`gate_id`."""

    @property
    def verdict(self) -> str:
        """``pass``, ``fail`` or ``skip``."""
        return "skip" if not self.evaluated else "pass" if self.passed else "fail"

    @property
    def label(self) -> str:
        """``<id> (gates[i] of <file name>)``: the verdict's id (:func:`gate_id`, as JUnit,
        JSON and the pytest plugin name it), then where it is declared."""
        g = self.gate
        of = f" of {PurePath(g.file).name}" if g.file and not g.file.startswith("<") else ""
        return f"{self.id or gate_id(self.case, g)} ({g.where}{of})"

    def row(self) -> dict:
        """This verdict as a row of the verdict table (:data:`GATE_COLUMNS`, in order)."""
        value = None if self.value is None or not np.isfinite(self.value) else float(self.value)
        return {
            "case": self.case,
            "source": self.gate.file,
            "gate": self.gate.where,
            "kind": self.gate.kind,
            "engine": self.gate.engine,
            "method": self.gate.method,
            "dt": self.gate.dt,
            "verdict": self.verdict,
            "measured": self.measured,
            "required": self.required,
            "id": self.id or gate_id(self.case, self.gate),
            "value": value,
        }

    def line(self) -> str:
        verdict = {"skip": "SKIP", "pass": "ok  ", "fail": "FAIL"}[self.verdict]
        return f"{verdict} {self.label}: measured {self.measured}, required {self.required}"


def _num(series: pd.Series) -> np.ndarray:
    return pd.to_numeric(series, errors="coerce").to_numpy(float)


def _at_dt(rows: pd.DataFrame, dt: float | None) -> pd.DataFrame:
    if dt is None or not len(rows):
        return rows
    return rows[np.isclose(_num(rows["dt"]), dt, rtol=1e-9, atol=0)]


def _within(value: float, lo: float | None, hi: float | None) -> bool:
    return bool(np.isfinite(value) and (lo is None or value >= lo) and (hi is None or value <= hi))


def _pairs(results: pd.DataFrame, case: str, g: Gate) -> list[tuple[str, str]]:
    """The (engine, method) pairs a gate stands for: itself, or what ``*`` expands to
    among the pairs the run simulated for ``case`` (at the gate's ``dt``, if it names one;
    with fixed steps, for an order gate)."""
    if g.engine != "*" and g.method != "*":
        return [(g.engine, g.method)]
    ran = results[(results["case"] == case) & ~results["status"].isin(NOT_RUN)]
    if g.dt is not None:
        ran = _at_dt(ran, g.dt)
    elif GATE_KINDS[g.kind].steps_only:
        ran = ran[ran["dt_kind"] == "step"]
    pairs = ran[["engine", "method"]].drop_duplicates().itertuples(index=False)
    return [(e, m) for e, m in pairs if g.engine in ("*", e) and g.method in ("*", m)]


def _status(row: pd.Series) -> str:
    """``status unstable at t=0.31 s`` (the time when the row has one)."""
    t = pd.to_numeric(pd.Series([row.get("t_fail")]), errors="coerce").iloc[0]
    return f"status {row['status']}" + (f" at t={t:.4g} s" if np.isfinite(t) else "")


def _broken(rows: pd.DataFrame) -> str | None:
    bad = rows[rows["status"].isin(BROKEN)]
    if not len(bad):
        return None
    r = bad.iloc[0]
    message = str(r.get("message", "") or "")
    return f"row dt={r['dt']} {r['status']}" + (f" ({message[:120]})" if message else "")


def check_gate(
    case: Case,
    g: Gate,
    results: pd.DataFrame,
    stability: pd.DataFrame | None = None,
    restitution: pd.DataFrame | None = None,
) -> GateResult:
    """Evaluate one gate for one engine and method (no ``*``); a gate with no row to read
    fails, saying so, and a gate whose case or engine the run left out altogether
    (``--cases``, ``--engines``) is not evaluated and says so."""
    kind = GATE_KINDS.get(g.kind)
    if kind is None:
        raise ValueError(f"{g.file or case.file}: {g.where}.kind: unknown gate kind {g.kind!r}")
    ran = results[(results["case"] == case.name) & (results["engine"] == g.engine)]
    if kind.reads == "restitution":
        return _restitution(case.name, g, restitution)
    if not len(ran):
        return GateResult(case.name, g, True, "not run", "a run of this case and engine", evaluated=False)
    rows = ran[ran["method"] == g.method]
    if kind.reads == "stability":
        return _stability(case, g, stability)
    if not len(rows):
        return GateResult(case.name, g, False, "no result row", "a row to read")
    if rows["status"].isin(NOT_RUN).all():
        r = rows.iloc[0]
        why = r.get("missing") if r["status"] == "unsupported" else r.get("message")
        return GateResult(case.name, g, False, f"{r['status']} ({why})", "a run to read")
    if kind.reads == "sweep":
        return CHECKS[g.kind](case, g, results, rows)
    at_dt = _at_dt(rows, g.dt)
    if not len(at_dt):
        return quick_only(case, g, results[results["case"] == case.name]) or GateResult(
            case.name, g, False, "no result row at this dt", "a row to read"
        )
    row = at_dt.iloc[0]
    if row["status"] in BROKEN:
        return GateResult(case.name, g, False, _broken(at_dt) or str(row["status"]), "a measured row")
    if not kind.any_status and row["status"] != "ok":
        return GateResult(case.name, g, False, _status(row), "status ok")
    return CHECKS[g.kind](case, g, results, at_dt)


def _status_is(case: Case, g: Gate, results: pd.DataFrame, rows: pd.DataFrame) -> GateResult:
    """A ``status`` gate: the row at its step has the status it expects."""
    status = rows.iloc[0]["status"]
    return GateResult(case.name, g, status == g.params["expect"], str(status), str(g.params["expect"]))


def _measured(case: Case, g: Gate, results: pd.DataFrame, rows: pd.DataFrame) -> GateResult:
    """An ``error`` or ``energy_drift`` gate: the row's value at most ``max`` (a case on
    which no engine ever measures it says so)."""
    value = float(_num(rows[g.kind])[0])
    ran = results[(results["case"] == case.name) & (results["status"] == "ok")]
    never = not np.isfinite(value) and not np.isfinite(_num(ran[g.kind])).any()
    return GateResult(
        case.name,
        g,
        _within(value, None, g.params["max"]),
        f"nothing: {g.kind} is never measured on this case (no ok row of any engine has one: "
        f"{GATE_KINDS[g.kind].unmeasured})"
        if never
        else f"{g.kind} {value:.3g}",
        f"<= {g.params['max']:g}",
        value=value,
    )


QUICK_ONLY = "not in this --quick run"
"""How the verdict of a gate that only a full run can evaluate begins (:func:`quick_only`)."""


def quick_only(case: Case, g: Gate, rows: pd.DataFrame) -> GateResult | None:
    """The verdict of a gate at a step that only the case's full sweep runs, read from a
    ``--quick`` run (``rows``, the run's rows of the case, all at steps of its quick sweep):
    not evaluated, saying so; ``None`` for any other gate. A full run evaluates it."""
    quick = [float(s) for s in (*getattr(case, "quick_dts", ()), *getattr(case, "quick_tolerances", ()))]
    if g.dt is None or not quick or not len(rows) or _in(g.dt, quick):
        return None
    if not all(_in(float(dt), quick) for dt in _num(rows["dt"]) if np.isfinite(dt)):
        return None
    return GateResult(
        case.name,
        g,
        True,
        f"{QUICK_ONLY}: dt={g.dt:g} is a step of the full sweep only",
        f"a full run (the quick sweep runs {', '.join(f'{s:g}' for s in sorted(quick))})",
        evaluated=False,
    )


def _in(dt: float, steps: list[float]) -> bool:
    return any(abs(dt - s) <= 1e-9 * s for s in steps)


def _carried_on(case: Case, rows: pd.DataFrame) -> pd.Series:
    """Which of ``rows`` are at a fixed step finer than any of the case's sweep: the ones
    :mod:`truestep.execution.refine` added."""
    sweep = [float(d) for d in getattr(case, "dts", ())]
    if not sweep:
        return pd.Series(False, index=rows.index)
    return (rows["dt_kind"] == "step") & (_num(rows["dt"]) < min(sweep) * (1 - 1e-9))


def _order(case: Case, g: Gate, rows: pd.DataFrame, results: pd.DataFrame | None = None) -> GateResult:
    """An ``order`` gate on one method's sweep: the order fitted to its measured rows
    (``results``: the whole run, whose other methods a declared-order gate compares with).
    A declared-order gate leaves out a run that timed out at a step finer than the case's
    sweep (:func:`_carried_on`): a limit on what carrying it on costs, not a verdict."""
    p = g.params
    if g.where == DECLARED:
        rows = rows[~(_carried_on(case, rows) & (rows["status"] == "timeout"))]
    broken = _broken(rows)
    if broken:
        return GateResult(case.name, g, False, broken, "every row of the sweep measured")
    ok = rows[(rows["status"] == "ok") & (rows["dt_kind"] == "step")]
    floor = round_off_floor(str(rows["engine"].iloc[0])) if len(rows) else ROUND_OFF
    order = fit_order(_num(ok["dt"]), _num(ok["error"]), scale=case.error_scale, floor=floor)
    if g.where == DECLARED and g.params.get("exact"):
        return _declared_exact(case, g, rows, floor)
    if g.where == DECLARED:
        return (
            _unstable_where_stable(case, g, rows)
            or (_unstable_unexplained(case, g, rows, results) if not np.isfinite(order) else None)
            or _declared_order(case, g, ok, order)
        )
    if not np.isfinite(order):
        unstable = int((rows["status"] == "unstable").sum())
        why = (
            f"{unstable} of {len(rows)} runs unstable"
            if unstable
            else "fewer than two errors in the asymptotic range"
        )
        return GateResult(case.name, g, False, f"no order: {why}", f"{p['expect']:g} +- {p['tol']:g}")
    return GateResult(
        case.name,
        g,
        _within(abs(order - p["expect"]), None, p["tol"]),
        f"order {order:.3f}",
        f"{p['expect']:g} +- {p['tol']:g}",
        value=order,
    )


def _property(case: Case, g: Gate, rows: pd.DataFrame) -> GateResult:
    """A ``property`` gate: the named property of the row at the gate's step, in bounds."""
    p = g.params
    name = p["name"]
    value = float(_num(rows[name])[0]) if name in rows else np.nan
    lo, hi = p.get("min"), p.get("max")
    bounds = " and ".join(
        s for s in (f">= {lo:g}" if lo is not None else "", f"<= {hi:g}" if hi is not None else "") if s
    )
    return GateResult(case.name, g, _within(value, lo, hi), f"{name} {value:.4g}", bounds, value=value)


def _speedup(case: Case, g: Gate, results: pd.DataFrame, row: pd.Series) -> GateResult:
    """A ``speedup`` gate: the row's speed-up over each engine of ``over``, at the same step,
    timed on the same host (the smallest counts)."""
    p = g.params
    ratios, elsewhere = [], []
    for other in p["over"]:
        o = _at_dt(
            results[
                (results["case"] == case.name) & (results["engine"] == other) & (results["status"] == "ok")
            ],
            g.dt,
        )
        if "host" in o and "host" in row.index:  # wall times compare within one machine
            here = "" if pd.isna(row["host"]) else str(row["host"])
            same = o["host"].fillna("").astype(str) == here
            elsewhere += [other] if len(o) and not same.any() else []
            o = o[same]
        if len(o):
            ratios.append(float(np.nanmin(_num(o["wall_s"]))) / float(row["wall_s"]))
    value = min(ratios) if ratios and not elsewhere else np.nan
    where = f" ({', '.join(elsewhere)} timed on another host: not compared)" if elsewhere else ""
    return GateResult(
        case.name,
        g,
        _within(value, p["min"], None),
        f"speed-up {value:.3g}x over {', '.join(p['over'])}{where}",
        f">= {p['min']:g}x",
        value=value,
    )


def _stability(case: Case, g: Gate, stability: pd.DataFrame | None) -> GateResult:
    p = g.params
    need = " and ".join(
        s
        for s in (
            f"within {p['rel_tol']:.3%} of exact" if "rel_tol" in p else "",
            f">= {p['min']:g} s" if "min" in p else "",
        )
        if s
    )
    s = pd.DataFrame() if stability is None else stability
    if len(s):
        s = s[(s["case"] == case.name) & (s["engine"] == g.engine) & (s["method"] == g.method)]
    if not len(s):
        return GateResult(case.name, g, False, "no stability row", need)
    r = s.iloc[0]
    if r.get("status", "ok") != "ok":
        return GateResult(case.name, g, False, f"search {r['status']}: {r.get('note', '')}", need)
    limit, exact = float(r["dt_limit"]), float(r["dt_limit_exact"])
    ok, text = np.isfinite(limit), f"dt_limit {limit:.6g}"
    if "rel_tol" in p:
        rel = abs(limit - exact) / exact if np.isfinite(exact) and exact > 0 else np.nan
        ok = ok and _within(rel, None, p["rel_tol"])
        text += f" (exact {exact:.6g}, off by {rel:.3%})"
    if "min" in p:
        ok = ok and limit >= p["min"]
    return GateResult(case.name, g, bool(ok), text, need, value=limit)


STABLE_MARGIN = 0.99
"""A run is held to its method's exact stability limit at steps up to this fraction of it
(a step a hair below the limit grows too slowly to matter; one 1 % below does not grow)."""


def _unstable_where_stable(case: Case, g: Gate, rows: pd.DataFrame) -> GateResult | None:
    """A declared-order gate's verdict where its sweep has a run ``unstable`` at a step its
    method's facts say is stable on this linear scene (at or below :data:`STABLE_MARGIN` of
    the exact limit, :func:`truestep.cases.exact.stability_limit`): failed, naming the step
    and the limit. Such a sweep shows no order, and saying "not evaluated" would let the
    bug that made it unstable through (a damper's sign flipped). ``None`` otherwise: no
    such run, or no exact limit known (a nonlinear scene, an engine neither installed here
    nor with facts recorded by its run, :mod:`truestep.measures.engine_facts`)."""
    unstable = rows[(rows["status"] == "unstable") & (rows["dt_kind"] == "step")]
    if not len(unstable):
        return None
    from truestep.adapters import EngineNotInstalled, UnknownEngine, get_adapter
    from truestep.adapters.base import facts_of
    from truestep.cases.exact import stability_limit
    from truestep.measures.engine_facts import recorded_facts, recorded_limit

    known, facts = recorded_facts(g.engine, g.method)  # the judged run's facts win
    if not known:
        try:
            facts = facts_of(get_adapter(g.engine), g.method)
        except (EngineNotInstalled, UnknownEngine):
            return None
    exact = recorded_limit(g.engine, g.method, case.name) if known else None
    if exact is None:
        exact = stability_limit(case, facts) if facts is not None else None
    if exact is None or not (np.isfinite(exact) or exact == np.inf) or exact <= 0:
        return None
    dts = np.sort(_num(unstable["dt"]))
    below = dts[dts <= STABLE_MARGIN * exact]
    if not len(below):
        return None
    limit = "every step" if exact == np.inf else f"steps up to {exact:.6g} s"
    return GateResult(
        case.name,
        g,
        False,
        f"unstable at dt {below[0]:.6g} s, where its facts say it is stable ({limit} on this "
        "linear scene): no order to fit, and the instability is the finding",
        f">= {g.params['expect']:g} - {g.params['tol']:g}",
    )


def _judged_facts(g: Gate):
    """``(known, facts)`` of the gate's engine and method: the judged run's recorded facts,
    else the installed adapter's; ``known`` is false where neither can be read."""
    from truestep.adapters import EngineNotInstalled, UnknownEngine, get_adapter
    from truestep.adapters.base import facts_of
    from truestep.measures.engine_facts import recorded_facts

    known, facts = recorded_facts(g.engine, g.method)
    if known:
        return True, facts
    try:
        return True, facts_of(get_adapter(g.engine), g.method)
    except (EngineNotInstalled, UnknownEngine):
        return False, None


def _unstable_unexplained(
    case: Case, g: Gate, rows: pd.DataFrame, results: pd.DataFrame | None
) -> GateResult | None:
    """A declared-order gate's verdict where its sweep shows no order because its finest
    step is ``unstable`` though a method no more stable than it ran ``ok`` on the same case
    at that step or a larger one: failed, naming both. Where the scene's exact stability
    limit is unknown (a spring with a rest length, a nonlinear scene), that is the
    evidence left that the instability is not the step's: a method whose declared reach
    on undamped modes (:attr:`~truestep.reference_impl.solvers.Stability.imaginary`) is at
    most this one's stays stable there (a flipped damper, which saying "not evaluated"
    would let through). ``None`` otherwise: the finest step is not unstable; the method's
    facts cannot be read, declare no stability or say it is unstable on every undamped
    mode (explicit Euler); or no such method ran stable (a chaotic close encounter, where
    the methods of less reach go unstable too)."""
    steps = rows[rows["dt_kind"] == "step"]
    dts = _num(steps["dt"])
    if results is None or not len(steps) or not np.isfinite(dts).any():
        return None
    finest = steps.iloc[int(np.nanargmin(dts))]
    known, facts = _judged_facts(g)
    mine = facts.stability if known and facts is not None else None
    if finest["status"] != "unstable" or mine is None or mine.imaginary == 0:
        return None
    dt = float(finest["dt"])
    ran = results[
        (results["case"] == case.name) & (results["dt_kind"] == "step") & (results["status"] == "ok")
    ]
    ran = ran[_num(ran["dt"]) >= dt * (1 - 1e-9)]
    for (engine, method), done in ran.groupby(["engine", "method"], sort=True):
        if (engine, method) == (g.engine, g.method):
            continue
        seen, other = _judged_facts(dataclasses.replace(g, engine=str(engine), method=str(method)))
        theirs = other.stability if seen and other is not None else None
        if theirs is not None and 0 < theirs.imaginary <= mine.imaginary:
            step = float(_num(done["dt"]).max())
            return GateResult(
                case.name,
                g,
                False,
                f"unstable at the sweep's finest step, dt {dt:.6g} s, where {engine}/{method}, no more "
                f"stable on undamped modes (its reach {theirs.imaginary:.3g} against {mine.imaginary:.3g}), "
                f"ran ok up to dt {step:.6g} s: no order to fit, and the instability is the finding",
                f">= {g.params['expect']:g} - {g.params['tol']:g}",
            )
    return None


def _declared_exact(case: Case, g: Gate, rows: pd.DataFrame, floor: float) -> GateResult:
    """A declared-order gate of a method its facts make exact on the case (a constant
    acceleration, integrated exactly by every Runge-Kutta method of order 2 or more and by
    the lecture's update): every fixed-step run ``ok`` with its error at round-off (below
    ``floor`` of the case's scale, :func:`~truestep.measures.metrics.round_off_floor`). Such
    a sweep has no order to fit; a bug that breaks the exactness (a lost half step) is an
    error above round-off, which fails it."""
    need = f"exact: every error below {floor:g} of the scale (its facts: exact under a constant acceleration)"
    steps = rows[rows["dt_kind"] == "step"]
    if not len(steps):
        return GateResult(case.name, g, True, "no run at a fixed step", need, evaluated=False)
    bad = steps[steps["status"] != "ok"]
    if len(bad):
        row = bad.iloc[0]
        return GateResult(case.name, g, False, f"{row['status']} at dt {float(row['dt']):.6g} s", need)
    errors = _num(steps["error"])
    worst = float(np.max(errors)) if np.isfinite(errors).all() else float("nan")
    relative = worst / case.error_scale
    return GateResult(
        case.name,
        g,
        bool(relative <= floor),
        f"largest error {worst:.3g} ({relative:.3g} of the scale) over {len(steps)} steps",
        need,
        value=relative,
    )


def _round_off_at_finest(
    case: Case, g: Gate, dts: np.ndarray, errors: np.ndarray, local: float
) -> str | None:
    """Why the errors of a method carried on to finer steps (:mod:`truestep.execution.refine`)
    say nothing of its order at the finest of them, if they do not: the two finest within
    :data:`~truestep.measures.metrics.ABOVE_FLOOR` times the engine's round-off floor, or,
    for an engine whose state is float32, an error that grows as the step shrinks (by a
    local order of ``-RISING`` or less: rounding adding up over more steps; Newton's VBD on
    rope-pendulum from 0.071 at 0.25 ms to 0.53 at 0.125 ms, its next run stalled). An
    error that does not fall, well above rounding, is the method's, and the gate fails it."""
    if not flat_above_floor(dts, errors, scale=case.error_scale, floor=round_off_floor(str(g.engine))):
        return (
            f"no order: the errors at the finest steps are within {ABOVE_FLOOR:g} times the "
            "engine's round-off floor"
        )
    if local <= -RISING and precision_of(str(g.engine)) == "float32":
        return (
            f"no order: the error grows as the step shrinks (dt^{local:.2f} at "
            f"{float(np.min(dts)):.4g} s): float32 rounding, adding up over more steps, "
            "outweighs the method's error there"
        )
    return None


def _declared_order(case: Case, g: Gate, ok: pd.DataFrame, order: float) -> GateResult:
    """A declared-order gate: the fitted order at least the declared one, less ``tol``.

    Not evaluated (saying why) where the sweep cannot show an order: fewer than two errors
    in the asymptotic range, or errors that do not yet fall with the step at the finest
    steps (a local order below :data:`CONVERGING`); but failed where such errors come from
    steps finer than the case's sweep (:mod:`truestep.execution.refine` carried it on
    there) and their local order no longer rises (by
    :data:`~truestep.measures.metrics.RISING`) and are not round-off's
    (:func:`_round_off_at_finest`): a method whose error stays flat however fine the step
    is wrong, not early (a rest length 1 % off: a flat 1.3e-2 m on spring-damper-pair).
    A method whose error falls faster over the sweep than its declared order says
    (symplectic Euler's second-order term outweighing its first-order one on a chain down
    to 1e-4 s) holds it: the declared order is the least it delivers."""
    p = g.params
    need = f">= {p['expect']:g} - {p['tol']:g}"
    if not np.isfinite(order):
        return GateResult(
            case.name,
            g,
            True,
            "no order: fewer than two errors in the asymptotic range",
            need,
            evaluated=False,
        )
    from truestep.measures.metrics import local_orders

    dts, errors = _num(ok["dt"]), _num(ok["error"])
    usable = np.isfinite(errors) & (errors > 0)
    local = local_orders(dts[usable], errors[usable])
    finer = bool(_carried_on(case, ok).any())  # carried on: execution.refine
    rising = len(local) >= 2 and local[-1] >= local[-2] + RISING
    if finer and rising and order < p["expect"] - p["tol"]:
        return GateResult(
            case.name,
            g,
            True,
            f"no order yet: {order:.3f} so far, the local order still rising at {float(np.min(dts)):.4g} s "
            "(carried on finer than the case's sweep as far as truestep goes)",
            need,
            evaluated=False,
        )
    if len(local) and local[-1] < CONVERGING:
        if finer and (why := _round_off_at_finest(case, g, dts[usable], errors[usable], local[-1])):
            return GateResult(case.name, g, True, why, need, evaluated=False)
        if finer and not rising:
            return GateResult(
                case.name,
                g,
                False,
                f"no order: the error falls as dt^{local[-1]:.2f} even at "
                f"{float(np.min(dts)):.4g} s, finer than the case's sweep (the method does not "
                "converge as declared)",
                need,
                value=order,
            )
        return GateResult(
            case.name,
            g,
            True,
            f"no order yet: the error falls as dt^"
            f"{local[-1]:.2f} at the finest steps (the sweep is not in the "
            "asymptotic range"
            + (
                f"; still rising at {float(np.min(dts)):.4g} s, finer than the case's sweep)"
                if finer
                else ")"
            ),
            need,
            evaluated=False,
        )
    return GateResult(case.name, g, order >= p["expect"] - p["tol"], f"order {order:.3f}", need, value=order)


def _restitution(case: str, g: Gate, table: pd.DataFrame | None) -> GateResult:
    p = g.params
    need = f"|{p['quantity']} - e_set| <= {p['tol']:g} on every bounce"
    t = pd.DataFrame() if table is None else table
    if len(t):
        t = t[(t["engine"] == g.engine) & (t["method"] == g.method)]
    if not len(t):
        return GateResult(
            case, g, True, "no restitution rows for this engine", "a restitution sweep of it", evaluated=False
        )
    t = _at_dt(t, g.dt)
    for key in ("e_set", "bounce"):
        if key in p:
            t = t[np.isclose(_num(t[key]), p[key], rtol=0, atol=1e-12)]
    broken = t[t["status"] != "ok"]
    if len(broken):
        r = broken.iloc[0]
        return GateResult(case, g, False, f"drop e={r['e_set']} dt={r['dt']:.4g} {r['status']}", need)
    values = _num(t[p["quantity"]])
    dev = np.abs(values - _num(t["e_set"]))
    measured = dev[np.isfinite(dev)]
    if not len(measured):
        return GateResult(case, g, False, "no bounce measured", need)
    worst = int(np.nanargmax(np.where(np.isfinite(dev), dev, -1)))
    r = t.iloc[worst]
    return GateResult(
        case,
        g,
        bool(np.max(measured) <= p["tol"]),
        f"worst {p['quantity']} {values[worst]:.4g} at e={r['e_set']:g} "
        f"dt={float(r['dt']):.4g} bounce {int(r['bounce'])} ({len(measured)} bounces)",
        need,
        value=float(values[worst]),
    )


def _no_worse(case: Case, g: Gate, results: pd.DataFrame, rows: pd.DataFrame) -> GateResult:
    p = g.params
    other_engine, other_method = p["than"]
    q, factor = p["quantity"], p["factor"]
    need = f"{q} <= {factor:g} x {other_engine}/{other_method}'s at every dt both ran"
    other = results[
        (results["case"] == case.name)
        & (results["engine"] == other_engine)
        & (results["method"] == other_method)
    ]
    ran = results[results["case"] == case.name]
    if g.dt is not None and not len(_at_dt(rows, g.dt)) and (skip := quick_only(case, g, ran)):
        return skip
    rows, other = _at_dt(rows, g.dt), _at_dt(other, g.dt)
    if not len(other) or other["status"].isin(NOT_RUN).all():
        return GateResult(case.name, g, True, f"{other_engine}/{other_method} not run", need, evaluated=False)
    broken = _broken(rows)
    if broken:
        return GateResult(case.name, g, False, broken, need)
    pairs = 0
    for _, r in rows.iterrows():
        o = other[
            (other["dt_kind"] == r["dt_kind"])
            & np.isclose(_num(other["dt"]), float(r["dt"]), rtol=1e-9, atol=0)
        ]
        if not len(o) or o.iloc[0]["status"] != "ok":
            continue
        pairs += 1
        mine, theirs = float(pd.to_numeric(r[q], errors="coerce")), float(_num(o[q])[0])
        if r["status"] != "ok" or not mine <= factor * theirs:
            shown = _status(r) if r["status"] != "ok" else f"{q} {mine:.3g}"
            return GateResult(
                case.name, g, False, f"dt={float(r['dt']):g}: {shown} against {theirs:.3g}", need
            )
    if not pairs:
        return GateResult(
            case.name, g, False, f"no dt that both this run and {other_engine}/{other_method} measured", need
        )
    return GateResult(case.name, g, True, f"no worse at {pairs} dt", need)


def check_gates(
    cases: list[Case],
    results: pd.DataFrame,
    stability: pd.DataFrame | None = None,
    restitution: pd.DataFrame | None = None,
    extra: list[tuple[list[str], Gate]] | None = None,
) -> list[GateResult]:
    """Every gate of every case, in case order, then every gate of ``extra`` (the gates
    of a gates file, :func:`truestep.cases.loader.load_gates_file`) on every case whose
    name matches one of its patterns (a ``restitution`` gate of a gates file reads the
    restitution sweep, which belongs to no case: it is checked once, as case
    :data:`SWEEP`). ``*`` engines and methods are expanded to the pairs the run
    simulated; such a gate with nothing to expand to is not evaluated."""
    out: list[GateResult] = []
    todo = gates_to_check(cases, extra)
    check_properties_exist(todo)
    for c, g in todo:
        kind = GATE_KINDS.get(g.kind)
        reads = None if kind is None else kind.reads  # an unknown kind fails below, saying so
        if reads in ("stability", "restitution") and "*" in (g.engine, g.method):
            pairs = _table_pairs(c, g, stability if reads == "stability" else restitution)
        else:
            pairs = _pairs(results, c.name, g)
        if not pairs:
            ran = results[results["case"] == c.name] if "case" in results else results.iloc[:0]
            out.append(
                quick_only(c, g, ran[~ran["status"].isin(NOT_RUN)])
                or GateResult(
                    c.name,
                    g,
                    True,
                    "nothing ran that it names",
                    "a run of a matching engine and method",
                    evaluated=False,
                )
            )
        for e, m in pairs:
            out.append(
                check_gate(c, dataclasses.replace(g, engine=e, method=m), results, stability, restitution)
            )
    out += unmatched(cases, extra)
    seen: dict[str, int] = {}
    for v in out:
        base = gate_id(v.case, v.gate)
        seen[base] = seen.get(base, 0) + 1
        v.id = base if seen[base] == 1 else f"{base}#{seen[base]}"
    return out


def lost_since(verdicts: list[GateResult], before: list[GateResult]) -> list[GateResult]:
    """``verdicts`` with every gate that ``before`` (the same gates on the baseline's tables)
    evaluated and this run cannot turned into a failure that says so: a change that makes
    runs go unstable or stop converging must not pass by leaving its gates unevaluated. A
    gate that only a full run evaluates, read from a ``--quick`` run (:func:`quick_only`),
    stays not evaluated."""
    evaluated = {v.id: v for v in before if v.evaluated}
    out = []
    for v in verdicts:
        was = evaluated.get(v.id)
        if was is not None and not v.evaluated and not v.measured.startswith(QUICK_ONLY):
            v = dataclasses.replace(
                v,
                passed=False,
                evaluated=True,
                measured=f"{v.measured}, where the baseline measured {was.measured}",
                required=f"{v.required}; evaluated, as in the baseline",
            )
        out.append(v)
    return out


def gate_id(case: str, g: Gate) -> str:
    """A gate verdict's id, the same from run to run, whatever the order of the gates, on
    the console, in markdown, JUnit, JSON and the pytest plugin's test ids:
    ``case/id/engine/method@dt`` when the gate file gives it an ``id``, else
    ``case/kind/engine/method`` with what else tells the gate apart (a property's name, the
    run a ``no-worse-than`` compares with, a restitution gate's quantity) and the step
    (``@dt``); ``engine`` and ``method`` are those a ``*`` stood for. A second gate with
    the same id in one run gets ``#2`` (in file order)."""
    dt = f"@{g.dt:g}" if g.dt is not None else ""
    if g.id:
        return f"{case}/{g.id}/{g.engine}/{g.method}{dt}"
    parts = [case, g.kind, g.engine, g.method]
    kind = GATE_KINDS.get(g.kind)
    if kind is not None and kind.tells_apart is not None:
        parts.append(kind.tells_apart(g.params))
    if g.where == DECLARED:
        parts.append(DECLARED)
    return "/".join(parts) + dt


def refuse_unknown_engines(extra: list[tuple[list[str], Gate]], engines: set[str], results: str) -> None:
    """A gates-file gate must name one of ``engines`` (registered, or in the run's
    ``results``) or ``*``: :class:`~truestep.cases.CaseError` naming its file and field
    otherwise (``truestep gate``, :func:`truestep.check` and the pytest plugin alike)."""
    from truestep.cases.errors import CaseError
    from truestep.cases.fields import short

    for _, g in extra:
        if g.engine != "*" and g.engine not in engines:
            raise CaseError(
                g.file,
                f"{g.where}.engine",
                f"unknown engine {short(g.engine)} (not registered, not in {results})",
            )


def gates_to_check(
    cases: list[Case], extra: list[tuple[list[str], Gate]] | None = None
) -> list[tuple[Case, Gate]]:
    """(case, gate) pairs: the cases' own gates, then each gates-file gate on every case
    its patterns match (a restitution gate once, as case :data:`SWEEP`)."""
    todo = [(c, g) for c in cases for g in c.gates]
    for patterns, g in extra or []:
        if GATE_KINDS[g.kind].reads == "restitution":
            todo.append((_SWEEP_CASE, g))
            continue
        todo += [(c, g) for c in cases if _matches(c, g, patterns)]
    return todo


def _matches(case: Case, g: Gate, patterns: list[str]) -> bool:
    """Whether a gates-file gate applies to ``case``: a pattern matches its name; a
    property gate matched only by a glob applies where the case measures that property
    (a case named outright that does not is refused: :func:`check_properties_exist`)."""
    hits = [p for p in patterns if fnmatch.fnmatchcase(case.name, p)]
    if not hits or not GATE_KINDS[g.kind].names_property or g.params["name"] in case.properties:
        return bool(hits)
    return any(p == case.name for p in hits)


def unmatched(cases: list[Case], extra: list[tuple[list[str], Gate]] | None) -> list[GateResult]:
    """A verdict, not evaluated, for each gates-file gate whose ``cases`` match no case of
    the run (it was dropped without a word): ``cases = "harmonic-osc"`` with a typo, or a
    run of other cases, shows."""
    out = []
    for patterns, g in extra or []:
        if GATE_KINDS[g.kind].reads == "restitution" or any(_matches(c, g, patterns) for c in cases):
            continue
        shown = ", ".join(patterns)
        out.append(
            GateResult(
                shown,
                g,
                True,
                f"no case of this run matches cases = {shown}",
                "a case it names",
                evaluated=False,
            )
        )
    return out


def check_properties_exist(todo: list[tuple[Case, Gate]]) -> None:
    """A gates-file property gate on a case that does not measure that property can never be
    judged: :class:`~truestep.cases.errors.CaseError` (exit 2), naming the gate's file and
    field, as a case file's own is refused when it loads."""
    from truestep.cases.errors import CaseError

    for case, g in todo:
        if (
            GATE_KINDS[g.kind].names_property
            and case is not _SWEEP_CASE
            and g.params["name"] not in case.properties
        ):
            raise CaseError(
                g.file or case.file,
                f"{g.where}.name",
                f"{g.params['name']!r} is not a property of {case.name} "
                f"(its properties: {', '.join(case.properties) or 'none'})",
            )


SWEEP = "restitution-sweep"
"""The case name under which gates on the restitution sweep are reported."""


@dataclass
class _Sweep:
    name: str = SWEEP
    file: str = ""


_SWEEP_CASE: Case = _Sweep()  # type: ignore[assignment]


def _table_pairs(case: Case, g: Gate, table: pd.DataFrame | None) -> list[tuple[str, str]]:
    if table is None or not len(table):
        return []
    t = table
    if "case" in t:
        t = t[t["case"] == case.name]
    t = t[~t["status"].isin(NOT_RUN)]
    pairs = t[["engine", "method"]].drop_duplicates().itertuples(index=False)
    return [(e, m) for e, m in pairs if g.engine in ("*", e) and g.method in ("*", m)]


def verdict_table(verdicts: list[GateResult]) -> pd.DataFrame:
    """The verdicts as a table (:data:`GATE_COLUMNS`)."""
    return pd.DataFrame([v.row() for v in verdicts], columns=GATE_COLUMNS)


Check = Callable[[Case, Gate, pd.DataFrame, pd.DataFrame], GateResult]
CHECKS: dict[str, Check] = {
    "order": lambda case, g, results, rows: _order(case, g, rows, results),
    "no-worse-than": _no_worse,
    "error": _measured,
    "energy_drift": _measured,
    "status": _status_is,
    "property": lambda case, g, results, rows: _property(case, g, rows),
    "speedup": lambda case, g, results, rows: _speedup(case, g, results, rows.iloc[0]),
}
"""The checker of each kind of gate that reads results rows (its kind's ``reads`` is
``sweep``: every step of the engine and method; ``row``: the rows at the gate's step);
``stability-limit`` and ``restitution`` gates read their own tables."""
