"""Malformed tables handed to ``truestep gate``: exit 2 and one line, never a traceback or
a quiet pass."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from truestep.cli import main

REPORTS = Path(__file__).resolve().parents[1] / "reports"


@pytest.fixture()
def run_dir(tmp_path):
    for name in ("results.csv", "stability.csv", "restitution.csv"):
        shutil.copy(REPORTS / name, tmp_path / name)
    return tmp_path


def _gate(path: Path, capsys) -> tuple[int, str]:
    code = main(["gate", "--results", str(path / "results.csv"), "-q"])
    return code, capsys.readouterr().err


def test_the_published_tables_are_read(run_dir, capsys):
    assert _gate(run_dir, capsys)[0] in (0, 1)


def _header(path: Path) -> str:
    return path.read_text().splitlines()[0]


@pytest.mark.parametrize(("table", "damage"), [
    ("results.csv", lambda p: p.write_text("")),
    ("results.csv", lambda p: p.write_text(_header(p) + "\n")),  # header only
    ("results.csv", lambda p: p.write_bytes(b"\0" * 64)),
    ("results.csv", lambda p: p.write_bytes(b"case,engine\n\xff\xfe,x\n")),
    ("results.csv", lambda p: p.write_text(p.read_text() + "a,b\n")),  # ragged
    ("results.csv", lambda p: p.write_text(p.read_text().replace(",ok,", ",7,", 1)
                                           .replace(",ok,", ",fine,", 1))),
    ("results.csv", lambda p: p.write_text(p.read_text().replace(",step,ok,", ",step,ok,x", 1))),
    ("stability.csv", lambda p: p.write_bytes(b"\x89PNG\r\n\x1a\n\0\0")),
    ("stability.csv", lambda p: p.write_text("case,engine\nx,y\n")),  # missing columns
    ("restitution.csv", lambda p: (p.unlink(), p.mkdir())),  # a directory
])
def test_malformed_tables_are_exit_2_and_one_line(run_dir, capsys, table, damage):
    damage(run_dir / table)
    code, err = _gate(run_dir, capsys)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1 and len(lines[0]) < 300 and "Traceback" not in err
    assert table in lines[0]


def test_an_unusable_out_fails_before_the_sweep(tmp_path, capsys):
    target = tmp_path / "a-file"
    target.write_text("kept")
    code = main(["run", "--quick", "--cases", "free-fall", "--engines", "reference",
                 "--out", str(target)])
    err = capsys.readouterr().err
    assert code == 2 and "is a file" in err and "sweep" not in err
    assert target.read_text() == "kept"


@pytest.mark.parametrize("table", ["results.csv", "stability.csv", "restitution.csv"])
def test_a_malformed_baseline_is_exit_2_and_one_line_and_an_api_error(run_dir, tmp_path, capsys,
                                                                      table):
    """The baseline directory is read as strictly as the results: by ``truestep gate
    --baseline`` (exit 2) and by ``truestep.compare`` (:class:`TableError`)."""
    import truestep
    from truestep.tables_io import TableError

    base = tmp_path / "baseline"
    base.mkdir()
    for name in ("results.csv", "stability.csv", "restitution.csv"):
        shutil.copy(run_dir / name, base / name)
    (base / table).write_text("case,engine,method\n1,2,3\n")
    code = main(["gate", "--results", str(run_dir / "results.csv"), "--baseline", str(base), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and table in err and "Traceback" not in err
    assert len([line for line in err.splitlines() if line.strip()]) == 1
    with pytest.raises(TableError, match=table):
        truestep.compare(base, run_dir)
    with pytest.raises(TableError, match="not a directory"):
        truestep.compare(base / table, run_dir)
