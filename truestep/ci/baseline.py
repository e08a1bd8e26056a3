"""Compare a run's tables with a previous run's, row by row: what got worse, what got better.

Rows are matched on their keys (``results``: case, engine, method, dt_kind, dt;
``stability``: case, engine, method; ``restitution``: engine, method, dt, e_set, bounce;
fitted orders: case, engine, method). A quantity got **worse** when it moved the wrong
way by more than its tolerance, **better** when it moved the right way by as much.
Rows present on one side only are listed as **appeared** or **vanished**.

The same revision and package versions give the same numbers on any machine, bit for
bit (:mod:`truestep.numerics`); :func:`identical` checks that promise cell by cell. The
tolerances are for what a change of code or versions may move without being worse. Wall
time is never compared across runs directly: only its ratio to one named engine and method
of the same case and step measured in the same run, with a wide band.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from truestep.measures.metrics import ROUND_OFF, fit_order, round_off_floor
from truestep.tables.spec import DERIVED, RESTITUTION, RESULTS, STABILITY, Compared, Table, compared

TOLERANCES: dict[str, float] = {name: c.tolerance for name, c in compared().items()}
"""Default tolerances, each with its reason beside it in :mod:`truestep.tables.spec` (the
tables' compared columns, then :data:`~truestep.tables.spec.DERIVED`): ``error``,
``energy_drift`` relative 1e-3 (above :data:`FLOORS`), ``nfev`` relative 0.02, ``dt_limit``
relative 0.01, ``order`` absolute 0.05, ``e_error`` absolute 0.005, ``wall_ratio`` relative
1.0."""
FLOORS: dict[str, float] = {name: c.floor for name, c in compared().items() if c.floor}
"""Absolute floors under the relative tolerances: differences below these are round-off."""
RESULT_KEYS = list(RESULTS.keys)
STABILITY_KEYS = list(STABILITY.keys)
RESTITUTION_KEYS = list(RESTITUTION.keys)
ORDER_KEYS = ["case", "engine", "method"]
STATUS_RANK = {"ok": 0, "stalled": 1, "unstable": 1, "solver-failed": 1, "timeout": 2, "crashed": 2}
"""Higher is worse: ok -> unstable is a regression, as is anything -> crashed."""
POSITION_ERRORS = frozenset({"error", "error_final"})
"""Quantities in a case's error units: a float32 engine's differ by its round-off,
:func:`~truestep.measures.metrics.round_off_floor` of the case's scale, on another CPU."""
FINDING_COLUMNS = ["change", "table", "key", "quantity", "baseline", "current", "note"]


@dataclass
class Finding:
    """One difference: ``change`` is ``worse``, ``better``, ``appeared``, ``vanished`` or
    (a cell of a run that should be identical, :func:`identical`) ``differs``."""

    change: str
    table: str
    key: str
    quantity: str
    baseline: object
    current: object
    note: str = ""

    def line(self) -> str:
        head = {
            "worse": "WORSE",
            "better": "better",
            "appeared": "new",
            "vanished": "GONE",
            "differs": "DIFFERS",
        }[self.change]
        if self.change in ("appeared", "vanished"):
            return f"{head:6s} {self.table} {self.key}"
        exact = self.change == "differs"  # cells one ulp apart must not print alike
        return (
            f"{head:6s} {self.table} {self.key} {self.quantity}: {_show(self.baseline, exact)} -> "
            f"{_show(self.current, exact)}" + (f" ({self.note})" if self.note else "")
        )


def _show(x: object, exact: bool = False) -> str:
    """A cell in a finding's line: a float to 6 figures, or (``exact``) its shortest repr
    that reads back as the same double."""
    if isinstance(x, float | np.floating):
        return repr(float(x)) if exact else f"{x:.6g}"
    return str(x)


@dataclass
class Comparison:
    """Everything :func:`compare` found, and how many rows it compared."""

    findings: list[Finding]
    compared: int
    tolerances: dict[str, float]
    time_against: str | None = None
    timed: int = 0
    """Rows whose wall-time ratio was compared (``time_against``)."""

    def worse(self) -> list[Finding]:
        return [f for f in self.findings if f.change in ("worse", "vanished", "differs")]

    def table(self) -> pd.DataFrame:
        return pd.DataFrame([f.__dict__ for f in self.findings], columns=FINDING_COLUMNS)


def _key(row: Mapping, keys: list[str]) -> str:
    """A row's key as a short label: ``harmonic-oscillator reference rk4 dt=0.001``."""
    out = []
    for k in keys:
        v = row[k]
        if k == "dt" and not np.isfinite(_as_float(v)):
            out.append(f"({row.get('status', '')})")
        elif k == "dt":
            out.append(f"{'tol' if row.get('dt_kind') == 'tolerance' else 'dt'}={float(v):g}")
        elif k in ("e_set", "bounce") and not np.isfinite(_as_float(v)):
            continue  # a row of a pair that did not run has no drop or bounce
        elif k == "e_set":
            out.append(f"e={float(v):g}")
        elif k == "bounce":
            out.append(f"bounce={int(v)}")
        elif k != "dt_kind":
            out.append(str(v))
    return " ".join(out)


def _key_value(column: str, value: object) -> object:
    """A key part that compares equal across tables: numbers rounded, NaN as ``None``."""
    if column in ("dt", "e_set", "bounce"):
        number = _as_float(value)
        return None if not np.isfinite(number) else round(number, 12)
    return value


def _index(df: pd.DataFrame, keys: list[str]) -> dict[tuple, dict]:
    return {tuple(_key_value(c, row[c]) for c in keys): row for row in df.to_dict("records")}


def _as_float(x: Any) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


def _moved(
    quantity: str,
    old: float,
    new: float,
    tol: float,
    *,
    higher_is_worse: bool = True,
    relative: bool = True,
    floor: float = 0.0,
) -> str | None:
    """``worse``, ``better`` or ``None`` for a quantity that went from ``old`` to ``new``;
    differences below ``floor`` (or the quantity's :data:`FLOORS`) are round-off."""
    if not (np.isfinite(old) and np.isfinite(new)):
        if np.isfinite(old) != np.isfinite(new):
            return "worse" if np.isfinite(old) else "better"
        return None
    band = tol * abs(old) if relative else tol
    band = max(band, FLOORS.get(quantity, 0.0), floor)
    delta = new - old if higher_is_worse else old - new
    if delta > band:
        return "worse"
    if delta < -band:
        return "better"
    return None


def _compare_rows(
    table: str,
    old: pd.DataFrame,
    new: pd.DataFrame,
    keys: list[str],
    quantities: list[tuple[str, bool, bool]],
    tol: Mapping[str, float],
    findings: list[Finding],
    scales: Mapping[str, float] | None = None,
) -> int:
    """Match rows on ``keys``; compare status and each (quantity, higher_is_worse, relative).
    A float32 engine's errors (:data:`POSITION_ERRORS`) move within its round-off floor
    times the case's scale (``scales``, default 1) without counting."""
    if old is None or new is None:
        return 0
    a, b = _index(old, keys), _index(new, keys)
    engine_floor: dict[str, float] = {}
    # in the order of the tables' rows: two calls on the same tables say the same, byte for byte
    findings += [Finding("vanished", table, _key(a[k], keys), "", "", "") for k in a if k not in b]
    findings += [Finding("appeared", table, _key(b[k], keys), "", "", "") for k in b if k not in a]
    for k in sorted(a.keys() & b.keys(), key=str):
        ra, rb = a[k], b[k]
        label = _key(ra, keys)
        sa, sb = str(ra.get("status", "ok")), str(rb.get("status", "ok"))
        if sa != sb and sa in STATUS_RANK and sb in STATUS_RANK:
            change = (
                "worse"
                if STATUS_RANK[sb] > STATUS_RANK[sa]
                else "better"
                if STATUS_RANK[sb] < STATUS_RANK[sa]
                else None
            )
            if change:
                findings.append(Finding(change, table, label, "status", sa, sb))
            continue
        if sb != "ok":
            continue
        engine = str(rb.get("engine", ""))
        if engine not in engine_floor:
            engine_floor[engine] = round_off_floor(engine)
        floor = engine_floor[engine]
        floor = floor * (scales or {}).get(str(rb.get("case", "")), 1.0) if floor > ROUND_OFF else 0.0
        for q, higher_is_worse, relative in quantities:
            if q not in ra or q not in rb or q not in tol:
                continue
            old, new = _as_float(ra[q]), _as_float(rb[q])
            change = _moved(
                q,
                old,
                new,
                tol[q],
                higher_is_worse=higher_is_worse,
                relative=relative,
                floor=floor if q in POSITION_ERRORS else 0.0,
            )
            if change:
                findings.append(Finding(change, table, label, q, old, new))
    return len(a.keys() & b.keys())


def orders(results: pd.DataFrame, scales: Mapping[str, float] | None = None) -> pd.DataFrame:
    """Fitted order per case, engine and fixed-step method (as the report fits them)."""
    rows = []
    steps = results[(results["dt_kind"] == "step") & (results["status"] == "ok")]
    for (case, engine, method), g in steps.groupby(["case", "engine", "method"], sort=False):
        order = fit_order(
            pd.to_numeric(g["dt"], errors="coerce"),
            pd.to_numeric(g["error"], errors="coerce"),
            scale=(scales or {}).get(case, 1.0),
            floor=round_off_floor(str(engine)),
        )
        rows.append({"case": case, "engine": engine, "method": method, "order": order})
    return pd.DataFrame(rows, columns=[*ORDER_KEYS, "order"])


def _relative_noise(rows: pd.DataFrame) -> np.ndarray:
    """Each row's wall-time noise over its wall time: its measured spread, at least
    :data:`~truestep.measures.picks.TIE_NOISE` and the timer's floor
    (:func:`~truestep.measures.picks.noise_band`)."""
    from truestep.measures.picks import noise_band

    wall = pd.to_numeric(rows["wall_s"], errors="coerce").to_numpy(float)
    spread = (
        pd.to_numeric(rows["wall_s_spread"], errors="coerce").to_numpy(float)
        if "wall_s_spread" in rows
        else None
    )
    return noise_band(wall, spread) / wall


def _wall_ratios(results: pd.DataFrame, against: tuple[str, str]) -> pd.DataFrame:
    """Each ok row's wall time over the named engine/method's at the same case and dt
    (``wall_ratio``), and how far noise may move that ratio, relative (``ratio_noise``:
    the row's and the named run's relative noise, :func:`_relative_noise`, added)."""
    e, m = against
    ok = results[results["status"] == "ok"].copy()
    ok["noise"] = _relative_noise(ok) if len(ok) else np.zeros(0)
    ref = ok[(ok["engine"] == e) & (ok["method"] == m)]
    ref = {
        (r["case"], r["dt_kind"], _key_value("dt", r["dt"])): (float(r["wall_s"]), float(r["noise"]))
        for r in ref.to_dict("records")
    }
    ratios, noise = [], []
    for r in ok.to_dict("records"):
        k = (r["case"], r["dt_kind"], _key_value("dt", r["dt"]))
        wall, band = ref.get(k, (np.nan, np.nan))
        ratios.append(float(r["wall_s"]) / wall if wall > 0 else np.nan)
        noise.append(float(r["noise"]) + band)
    ok["wall_ratio"], ok["ratio_noise"] = ratios, noise
    return ok[np.isfinite(ok["wall_ratio"].to_numpy(float))]


def _compare_timing(old: pd.DataFrame, new: pd.DataFrame, tol: float, findings: list[Finding]) -> int:
    """Wall-time ratios (:func:`_wall_ratios`) row by row: ``worse`` only where the new
    ratio, less its noise, exceeds the old one, plus its noise, by more than ``tol``
    (relative), ``better`` the other way; ratios whose noise bands leave no such gap are
    a tie. Noise is a factor (:func:`~truestep.measures.picks.noise_interval`): a ratio
    known to ``n`` lies between ``r / (1 + n)`` and ``r * (1 + n)``, so a row whose spread
    passes its median still gates (``r * (1 - n)`` would fall below 0 and never be worse).
    An unchanged solver run twice (A/A) passes: single timings of a few microseconds move
    by a large factor from run to run."""
    a, b = _index(old, RESULT_KEYS), _index(new, RESULT_KEYS)
    for k in sorted(a.keys() & b.keys(), key=str):
        ra, rb = a[k], b[k]
        r0, r1 = float(ra["wall_ratio"]), float(rb["wall_ratio"])
        n0, n1 = float(ra["ratio_noise"]), float(rb["ratio_noise"])
        if r1 / (1 + n1) > r0 * (1 + n0) * (1 + tol):
            findings.append(Finding("worse", "timing", _key(rb, RESULT_KEYS), "wall_ratio", r0, r1))
        elif r1 * (1 + n1) * (1 + tol) < r0 / (1 + n0):
            findings.append(Finding("better", "timing", _key(rb, RESULT_KEYS), "wall_ratio", r0, r1))
    return len(a.keys() & b.keys())


def compare(
    baseline: Mapping[str, pd.DataFrame | None],
    current: Mapping[str, pd.DataFrame | None],
    *,
    tolerances: Mapping[str, float] | None = None,
    time_against: str | None = None,
    scales: Mapping[str, float] | None = None,
    engines: set[str] | None = None,
) -> Comparison:
    """Compare ``current`` tables (``results``, ``stability``, ``restitution``; any may be
    ``None``) with ``baseline``'s. ``tolerances`` override :data:`TOLERANCES`;
    ``time_against`` (``engine/method``) turns on the wall-time comparison. ``engines``
    (``None``: all) are the engines whose rows are compared: the ``time_against`` rows
    are read for the ratios whether or not their engine is among them."""
    tol = {**TOLERANCES, **(tolerances or {})}
    findings: list[Finding] = []
    whole_old, whole_new = baseline.get("results"), current.get("results")
    baseline, current = narrow(baseline, engines=engines), narrow(current, engines=engines)
    old_r, new_r = baseline.get("results"), current.get("results")
    timed = 0
    compared = _compare_rows(
        "results",
        old_r,
        new_r,
        RESULT_KEYS,
        _quantities(RESULTS),
        tol,
        findings,
        scales,
    )
    if old_r is not None and new_r is not None:
        compared += _compare_rows(
            "orders",
            orders(old_r, scales),
            orders(new_r, scales),
            ORDER_KEYS,
            [_quantity("order", DERIVED["order"])],
            tol,
            findings,
        )
        if time_against and whole_old is not None and whole_new is not None:
            e, _, m = time_against.partition("/")
            timed = _compare_timing(
                _in_engines(_wall_ratios(whole_old, (e, m)), engines),
                _in_engines(_wall_ratios(whole_new, (e, m)), engines),
                tol["wall_ratio"],
                findings,
            )
            compared += timed
    compared += _compare_rows(
        "stability",
        baseline.get("stability"),
        current.get("stability"),
        STABILITY_KEYS,
        _quantities(STABILITY),
        tol,
        findings,
    )
    old_e, new_e = (
        _restitution_error(baseline.get("restitution")),
        _restitution_error(current.get("restitution")),
    )
    compared += _compare_rows(
        "restitution",
        old_e,
        new_e,
        RESTITUTION_KEYS,
        [_quantity("e_error", DERIVED["e_error"])],
        tol,
        findings,
    )
    return Comparison(findings, compared, tol, time_against, timed)


def _in_engines(table: pd.DataFrame, engines: set[str] | None) -> pd.DataFrame:
    """The rows of ``table`` of ``engines`` (``None``: all)."""
    return table if engines is None else table[table["engine"].astype(str).isin(engines)]


def _quantity(name: str, c: Compared) -> tuple[str, bool, bool]:
    return name, c.higher_is_worse, c.relative


def _quantities(table: Table) -> list[tuple[str, bool, bool]]:
    """The (quantity, higher_is_worse, relative) of each column of ``table`` a baseline
    compares."""
    return [_quantity(c.name, c.compared) for c in table.columns if c.compared is not None]


TABLE_KEYS = {"results": RESULT_KEYS, "stability": STABILITY_KEYS, "restitution": RESTITUTION_KEYS}
"""The columns that name a row, per table."""


def narrow(
    tables: Mapping[str, pd.DataFrame | None],
    *,
    cases: set[str] | None = None,
    engines: set[str] | None = None,
) -> dict[str, pd.DataFrame | None]:
    """``tables`` with only the rows of ``cases`` and ``engines`` (``None``: all): a run that
    was asked for fewer cases or engines is compared with the baseline's rows of those
    only, and the others are not "vanished". ``restitution`` has no case column: it is
    kept whole where its engines are asked for."""
    out: dict[str, pd.DataFrame | None] = {}
    for name, table in tables.items():
        if table is None or not len(table.columns):
            out[name] = table
            continue
        keep = np.ones(len(table), bool)
        if cases is not None and "case" in table:
            keep &= table["case"].astype(str).isin(cases).to_numpy()
        if engines is not None and "engine" in table:
            keep &= table["engine"].astype(str).isin(engines).to_numpy()
        out[name] = table[keep]
    return out


def _same_cell(a: object, b: object) -> bool:
    fa, fb = _as_float(a), _as_float(b)
    if isinstance(a, float | int | np.floating | np.integer) or isinstance(
        b, float | int | np.floating | np.integer
    ):
        return (np.isnan(fa) and np.isnan(fb)) or fa == fb
    if pd.isna(a) and pd.isna(b):
        return True
    return str(a) == str(b)


def identical(
    baseline: Mapping[str, pd.DataFrame | None], current: Mapping[str, pd.DataFrame | None]
) -> tuple[list[Finding], int]:
    """Every cell of every non-timing column, compared exactly (the promise of
    :mod:`truestep.numerics`: the same revision and package versions give the same
    numbers on any machine). Returns a ``differs`` finding per differing cell (and
    ``vanished``/``appeared`` rows) and the number of cells compared. Rows whose message
    says their engine is not repeatable are left out."""
    from truestep.execution.runner import MACHINE_COLUMNS
    from truestep.execution.timing import NOT_REPEATABLE

    findings: list[Finding] = []
    cells = 0
    for name, keys in TABLE_KEYS.items():
        old, new = baseline.get(name), current.get(name)
        if old is None or new is None:
            continue
        a, b = _index(old, keys), _index(new, keys)
        for k in a.keys() - b.keys():
            findings.append(Finding("vanished", name, _key(a[k], keys), "", "", ""))
        for k in b.keys() - a.keys():
            findings.append(Finding("appeared", name, _key(b[k], keys), "", "", ""))
        columns = [c for c in old.columns if c in set(new.columns) and c not in MACHINE_COLUMNS]
        for k in sorted(a.keys() & b.keys(), key=str):
            ra, rb = a[k], b[k]
            if any(NOT_REPEATABLE in str(r.get("message", "")) for r in (ra, rb)):
                continue
            for c in columns:
                cells += 1
                if not _same_cell(ra[c], rb[c]):
                    findings.append(Finding("differs", name, _key(ra, keys), c, ra[c], rb[c]))
    return findings, cells


def _restitution_error(table: pd.DataFrame | None) -> pd.DataFrame | None:
    """The restitution table with ``e_error = |e_measured - e_set|`` (what can get
    worse), rows without a bounce left out."""
    if table is None:
        return None
    t = table.copy()
    t["e_error"] = (
        pd.to_numeric(t["e_measured"], errors="coerce") - pd.to_numeric(t["e_set"], errors="coerce")
    ).abs()
    return t.dropna(subset=["dt", "e_set", "bounce"])


def read_tables(directory: Path) -> dict[str, pd.DataFrame | None]:
    """``results``, ``stability``, ``restitution`` of a run's output directory (``None``
    for a table the directory lacks), read strictly: a malformed or missing results table
    raises :class:`~truestep.tables.io.TableError` (see
    :func:`~truestep.tables.io.read_run_tables`)."""
    from truestep.tables.io import read_run_tables

    return read_run_tables(Path(directory))
