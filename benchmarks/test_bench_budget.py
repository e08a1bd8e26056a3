"""``truestep bench --budget`` bounds the whole table's wall time (a wall-clock claim, so it
lives here and not in the unit tests, whose verdicts never depend on the machine's load).

Run: ``python -m pytest benchmarks/test_bench_budget.py -q`` on an idle machine.
"""

from __future__ import annotations

import pytest

from truestep.adapters import get_adapter
from truestep.execution import bench


def compile_reference_loops() -> None:
    """The reference's loops for the rain scene, compiled (or loaded) before the clock runs."""
    reference = get_adapter("reference")
    for method in reference.methods:
        if method not in reference.adaptive_methods and method != "implicit-euler":
            reference.prepare(bench.rain_case(10), method)


SLACK_S = 0.25
"""Assembling the table after the last child: a few ms on an idle machine."""


@pytest.mark.engine
def test_the_whole_table_keeps_within_its_budget():
    compile_reference_loops()
    budget = 10.0
    out = bench.scaling_table(
        ["reference", "pymunk"],
        sizes=(10, 100, 1000, 10_000, 100_000),
        budget_s=budget,
        target_s=0.05,
        progress=lambda line: None,
    )
    # the bandwidth measurement, compiling, the warm-ups and every child count
    assert out.attrs["elapsed_s"] <= budget + SLACK_S
    reference = out[(out["engine"] == "reference") & (out["method"] == "lecture")]
    assert (reference["status"] == "ok").sum() >= 2  # more than one size of the reference
    late = out[out["note"].str.contains("budget")]
    assert (late["status"] == "skipped").all()
