"""A lone surrogate in an adapter's message (issue 37, item 11): it stopped the report at
the CSV writer with a traceback (and every ``--resume`` the same way); now the row says
what the engine said, its undecodable bytes escaped, and the report is written."""

from __future__ import annotations

import pandas as pd

from truestep.cli import main

GARBLED = """
from truestep.adapters.reference import ReferenceAdapter


class Garbled(ReferenceAdapter):
    name = "garbled"

    def simulate(self, case, method, dt, **kw):
        raise RuntimeError("the device said " + b"\\xff\\xfe".decode("utf-8", "surrogateescape"))
"""


def test_a_message_with_undecodable_bytes_is_a_row_and_the_report_is_written(tmp_path, monkeypatch, capsys):
    (tmp_path / "garbled_adapter.py").write_text(GARBLED)
    monkeypatch.syspath_prepend(str(tmp_path))
    out = tmp_path / "out"
    args = [
        "run",
        "--quick",
        "--cases",
        "free-fall",
        "--engines",
        "garbled_adapter:Garbled",
        "--out",
        str(out),
    ]
    assert main(args) == 0, capsys.readouterr().err[-2000:]
    rows = pd.read_csv(out / "results.csv")
    crashed = rows[rows["status"] == "crashed"]
    assert (
        len(crashed) and crashed["message"].str.contains(r"the device said \udcff\udcfe", regex=False).all()
    )
    assert main(["gate", "--results", str(out / "results.csv"), "-q"]) in (0, 1)
    assert "Traceback" not in capsys.readouterr().err
