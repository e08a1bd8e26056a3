"""``--out`` only ever replaces a report truestep wrote: anything else is refused with one
line and nothing touched; what a run writes takes its owner and mode from the run."""

from __future__ import annotations

import os
import shutil
import stat
from pathlib import Path

import pytest
from kill_helpers import snapshot

from truestep.cli import main
from truestep.runtime.folder import MARKER, MARKER_TEXT, OutRefused, check_out, prepare

REPORTS = Path(__file__).resolve().parents[2] / "reports"


def _report(where: Path) -> Path:
    """A small folder as truestep writes a report (the marker, tables, figures)."""
    where.mkdir(parents=True)
    (where / MARKER).write_text(MARKER_TEXT)
    (where / "results.csv").write_text("case\n")
    (where / "figures").mkdir()
    (where / "figures" / "a.png").write_bytes(b"\x89PNG")
    return where


def _mine(where: Path) -> Path:
    where.mkdir(parents=True, exist_ok=True)
    (where / "notes.txt").write_text("mine")
    (where / "results.csv").write_text("my table")
    return where


def test_the_published_report_is_marked_as_a_run_marks_it():
    assert (REPORTS / MARKER).read_text() == MARKER_TEXT
    assert check_out(REPORTS) == REPORTS.resolve()


def test_absent_empty_and_marked_folders_may_be_replaced(tmp_path):
    assert check_out(tmp_path / "new") == tmp_path / "new"
    (tmp_path / "empty").mkdir()
    assert check_out(tmp_path / "empty") == tmp_path / "empty"
    rep = _report(tmp_path / "rep")
    assert check_out(rep) == rep
    (tmp_path / "link").symlink_to(rep)
    assert check_out(tmp_path / "link") == rep


REFUSED = {
    "a folder of other files": (lambda t: _mine(t / "x"), "not a report truestep wrote"),
    "a file": (lambda t: (t / "x").write_text("mine") and t / "x", "is a file"),
    "a link to other files": (lambda t: (t / "x").symlink_to(_mine(t / "mine")) or t / "x", "symbolic link"),
    "a report with a file of someone's": (
        lambda t: (_report(t / "x") / "notes.txt").write_text("mine") and t / "x",
        "notes.txt",
    ),
    "a report whose figures are a link": (lambda t: _linked_figures(t), "not a directory"),
    "a report with a link in its figures": (lambda t: _link_in_figures(t), "figures/b.png"),
    "a forged marker that is a link": (lambda t: _forged_marker(t), "not a report"),
}


def _linked_figures(t: Path) -> Path:
    rep = _report(t / "x")
    shutil.rmtree(rep / "figures")
    (rep / "figures").symlink_to(_mine(t / "pictures"))
    return rep


def _link_in_figures(t: Path) -> Path:
    rep = _report(t / "x")
    (rep / "figures" / "b.png").symlink_to("/etc/hostname")
    return rep


def _forged_marker(t: Path) -> Path:
    rep = _mine(t / "x")
    (t / "marker").write_text(MARKER_TEXT)
    (rep / MARKER).symlink_to(t / "marker")
    return rep


@pytest.mark.parametrize("label", list(REFUSED))
def test_anything_else_is_refused_with_one_line_and_nothing_touched(tmp_path, capsys, label):
    make, reason = REFUSED[label]
    out = make(tmp_path)
    before = snapshot(tmp_path)
    with pytest.raises(OutRefused, match=reason):
        check_out(out)
    for argv in (
        ["run", "--quick", "--engines", "reference", "--cases", "free-fall"],
        ["figures"],
        ["bench", "--engines", "reference", "--sizes", "100"],
    ):
        assert main([*argv, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and reason in err[0]
    assert snapshot(tmp_path) == before
    assert not [n for n in os.listdir(tmp_path) if n.startswith(".x.")]


def test_home_and_current_directories_are_refused(tmp_path, monkeypatch, capsys):
    home = _mine(tmp_path / "home")
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(home)
    before = snapshot(home)
    for out in (".", str(home), os.path.expanduser("~")):  # the working folder: refused as that
        assert main(["run", "--quick", "--engines", "reference", "--cases", "free-fall", "--out", out]) == 2
        assert "is the working folder or one above it" in capsys.readouterr().err
    monkeypatch.chdir(tmp_path)  # home, not the working folder: refused as a folder truestep did not write
    assert main(["run", "--quick", "--engines", "reference", "--cases", "free-fall", "--out", str(home)]) == 2
    assert "not a report truestep wrote" in capsys.readouterr().err
    assert snapshot(home) == before


def test_prepare_marks_a_new_folder(tmp_path):
    out = prepare(tmp_path / "bench")
    assert (out / MARKER).read_text() == MARKER_TEXT
    assert prepare(out) == out


def test_the_new_report_takes_its_owner_and_mode_from_the_run(tmp_path):
    rep = tmp_path / "rep"
    shutil.copytree(REPORTS, rep, ignore=shutil.ignore_patterns("*.png", "index.*"))
    os.chmod(rep, 0o777)
    if os.geteuid() == 0:
        os.chown(rep / "figures", 65534, 65534)
    assert main(["run", "--quick", "--engines", "reference", "--cases", "free-fall", "--out", str(rep)]) == 0
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(os.stat(rep).st_mode) == 0o777 & ~umask
    assert {os.stat(p).st_uid for p in [rep, *rep.rglob("*")]} == {os.geteuid()}
    assert (rep / MARKER).read_text() == MARKER_TEXT


def test_the_python_api_refuses_the_same_folders(tmp_path):
    import truestep

    mine = _mine(tmp_path / "mine")
    before = snapshot(mine)
    with pytest.raises(OutRefused, match="not a report truestep wrote"):
        truestep.run("free-fall", engines=["reference"], quick=True, analyses=False, out=mine)
    assert snapshot(mine) == before


def test_scratch_names_planted_beside_out_are_removed_never_followed(tmp_path):
    from truestep.runtime import publish

    elsewhere = _mine(tmp_path / "elsewhere")
    before = snapshot(elsewhere)
    (tmp_path / ".rep.old-999999").symlink_to(elsewhere)
    (tmp_path / ".rep.staging-999998").symlink_to(elsewhere)
    (tmp_path / ".rep.old-999997").write_text("a file")
    done = publish.recover(tmp_path / "rep")
    assert len(done) == 3 and not (tmp_path / "rep").exists()
    assert not [n for n in os.listdir(tmp_path) if n.startswith(".rep.")]
    assert snapshot(elsewhere) == before
