"""Same scheme, same steps: an engine's method beside the reference method it says it is.

An adapter may declare ``peers``: for a method, the reference method that computes the
same scheme (Drake's ``runge_kutta2`` is Heun's method, MuJoCo's ``RK4`` the classical
RK4). Two implementations of one scheme on one case at one step make the same error, up
to round-off and what the engine adds (a contact model, a float32 state). The ratio of
their errors at equal steps is a measured check of that claim: a ratio of 1 confirms it,
a median ratio away from 1 means the engine computes something else under that name (a
step split in two, a force held through the stages), and it is reported as found.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from truestep.measures.metrics import ROUND_OFF, round_off_floor
from truestep.reference_impl.features import Feature

PEER_COLUMNS = ("engine", "method", "peer", "cases", "rows", "ratio", "ratio_min", "ratio_max", "verdict")
"""The table's columns: the engine and its method, the reference method it names as its
scheme, the cases and rows compared, the median, least and greatest error ratio
(engine / reference, same case, same step), and the verdict (:func:`verdict`)."""

SAME = (0.8, 1.25)
"""Median ratios within this band read as the same scheme: two implementations of one
scheme differ by round-off and engine detail, never by a steady factor beyond it."""


def declared_peers(engine: str) -> Mapping[str, str]:
    """The ``peers`` (method -> reference method) the judged run recorded for ``engine``
    (:func:`~truestep.measures.engine_facts.take`), else those its installed adapter
    declares, else none (an engine not installed here, or one that declares none)."""
    from truestep.adapters import EngineNotInstalled, UnknownEngine, adapter_class
    from truestep.measures.engine_facts import recorded_words

    recorded = recorded_words(engine, "peers")
    if recorded is not None:
        return recorded
    try:
        return dict(getattr(adapter_class(engine), "peers", None) or {})
    except (EngineNotInstalled, UnknownEngine):
        return {}


def verdict(ratio: float) -> str:
    """``same scheme`` for a median ratio inside :data:`SAME`, else the median, in words."""
    if not np.isfinite(ratio):
        return "not compared"
    if SAME[0] <= ratio <= SAME[1]:
        return "same scheme"
    return f"median error {ratio:.2g}x the reference's: not the named scheme as such"


FLOOR = 1e-10
"""Rows whose reference error is below this are not compared: there the error is
round-off, whose ratio says nothing about the scheme."""

FLOAT32_MARGIN = 10.0
"""A float32 engine is compared where the reference's error is at least this many times
its round-off floor: there float32's rounding moves the ratio by a tenth at most."""

CONTACT = frozenset({Feature.PLANES, Feature.THIN_WALLS, Feature.FRICTION})
"""Features where engines model the physics differently (soft contact, restitution
rules): a case with any of them is no test of an integrator's scheme."""


def same_scheme(
    results: pd.DataFrame, cases: list, peers: Mapping[str, Mapping[str, str]] | None = None
) -> pd.DataFrame:
    """The :data:`PEER_COLUMNS` table: for every engine method with a declared peer, the
    ratio of its error to the peer's on the same case at the same step, over every such
    pair of rows that ended ok with the reference's error above :data:`FLOOR` (for a
    float32 engine, above :data:`FLOAT32_MARGIN` times its round-off floor of the case's
    scale, :func:`~truestep.measures.metrics.round_off_floor`), on the
    ``cases`` without contact (:data:`CONTACT`), at fixed steps only (a tolerance is no
    common step). ``peers``: engine -> method -> reference method (default: what each
    engine's adapter declares)."""
    free = {c.name for c in cases if not (set(c.features) & CONTACT)}
    scale = {c.name: c.error_scale for c in cases}
    fixed = results[(results["status"] == "ok") & (results["dt_kind"] == "step") & results["case"].isin(free)]
    error = pd.to_numeric(fixed["error"], errors="coerce")
    fixed = fixed.assign(error=error)[error > 0]
    reference = fixed[(fixed["engine"] == "reference") & (fixed["error"] > FLOOR)][
        ["case", "method", "dt", "error"]
    ]
    rows = []
    for engine in sorted(set(results["engine"]) - {"reference"}):
        declared = peers.get(engine, {}) if peers is not None else declared_peers(engine)
        for method, peer in sorted(declared.items()):
            mine = fixed[(fixed["engine"] == engine) & (fixed["method"] == method)][["case", "dt", "error"]]
            theirs = reference[reference["method"] == peer][["case", "dt", "error"]]
            floor = round_off_floor(engine)
            if floor > ROUND_OFF:
                theirs = theirs[theirs["error"] > FLOAT32_MARGIN * floor * theirs["case"].map(scale)]
            both = mine.merge(theirs, on=["case", "dt"], suffixes=("", "_peer"))
            ratio = (both["error"] / both["error_peer"]).to_numpy(float)
            median = float(np.median(ratio)) if len(ratio) else float("nan")
            rows.append(
                {
                    "engine": engine,
                    "method": method,
                    "peer": peer,
                    "cases": int(both["case"].nunique()),
                    "rows": len(both),
                    "ratio": median,
                    "ratio_min": float(ratio.min()) if len(ratio) else float("nan"),
                    "ratio_max": float(ratio.max()) if len(ratio) else float("nan"),
                    "verdict": verdict(median),
                }
            )
    return pd.DataFrame(rows, columns=list(PEER_COLUMNS))


__all__ = [
    "CONTACT",
    "FLOAT32_MARGIN",
    "FLOOR",
    "PEER_COLUMNS",
    "SAME",
    "declared_peers",
    "same_scheme",
    "verdict",
]
