"""The named properties a case may ask for (``properties = [...]``), with the kind of case
each reads: the vocabulary the loader checks a case file against. The functions that
measure them live above the cases, in :mod:`truestep.measures.properties`, and may only
register names listed here (a test holds the two the same)."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

PROPERTY_KINDS: Mapping[str, str] = MappingProxyType(
    {
        name: "particles"
        for name in (
            "momentum_drift",
            "min_signed_volume",
            "max_penetration",
            "final_speed",
            "max_strain",
            "stopping_distance_error",
            "apex_height_error",
            "bounce_time_error",
            "spawn_rate_z",
            "population_z",
            "strand_error",
            "strand_count",
            "tunnelled",
        )
    }
)
"""Property name -> the kind of case it reads (``particles``: every property of truestep
reads particles); a case of another kind that names it is refused when it loads."""
