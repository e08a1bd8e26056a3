"""One engine on two devices (:mod:`truestep.measures.twins`): a second registration of an
engine's adapter made for a GPU is its twin; the report sets each of the twin's rows beside
the CPU engine's at the same case, method and step, and names every row where they part
beyond round-off; ``run.json`` records the pairs, and a verdict elsewhere reads them."""

from __future__ import annotations

import json
import textwrap

import numpy as np
import pandas as pd
import pytest

from truestep.cases import load_cases
from truestep.measures import engine_facts
from truestep.measures.metrics import ROUND_OFF, ROUND_OFF_FLOAT32
from truestep.measures.twins import TWIN_COLUMNS, twin_rows, twins_of
from truestep.reporting.sections import twin_section


def _row(engine, device, method, dt, status, error, case="bouncing-ball"):
    return {
        "case": case,
        "engine": engine,
        "method": method,
        "dt": dt,
        "dt_kind": "step",
        "device": device,
        "status": status,
        "error": error,
    }


def test_a_twin_s_rows_stand_beside_the_cpu_engine_s_and_part_beyond_round_off():
    """Four rows of a float64 engine and its GPU twin on bouncing-ball: equal errors agree,
    errors 1e-9 of the scale apart part (beyond float64's 1e-11), a crash beside an ok row
    parts, and a step only one of them ran is not compared."""
    case = load_cases("bouncing-ball")[0]
    scale = case.error_scale
    rows = [
        _row("reference", "cpu", "lecture", 0.004, "ok", 0.01),
        _row("reference-gpu", "cuda:0", "lecture", 0.004, "ok", 0.01),
        _row("reference", "cpu", "lecture", 0.002, "ok", 0.005),
        _row("reference-gpu", "cuda:0", "lecture", 0.002, "ok", 0.005 + 1e-9 * scale),
        _row("reference", "cpu", "symplectic-euler", 0.004, "ok", 0.02),
        _row("reference-gpu", "cuda:0", "symplectic-euler", 0.004, "crashed", np.nan),
        _row("reference", "cpu", "symplectic-euler", 0.002, "ok", 0.01),
        _row("reference-gpu", "cuda:0", "symplectic-euler", 0.002, "unsupported", np.nan),
    ]
    table = twin_rows(pd.DataFrame(rows), [case], {"reference-gpu": "reference"})
    assert list(table.columns) == list(TWIN_COLUMNS) and len(table) == 3
    by = {(r.method, r.dt): r for r in table.itertuples(index=False)}
    assert not by["lecture", 0.004].parts and by["lecture", 0.004].difference == 0.0
    assert by["lecture", 0.002].parts and by["lecture", 0.002].difference == pytest.approx(1e-9, rel=1e-3)
    assert by["symplectic-euler", 0.004].parts and by["symplectic-euler", 0.004].twin_status == "ok"
    assert set(table.band) == {ROUND_OFF} and set(table.device) == {"cuda:0"}
    said = "".join(twin_section(table))
    assert "**reference-gpu** on cuda:0 is **reference** on cpu" in said
    assert "they part in 2: bouncing-ball lecture at 0.002" in said
    assert "crashed on cuda:0, ok on cpu" in said


def test_a_float32_twin_is_held_to_float32_s_round_off():
    case = load_cases("bouncing-ball")[0]
    rows = [
        _row("mujoco-warp", "cpu", "Euler", 0.004, "ok", 0.01),
        _row("mujoco-warp-gpu", "cuda:0", "Euler", 0.004, "ok", 0.01 + 5e-5 * case.error_scale),
    ]
    table = twin_rows(pd.DataFrame(rows), [case], {"mujoco-warp-gpu": "mujoco-warp"})
    assert table.band.iloc[0] == ROUND_OFF_FLOAT32 and not table.parts.iloc[0]


def test_a_run_without_twins_has_no_twin_section():
    case = load_cases("bouncing-ball")[0]
    rows = [
        _row("reference", "cpu", "lecture", 0.004, "ok", 0.01),
        _row("pymunk", "cpu", "lecture", 0.004, "ok", 0.01),
    ]
    assert (
        not len(twin_rows(pd.DataFrame(rows), [case]))
        and twin_section(twin_rows(pd.DataFrame(rows), [case])) == []
    )


@pytest.fixture
def reference_on_a_gpu(tmp_path, monkeypatch):
    """``--engines twinmod:ReferenceOnGpu``: the reference's adapter, registered again as
    ``reference-gpu`` on ``cuda:0`` (this machine may have no GPU: its runs then crash)."""
    from truestep import adapters
    from truestep.adapters import warp_runtime

    (tmp_path / "twinmod.py").write_text(
        textwrap.dedent("""
            from truestep.adapters.reference import ReferenceAdapter

            class ReferenceOnGpu(ReferenceAdapter):
                name = "reference-gpu"

                def __init__(self):
                    super().__init__(device="cuda:0")
        """)
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(adapters, "_RESOLVED", dict(adapters._RESOLVED))
    monkeypatch.setattr(warp_runtime, "_GPU_WANTED", [])  # this test's GPU adapter marks no other test
    return "twinmod:ReferenceOnGpu"


def test_a_second_registration_on_a_gpu_is_the_twin_and_the_report_and_record_say_so(
    tmp_path, reference_on_a_gpu
):
    pytest.importorskip("warp")
    from truestep import api
    from truestep.adapters import resolve_engine
    from truestep.adapters.devices import cuda_devices

    assert resolve_engine(reference_on_a_gpu) == "reference-gpu"
    assert twins_of(["reference", "pymunk", "reference-gpu"], recorded=False) == {
        "reference-gpu": "reference"
    }
    assert twins_of(["pymunk", "reference-gpu"], recorded=False) == {}
    tables = api.run(
        "bouncing-ball",
        ["reference", reference_on_a_gpu],
        quick=True,
        analyses=False,
        out=tmp_path / "rep",
        progress=lambda _: None,
    )
    record = json.loads((tmp_path / "rep" / "run.json").read_text())
    assert record["twins"] == {"reference-gpu": "reference"}
    gpu = tables.results[tables.results.engine == "reference-gpu"]
    page = (tmp_path / "rep" / "index.md").read_text()
    assert "### One engine on two devices" in page
    assert f"over {len(gpu)} rows at the same case, method and step" in page
    if cuda_devices() == 0:  # each GPU row crashed beside an ok CPU row: every one parts
        assert set(gpu.status) == {"crashed"} and f"they part in {len(gpu)}" in page
    engine_facts.take(record)
    try:
        assert twins_of(["reference", "reference-gpu"]) == {"reference-gpu": "reference"}
    finally:
        engine_facts.take()
