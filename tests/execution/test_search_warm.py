"""A case's energy scale is made once, in truestep's process, before the searches of that
case fork: each search process used to read it again along the case's reference path
(1.7-1.9 s for the cloths and the rope)."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

from truestep.cases.loader import CASE_DIR, load_case
from truestep.execution import analyses
from truestep.measures import energy_scale


def test_each_case_s_energy_scale_is_made_once_before_its_searches_fork(monkeypatch, tmp_path: Path):
    """Every process that makes the scale writes its pid: only truestep's own does, once,
    and the searches (forked, two at a time) find it made and end as they do without."""
    log = tmp_path / "made"
    real = energy_scale._scale

    def logged(case):
        with log.open("a") as f:
            f.write(f"{os.getpid()}\n")
        return real(case)

    monkeypatch.setattr(energy_scale, "_scale", logged)
    case = load_case(CASE_DIR / "spring-chain.toml")  # a fresh case object: no scale kept for it
    case = dataclasses.replace(case, stability=dataclasses.replace(case.stability, quick=True))
    table = analyses.stability_table([case], ["reference"], quick=True, workers=2)
    assert log.read_text().split() == [str(os.getpid())]
    searched = table[table["status"] == "ok"]
    assert len(searched) >= 5, table[["method", "status", "note"]]
    euler = searched.set_index("method").loc["euler"]
    assert euler["dt_limit"] <= euler["dt_limit_exact"] < euler["dt_unstable"]
