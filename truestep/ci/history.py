"""Runs kept by commit, read back over commits.

A history is a folder of saved runs (:func:`truestep.ci.saved.save`), one per git
revision of the project, in the order they were added (``index.json``). ``truestep
history add`` saves the current run under the project's revision (a revision added again
replaces its entry); ``truestep history show`` prints one row's quantity over the saved
commits and names the commits where it stepped (:func:`steps`, as asv names the commit
where a benchmark moved) and, for a timing, the commits whose run was timed on another
machine (:func:`machine_changes`); ``truestep history export`` writes a run as the JSON
github-action-benchmark reads (``customSmallerIsBetter``).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from truestep.ci.saved import BaselineRefused, git_state, save

INDEX = "index.json"
"""The history's list of entries, oldest first: ``[{"revision", "dirty", "folder"}]``."""


class HistoryError(Exception):
    """A history that cannot be read or added to; ``str()`` is one line."""


def _index(store: Path) -> list[dict]:
    path = store / INDEX
    if not path.exists():
        return []
    try:
        entries = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise HistoryError(f"{path}: not a history index ({err})") from None
    if not isinstance(entries, list) or not all(isinstance(e, dict) and "folder" in e for e in entries):
        raise HistoryError(f"{path}: not a history index (a list of entries with a folder)")
    return entries


def add(results: Path, store: Path, *, root: Path | None = None) -> dict:
    """Save the run of ``results`` into ``store`` under the project's git revision (at
    ``root``, default the working directory); returns the entry. A project that is not a
    git checkout cannot keep a history by commit (:class:`HistoryError`)."""
    root = Path.cwd() if root is None else root
    state = git_state(root)
    if state is None:
        raise HistoryError(f"{root}: not a git checkout: a history keeps runs by commit")
    revision = str(state["revision"])
    folder = revision[:12] + ("-dirty" if state["dirty"] else "")
    store.mkdir(parents=True, exist_ok=True)
    entries = [e for e in _index(store) if e["folder"] != folder]
    try:
        save(results, store / folder, root=root)
    except BaselineRefused as err:
        raise HistoryError(str(err)) from None
    entry = {"revision": revision, "dirty": bool(state["dirty"]), "folder": folder}
    entries.append(entry)
    tmp = store / f".{INDEX}.new"
    tmp.write_text(json.dumps(entries, indent=1) + "\n")
    os.replace(tmp, store / INDEX)
    return entry


@dataclass(frozen=True)
class Point:
    """One saved commit's value of a quantity (NaN where that run has no such row), and
    the machine its run was timed on (its ``run.json``'s ``machine``; None where the run
    recorded none)."""

    revision: str
    dirty: bool
    value: float
    status: str
    machine: Mapping | None = None


def series(store: Path, quantity: str, case: str, engine: str, method: str, dt: float | None) -> list[Point]:
    """``quantity`` of one row (case, engine, method and, when given, step) in every
    saved run, oldest first."""
    out = []
    for e in _index(store):
        path = store / e["folder"] / "results.csv"
        if not path.exists():
            raise HistoryError(f"{path}: missing (the history's index names it)")
        table = pd.read_csv(path)
        if quantity not in table:
            raise HistoryError(f"{path}: no column {quantity!r}")
        rows = table[(table["case"] == case) & (table["engine"] == engine) & (table["method"] == method)]
        if dt is not None:
            rows = rows[np.isclose(pd.to_numeric(rows["dt"], errors="coerce"), dt, rtol=1e-9, atol=0)]
        if len(rows) > 1:
            raise HistoryError(f"{case} {engine}/{method}: {len(rows)} rows in {path}: name the step (--dt)")
        value = float(pd.to_numeric(rows[quantity], errors="coerce").iloc[0]) if len(rows) else math.nan
        status = str(rows["status"].iloc[0]) if len(rows) else "absent"
        out.append(Point(e["revision"], bool(e["dirty"]), value, status, _machine(store / e["folder"])))
    return out


def _machine(folder: Path) -> Mapping | None:
    """The machine a saved run was timed on; None where it recorded none."""
    from truestep.reporting.run_record import read_run_record

    recorded = (read_run_record(folder) or {}).get("machine")
    return recorded if isinstance(recorded, dict) else None


def machine_changes(points: list[Point]) -> dict[int, str]:
    """The indices of ``points`` whose run was timed on another machine than the run
    before it that recorded one (:func:`truestep.runtime.machine.timed_alike`, as the
    gate's ``--time-against`` note decides), each with that machine in words: a timing
    that steps there may have stepped with the machine, not the commit."""
    from truestep.runtime.machine import line, timed_alike

    out: dict[int, str] = {}
    last: Mapping | None = None
    for k, p in enumerate(points):
        if not timed_alike(p.machine, last):
            out[k] = line(p.machine)
        last = p.machine or last
    return out


def steps(values: list[float], tolerance: float, window: int = 3) -> list[int]:
    """The indices where a series steps. A candidate is ``k`` where the median of up to
    ``window`` values from ``k`` on differs from the median of up to ``window`` values
    before it by more than ``tolerance`` (relative to the earlier); of a run of
    consecutive candidates (one move seen from several windows) the step is the one
    with the largest jump between neighbours (the first of equal ones). A value that
    appears or vanishes (finite to NaN) is a step. Medians let a noisy quantity (a wall
    time) step once where it moved, not at every wobble; a deterministic one (an error)
    steps exactly where it changed."""

    def jump(k: int) -> float:
        a, b = values[k - 1], values[k]
        if math.isfinite(a) != math.isfinite(b):
            return math.inf
        return abs(b - a) / abs(a) if a != 0 else (math.inf if b != 0 else 0.0)

    candidates = []
    for k in range(1, len(values)):
        if math.isfinite(values[k - 1]) != math.isfinite(values[k]):
            candidates.append(k)
            continue
        before = [v for v in values[max(0, k - window) : k] if math.isfinite(v)]
        after = [v for v in values[k : k + window] if math.isfinite(v)]
        if before and after:
            a, b = float(np.median(before)), float(np.median(after))
            if (abs(b - a) / abs(a) if a != 0 else (math.inf if b != 0 else 0.0)) > tolerance:
                candidates.append(k)
    out: list[int] = []
    run: list[int] = []
    for k in [*candidates, -1]:
        if run and k != run[-1] + 1:
            out.append(max(run, key=lambda j: (jump(j), -j)))
            run = []
        if k >= 0:
            run.append(k)
    return out


def benchmark_json(results: pd.DataFrame, quantities: tuple[str, ...] = ("error", "wall_s")) -> list[dict]:
    """A run's ok rows as github-action-benchmark's ``customSmallerIsBetter`` entries: one
    per row and quantity, named ``case/engine/method@dt quantity``, in the table's order."""
    units = {"error": "m (or the case's units)", "energy_drift": "1", "wall_s": "s", "nfev": "evaluations"}
    out = []
    for r in results[results["status"] == "ok"].to_dict("records"):
        kind = "tol" if r.get("dt_kind") == "tolerance" else "dt"
        name = f"{r['case']}/{r['engine']}/{r['method']}@{kind}={float(r['dt']):g}"
        for q in quantities:
            value = pd.to_numeric(pd.Series([r.get(q)]), errors="coerce").iloc[0]
            if np.isfinite(value):
                out.append({"name": f"{name} {q}", "unit": units.get(q, ""), "value": float(value)})
    return out
