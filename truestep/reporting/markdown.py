"""Markdown building blocks of the report: numbers as text, tables, links.

Every number goes through :func:`fmt` (three significant figures); every table through
:func:`md_table`; a long table folds away with :func:`folded` (a ``<details>`` block that
GitHub and the HTML page both show closed).
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from truestep.runtime.visible import visible
from truestep.tables.spec import labels


def fmt(x: object, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "" if x is None or np.isnan(x) else ("inf" if x > 0 else "-inf")
    if isinstance(x, float | np.floating):
        return f"{x:.{digits}g}"
    return str(x)


ESCAPED = "\\`*_[]<>|!#&$~"
"""Characters that Markdown (or HTML inside it) would read as markup; :func:`text`
escapes each with a backslash."""
_ESCAPE = re.compile("([" + re.escape(ESCAPED) + "])")


def text(value: object) -> str:
    """``value`` as Markdown that shows exactly its characters: whitespace (new lines
    included) collapsed to single spaces, hidden characters (controls, bidirectional
    controls, zero-width ones) written as escapes (:func:`truestep.runtime.visible.visible`),
    every markup character backslash-escaped. Everything a case file or an adapter wrote
    (titles, descriptions, messages, engine and method names) goes into the report
    through it, so it can neither inject markup nor embed a file nor hide a character."""
    return _ESCAPE.sub(r"\\\1", visible(" ".join(str(value).split())))


def _cell(v: object) -> str:
    return text(v) if isinstance(v, str) else fmt(v)


def md_table(df: pd.DataFrame) -> str:
    """A pipe table with numbers to three significant digits; text cells go through
    :func:`text`."""
    if df.empty:
        return "_(no rows)_\n"
    head = "| " + " | ".join(str(c) for c in df.columns) + " |"
    sep = "|" + "|".join("---" for _ in df.columns) + "|"
    body = ["| " + " | ".join(_cell(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join([head, sep, *body]) + "\n"


def slug(title: str) -> str:
    """The anchor of a heading, as GitHub makes it: lower case, spaces to dashes,
    punctuation dropped."""
    text = re.sub(r"[^\w\- ]", "", title.strip().lower())
    return re.sub(r" ", "-", text)


def link(title: str) -> str:
    """A markdown link to the heading ``title``."""
    return f"[{title}](#{slug(title)})"


def folded(summary: str, body: str) -> str:
    """``body`` (markdown) in a ``<details>`` block that opens on ``summary``."""
    return f"<details><summary>{summary}</summary>\n\n{body}\n</details>\n"


UNITS: dict[str, str] = {
    **labels(),
    "dt_survived": "dt_survived (s)",
    "slower_by": "slower by (x)",
    "apex_height_error": "apex height error (relative)",
    "bounce_time_error": "bounce time error (s)",
    "max_penetration": "max penetration (m)",
    "momentum_drift": "momentum error (relative)",
    "max_strain": "max strain (relative)",
    "min_signed_volume": "min signed volume (of start)",
    "final_speed": "final speed (m/s)",
    "stopping_distance_error": "stopping distance error (m)",
    "spawn_rate_z": "spawn rate (z-score)",
    "population_z": "population (z-score)",
    "strand_error": "strand error (m)",
    "strand_count": "strands (count)",
    "tunnelled": "tunnelled (particles)",
}
"""Column headers with their units, for the tables the report shows (the CSV files keep
the bare names other tools read): the tables' columns' (:func:`truestep.tables.spec.labels`),
then those of the report's own columns and of the properties."""


def with_units(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with every column the report knows a unit for renamed to say it."""
    return df.rename(columns={c: UNITS[c] for c in df.columns if c in UNITS})
