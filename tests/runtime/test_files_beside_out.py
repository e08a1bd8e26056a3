"""Files beside ``--out`` are the user's (issue 37, items 1-3): a hard link or FIFO in the
lock's place is refused before anything is written to it; an empty ``--out`` is exit 2,
not ``reports/``; a folder of the user's under a scratch or journal name is never
deleted."""

from __future__ import annotations

import os

import pytest

from truestep.cli import main
from truestep.execution.journal import Journal, JournalError
from truestep.runtime.publish import recover
from truestep.runtime.run_lock import LockBusy, RunLock


def test_a_hard_link_in_the_locks_place_is_refused_and_its_file_kept(tmp_path):
    mine = tmp_path / "thesis.txt"
    mine.write_text("years of work")
    os.link(mine, tmp_path / ".rep.lock")
    with pytest.raises(LockBusy, match="hard link"):
        RunLock(tmp_path / "rep").acquire()
    assert mine.read_text() == "years of work"


def test_a_fifo_in_the_locks_place_is_refused_naming_it(tmp_path):
    os.mkfifo(tmp_path / ".rep.lock")
    with pytest.raises(LockBusy, match=r"\.rep\.lock is not a regular file"):
        RunLock(tmp_path / "rep").acquire()


def test_an_empty_out_is_exit_2_and_reports_is_not_touched(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "reports").mkdir()
    (tmp_path / "reports" / "mine.txt").write_text("keep")
    assert main(["run", "--quick", "--cases", "free-fall", "--engines", "reference", "--out", ""]) == 2
    assert "--out: an empty path" in capsys.readouterr().err
    assert (tmp_path / "reports" / "mine.txt").read_text() == "keep"


@pytest.mark.parametrize(
    ("argv", "said"),
    [
        (["figures", "--out", ""], "--out: an empty path"),
        (["bench", "--engines", "reference", "--sizes", "10", "--out", " "], "--out: an empty path"),
        (["baseline", "save", "--results", "results.csv", ""], "DIR: an empty path"),
        (["baseline", "save", "--results", "results.csv", "."], "DIR: . is the working folder"),
        (
            ["run", "--quick", "--cases", "free-fall", "--engines", "reference", "--out", ".."],
            "the working folder",
        ),
        (["figures", "--out", "."], "--out: . is the working folder"),
    ],
    ids=["figures-empty", "bench-blank", "baseline-empty", "baseline-here", "run-above", "figures-here"],
)
def test_no_command_writes_into_an_empty_out_or_replaces_the_working_folder(
    tmp_path, monkeypatch, capsys, argv, said
):
    """Every command that writes a folder refuses an empty value (an unset variable) and
    the working folder or one above it, which it would replace whole: exit 2, one line,
    nothing written."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.txt").write_text("keep")
    assert main(argv) == 2
    assert said in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.txt"]


def test_a_users_folder_under_a_staging_name_of_a_dead_run_is_left(tmp_path):
    dead = 2**22 + 12345  # above any pid this machine hands out
    theirs = tmp_path / f".rep.staging-{dead}"
    theirs.mkdir()
    (theirs / "notes.txt").write_text("mine")
    ours = tmp_path / f".rep.old-{dead}"
    ours.mkdir()  # empty: what a killed run leaves before it writes anything
    said = recover(tmp_path / "rep")
    assert (theirs / "notes.txt").read_text() == "mine"
    assert not ours.exists()
    assert any("left .rep.staging" in line for line in said)


def test_a_users_folder_under_the_journals_name_is_refused_not_deleted(tmp_path):
    folder = tmp_path / ".rep.partial"
    folder.mkdir()
    (folder / "data.csv").write_text("1,2,3")
    journal = Journal(tmp_path / "rep")
    with pytest.raises(JournalError, match="truestep did not make"):
        journal.start({"cases": []})
    assert (folder / "data.csv").read_text() == "1,2,3"
