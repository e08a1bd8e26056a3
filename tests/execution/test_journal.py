"""The checkpoints of an interrupted run are data: they round-trip rows, traces and
tables exactly, and nothing planted in the journal is ever loaded or run."""

from __future__ import annotations

import json
import os
import pickle
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from truestep.cases import load_cases
from truestep.cli import main
from truestep.execution.checkpoint_data import DataError, load_json, tables_from, tables_to
from truestep.execution.journal import Journal, JournalError, fingerprint
from truestep.execution.runner import MACHINE_COLUMNS, run_matrix

REPORTS = Path(__file__).resolve().parents[2] / "reports"


class Plant:
    """A pickle that creates a file when it is loaded."""

    def __init__(self, mark: Path) -> None:
        self.mark = mark

    def __reduce__(self):
        return (os.system, (f"touch {self.mark}",))


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """A real journal of a quick run of free-fall, and the run's rows and traces."""
    out = tmp_path_factory.mktemp("journal") / "rep"
    cases = load_cases("free-fall")
    journal = Journal(out)
    journal.start(fingerprint(cases, ["reference"], quick=True))
    traces: dict = {}
    results = run_matrix(
        cases, ["reference"], quick=True, traces=traces, journal=journal, progress=lambda _: None
    )
    return out, cases, results, traces


def _resume(out: Path, cases) -> Journal:
    journal = Journal(out)
    journal.resume(fingerprint(cases, ["reference"], quick=True))
    return journal


def test_a_resumed_sweep_gives_the_rows_and_traces_it_made(swept):
    out, cases, results, traces = swept
    journal = _resume(out, cases)
    again: dict = {}
    resumed = run_matrix(
        cases, ["reference"], quick=True, traces=again, journal=journal, progress=lambda _: None
    )
    pd.testing.assert_frame_equal(resumed.drop(columns="host"), results.drop(columns="host"))
    assert again.keys() == traces.keys()
    for key, (t, e) in traces.items():
        assert np.array_equal(again[key][0], t) and np.array_equal(again[key][1], e, equal_nan=True)
    assert journal.ignored_line() == ""


def test_the_analyses_tables_round_trip_exactly():
    tables = {name: pd.read_csv(REPORTS / f"{name}.csv") for name in ("stability", "restitution", "scaling")}
    tables["scaling"]["steps"] = tables["scaling"]["steps"].astype("Int64")
    tables["scaling"].loc[0, "steps"] = pd.NA
    tables["scaling"].attrs.update(bandwidth_bytes_per_s=1.5e10, budget_s=12.0, note="x")
    tables["empty"] = pd.DataFrame()
    back = tables_from(load_json(json.dumps(tables_to(tables)).encode()))
    for name, table in tables.items():
        pd.testing.assert_frame_equal(back[name], table)
        assert back[name].attrs == table.attrs
        assert back[name].to_csv(index=False) == table.to_csv(index=False)


@pytest.mark.parametrize(
    "text", [b"NaN", b'{"a": Infinity}', b"1e999", b"[" * 100000, pickle.dumps({"a": 1})]
)
def test_anything_but_strict_json_is_refused(text):
    with pytest.raises(DataError):
        load_json(text)


def test_planted_and_damaged_checkpoints_are_ignored_never_loaded(swept, tmp_path):
    out, cases, results, _ = swept
    mark = tmp_path / "PAYLOAD-RAN"
    journal = Journal(out)
    sweeps = sorted(p for p in journal.dir.iterdir() if p.name.startswith("sweep-"))
    saved = {p: p.read_bytes() for p in sweeps}
    try:
        sweeps[0].write_bytes(pickle.dumps(Plant(mark)))
        data = bytearray(saved[sweeps[1]])
        data[-10] = ord("7") if data[-10] != ord("7") else ord("3")
        sweeps[1].write_bytes(bytes(data))
        for name in ("analyses.pkl", "sweep-0123456789abcdef.pkl", "evil.npz"):
            (journal.dir / name).write_bytes(pickle.dumps(Plant(mark)))
        (journal.dir / "analyses.json").symlink_to("/dev/zero")
        os.mkfifo(journal.dir / ("sweep-" + "0" * 32 + ".json"))
        resumed = _resume(out, cases)
        line = resumed.ignored_line()
        assert "ignored 7 entries" in line and "never loaded" in line and "\n" not in line
        assert resumed.analyses() is None
        rows = run_matrix(cases, ["reference"], quick=True, journal=resumed, progress=lambda _: None)
        pd.testing.assert_frame_equal(
            rows.drop(columns=list(MACHINE_COLUMNS)), results.drop(columns=list(MACHINE_COLUMNS))
        )
        assert not mark.exists()
    finally:
        for p in journal.dir.iterdir():
            if p not in saved:
                p.unlink()
        for p, data in saved.items():
            p.write_bytes(data)


def test_a_checkpoint_of_another_run_is_not_taken(swept, tmp_path):
    out = swept[0]
    other = Journal(tmp_path / "other")
    other.start(fingerprint(load_cases("harmonic-oscillator"), ["reference"], quick=True))
    name = next(p.name for p in Journal(out).dir.iterdir() if p.name.startswith("sweep-"))
    (other.dir / name).write_bytes((Journal(out).dir / name).read_bytes())
    resumed = _resume(tmp_path / "other", load_cases("harmonic-oscillator"))
    assert "written by another run" in resumed.ignored_line()


def test_a_journal_that_is_a_link_or_holds_no_journal_is_not_resumed(tmp_path, capsys):
    cases = load_cases("free-fall")
    fp = fingerprint(cases, ["reference"], quick=True)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / ".rep.partial").symlink_to(elsewhere)
    with pytest.raises(JournalError, match="symbolic link"):
        Journal(tmp_path / "rep").resume(fp)
    (tmp_path / ".rep.partial").unlink()
    (tmp_path / ".rep.partial").mkdir()
    (tmp_path / ".rep.partial" / "journal.json").write_bytes(pickle.dumps(fp))
    with pytest.raises(JournalError, match="not a journal"):
        Journal(tmp_path / "rep").resume(fp)
    argv = [
        "run",
        "--quick",
        "--cases",
        "free-fall",
        "--engines",
        "reference",
        "--out",
        str(tmp_path / "rep"),
        "--resume",
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a journal" in err[0]


def test_starting_afresh_replaces_a_link_in_the_journals_place(tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "keep.txt").write_text("mine")
    (tmp_path / ".rep.partial").symlink_to(elsewhere)
    journal = Journal(tmp_path / "rep")
    journal.start(fingerprint(load_cases("free-fall"), ["reference"], quick=True))
    assert journal.dir.is_dir() and not journal.dir.is_symlink()
    assert (elsewhere / "keep.txt").read_text() == "mine"
    assert oct(journal.dir.stat().st_mode & 0o777) == "0o700"
