"""The rows of more than 5 s of stepping and what each buys (issue 34, item 3): listed in
the report beside the same method's next coarser step, recomputed here from the tables."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from truestep.measures.picks import LONG_ROW_S, costly_rows

REPORTS = Path(__file__).resolve().parents[2] / "reports"
COLUMNS = ["case", "engine", "method", "dt", "dt_kind", "status", "error", "wall_s"]


def test_a_long_row_is_listed_beside_its_next_coarser_step():
    """Three steps of one method: only the finest is long; its neighbour is the middle
    step, not the coarsest; a long adaptive row is set beside the next looser tolerance;
    a long row at its coarsest step has none; short rows and rows not run are not listed."""
    rows = [
        ("c", "e", "m", 1e-3, "step", "ok", 1e-4, 6.0),
        ("c", "e", "m", 2e-3, "step", "ok", 4e-4, 3.0),
        ("c", "e", "m", 4e-3, "step", "ok", 1.6e-3, 1.5),
        ("c", "e", "a", 1e-8, "tolerance", "ok", 1e-9, 7.0),
        ("c", "e", "a", 1e-6, "tolerance", "ok", 1e-7, 0.5),
        ("c", "f", "m", 4e-3, "step", "unstable", np.nan, 9.0),
        ("c", "g", "m", 4e-3, "skipped", "skipped", np.nan, 99.0),
    ]
    table = costly_rows(pd.DataFrame(rows, columns=COLUMNS)).set_index(["engine", "method"])
    assert list(table.index) == [("f", "m"), ("e", "a"), ("e", "m")]  # longest first
    assert table.loc[("e", "m"), ["coarser_dt", "coarser_wall_s", "coarser_error"]].tolist() == [
        2e-3,
        3.0,
        4e-4,
    ]
    assert table.loc[("e", "a"), "coarser_dt"] == 1e-6
    assert np.isnan(table.loc[("f", "m"), "coarser_dt"]) and np.isnan(table.loc[("f", "m"), "error"])


def _escaped(name: str) -> str:
    return name.replace("_", "\\_")


def test_the_report_lists_every_long_row_of_the_published_run():
    """Every row of the published results that ran and took more than 5 s is a line of the
    report, with its time, its error and its neighbour's, read back from the tables."""
    results = pd.read_csv(REPORTS / "results.csv")
    ran = results[~results["status"].isin(["unsupported", "skipped"])]
    long = ran[pd.to_numeric(ran["wall_s"], errors="coerce") > LONG_ROW_S]
    page = (REPORTS / "index.md").read_text()
    listed = re.findall(
        r"^- (\S+) (\S+) / (\S+) at (?:dt|tol) ([0-9.e+-]+)(?: s)?: ([0-9.e+-]+) s, ", page, re.M
    )
    assert len(listed) == len(long)
    for r in long.itertuples(index=False):  # a method may have several long rows, one per step
        # a step is printed to three digits: 3.13e-05 for a carried-on 3.125e-05
        key = (r.case, r.engine, _escaped(r.method))
        line = next(
            (x for x in listed if x[:3] == key and float(x[3]) == pytest.approx(r.dt, rel=5e-3)), None
        )
        assert line is not None, (key, r.dt)
        assert line[4] == f"{r.wall_s:.3g}"  # printed to three digits
        same = ran[(ran["case"] == r.case) & (ran["engine"] == r.engine) & (ran["method"] == r.method)]
        coarser = same[same["dt"] > r.dt]["dt"]
        if len(coarser):
            neighbour = same[same["dt"] == coarser.min()].iloc[0]
            head = f"- {key[0]} {key[1]} / {key[2]} at "
            at = rf"^{re.escape(head)}(?:dt|tol) {re.escape(line[3])}\b.*$"
            found = re.search(at, page, re.M)
            assert found is not None, at
            text = found.group(0)
            finite = np.isfinite(neighbour["error"])
            was = f"error {neighbour['error']:.3g}" if finite else "no error measured"
            assert was in text and f"{neighbour['wall_s']:.3g} s" in text, text
