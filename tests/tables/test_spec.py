"""The tables' column spec (:mod:`truestep.tables.spec`) is what the tables, their readers,
the baseline, the gates' schema, the report and the docs use: checked against the
published tables and each consumer."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from truestep.cases import gate_kinds
from truestep.ci import baseline
from truestep.execution.runner import MACHINE_COLUMNS, RESULT_COLUMNS
from truestep.reporting.markdown import UNITS
from truestep.tables import io as tables_io
from truestep.tables.spec import DERIVED, RESULTS, TABLES, compared, labels, markdown

ROOT = Path(__file__).resolve().parents[2]
REPORTS = ROOT / "reports"


@pytest.mark.parametrize("name", list(TABLES))
def test_the_published_tables_have_the_declared_columns_in_order(name):
    """A run writes each table with its spec's columns, in order (results: then one column
    per property), and a row's keys are unique."""
    table = pd.read_csv(REPORTS / f"{name}.csv", keep_default_na=False, na_values=[""])
    spec = TABLES[name]
    assert list(table.columns[: len(spec.names)]) == spec.names
    extra = list(table.columns[len(spec.names) :])
    assert extra == ([] if name != "results" else sorted(extra))
    assert not table.duplicated(subset=list(spec.keys)).any()
    for c in spec.columns:
        if c.numeric:
            assert pd.api.types.is_numeric_dtype(table[c.name]), c.name
        if c.least is not None:
            values = table[c.name].dropna()
            assert (values >= c.least).all() and (c.most is None or (values <= c.most).all()), c.name


def test_the_readers_read_the_spec():
    assert RESULT_COLUMNS == RESULTS.names
    assert set(MACHINE_COLUMNS) == {"wall_s", "wall_s_spread", "repeats", "host", "case_source"}
    for name in tables_io.READ:
        assert tables_io.KEYS[name] == TABLES[name].keys
        assert set(tables_io.NUMERIC[name]) == {c.name for c in TABLES[name].columns if c.numeric}
        assert tables_io.REQUIRED[name] <= set(TABLES[name].names)
    assert gate_kinds.QUANTITIES == {"error", "energy_drift", "energy_drift_final", "nfev"}


def test_a_value_out_of_the_declared_bounds_is_refused(tmp_path):
    """``least``/``most``/``whole`` of a column are what a reader checks."""
    rows = pd.read_csv(REPORTS / "restitution.csv")
    for column, value in (("e_set", 1.5), ("bounce", 2.5), ("bounce", 0), ("e_set", -0.1)):
        bad = rows.copy()
        bad.loc[0, column] = value
        path = tmp_path / "restitution.csv"
        bad.to_csv(path, index=False)
        with pytest.raises(tables_io.TableError, match=f"column {column}"):
            tables_io.read_table(path, "restitution", set())


def test_the_baseline_compares_what_the_spec_says():
    assert baseline.TOLERANCES == {
        "error": 1e-3,
        "energy_drift": 1e-3,
        "nfev": 0.02,
        "dt_limit": 0.01,
        "order": 0.05,
        "e_error": 0.005,
        "wall_ratio": 0.5,
    }
    assert baseline.FLOORS == {"error": 1e-12, "energy_drift": 1e-12}
    assert set(compared()) == set(baseline.TOLERANCES) and set(DERIVED) <= set(compared())
    for name, c in compared().items():
        assert c.why, name


def test_a_table_refuses_a_column_it_does_not_declare():
    with pytest.raises(KeyError, match="no column 'speed'"):
        TABLES["stability"].frame([{"case": "a", "speed": 1.0}])
    frame = TABLES["stability"].frame([{"case": "a", "engine": "e"}])
    assert list(frame.columns) == TABLES["stability"].names


def test_the_report_labels_and_the_help_come_from_the_spec():
    for name, header in labels().items():
        assert UNITS[name] == header
    assert UNITS["dt"] == "dt (s; tol if adaptive)" and UNITS["wall_s"] == "wall (s)"
    out = subprocess.run(
        [sys.executable, "-m", "truestep", "gate", "--help"], capture_output=True, text=True, check=True
    ).stdout
    assert ", ".join(compared()) in " ".join(out.split())


def test_the_readme_documents_every_column_as_the_spec_does():
    """The README's column tables are :func:`markdown`'s output, word for word (regenerate
    with ``python -c "from truestep.tables.spec import markdown; print(markdown())"``)."""
    readme = (ROOT / "README.md").read_text()
    assert markdown() in readme
    for table in TABLES.values():
        for c in table.columns:
            assert f"| `{c.name}` |" in readme
