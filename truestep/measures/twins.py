"""One engine on two devices: its rows off the CPU beside its rows on the CPU (twin rows).

An engine runs on a GPU beside itself on the CPU when a run holds it twice: the engine,
and a second registration of its adapter (its class or a subclass, under another name)
made for another device, such as ``class NewtonGpu(NewtonAdapter)`` with ``name =
"newton-gpu"`` and ``device="cuda:0"``. Such an engine is the *twin* of the first
(:func:`twins_of`), and ``run.json`` records the pairs (``twins``, read back where a run is
judged: :func:`~truestep.measures.engine_facts.take`).

Two devices computing one scheme in one precision differ by round-off: where a twin's row
ends otherwise than its CPU row at the same case, method and step, or its error differs by
more than the round-off floor of the case's scale (:func:`~truestep.measures.metrics.round_off_floor`:
1e-4 for a float32 engine, whose rounding adds up over a run, 1e-11 for float64), the
twins *part*, and the report names the row (:func:`twin_rows`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np
import pandas as pd

from truestep.measures.metrics import round_off_floor

TWIN_COLUMNS = (
    "engine",
    "twin_of",
    "case",
    "method",
    "dt",
    "device",
    "twin_device",
    "status",
    "twin_status",
    "error",
    "twin_error",
    "difference",
    "band",
    "parts",
)
"""The table's columns: the engine off the CPU and the engine it is the twin of, the row
(case, method, step or tolerance), each one's device, status and error, the errors'
difference as a fraction of the case's scale, the round-off band it is held to, and
whether the twins part there."""

RECORDED_TWINS: dict[str, str] = {}
"""Engine off the CPU -> the engine on the CPU it is the twin of, as the judged run recorded
them (``run.json`` ``twins``), set by :func:`truestep.measures.engine_facts.take`."""


def twins_of(engines: Iterable[str], *, recorded: bool = True) -> dict[str, str]:
    """engine -> the engine it is the twin of, among ``engines``: the pairs the judged run
    recorded (:data:`RECORDED_TWINS`; not with ``recorded``
    false), else, for these engines as installed here, each engine that computes off the
    CPU whose adapter class is another's on the CPU or a subclass of it (that one: the
    first such in ``engines``)."""
    from truestep.adapters import EngineNotInstalled, UnknownEngine, adapter_class
    from truestep.adapters.devices import CPU, engine_device

    engines = list(dict.fromkeys(engines))
    if recorded and RECORDED_TWINS:
        return {b: a for b, a in RECORDED_TWINS.items() if b in engines and a in engines}
    found: dict[str, tuple[type, str]] = {}
    for engine in engines:
        try:
            found[engine] = (adapter_class(engine), engine_device(engine) or CPU)
        except (EngineNotInstalled, UnknownEngine):
            continue
    twins = {}
    for b, (cls_b, dev_b) in found.items():
        if dev_b == CPU:
            continue
        bases = [a for a, (cls_a, dev_a) in found.items() if dev_a == CPU and issubclass(cls_b, cls_a)]
        base = bases[0] if bases else None
        if base is not None:
            twins[b] = base
    return twins


def twin_rows(results: pd.DataFrame, cases: list, twins: Mapping[str, str] | None = None) -> pd.DataFrame:
    """The :data:`TWIN_COLUMNS` table: every row of a twin (``twins``, default
    :func:`twins_of` the results' engines) beside its CPU engine's row at the same case,
    method and step, both having run (not ``unsupported`` or ``skipped``)."""
    twins = twins_of(results["engine"].astype(str)) if twins is None else twins
    if not twins or not len(results):
        return pd.DataFrame(columns=list(TWIN_COLUMNS))
    scale = {c.name: float(c.error_scale) for c in cases}
    ran = results[~results["status"].isin(["unsupported", "skipped"])]
    key = ["case", "method", "dt_kind", "dt"]
    rows = []
    for engine, base in twins.items():
        mine = ran[ran["engine"] == engine]
        theirs = ran[ran["engine"] == base]
        both = mine.merge(theirs, on=key, suffixes=("", "_twin"))
        band = max(round_off_floor(engine), round_off_floor(base))
        for r in both.itertuples(index=False):
            e, f = float(r.error), float(r.error_twin)
            finite = np.isfinite(e) and np.isfinite(f)
            difference = abs(e - f) / scale.get(str(r.case), 1.0) if finite else np.nan
            parts = r.status != r.status_twin or (np.isfinite(difference) and difference > band)
            rows.append(
                {
                    "engine": engine,
                    "twin_of": base,
                    "case": r.case,
                    "method": r.method,
                    "dt": r.dt,
                    "device": r.device,
                    "twin_device": r.device_twin,
                    "status": r.status,
                    "twin_status": r.status_twin,
                    "error": e,
                    "twin_error": f,
                    "difference": difference,
                    "band": band,
                    "parts": bool(parts),
                }
            )
    return pd.DataFrame(rows, columns=list(TWIN_COLUMNS))


__all__ = ["TWIN_COLUMNS", "twin_rows", "twins_of"]
