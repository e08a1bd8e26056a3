"""Only regular files are read, their size capped before a byte is read: FIFOs, devices,
directories and sparse giants are one-line refusals, never a hang or a MemoryError."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from truestep.cases import CaseError, load_case
from truestep.cli import main
from truestep.runtime.files import FileRefused, read_regular

CAP = 1024


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _sparse(path: Path, size: int = 20 * 2**30) -> Path:
    with path.open("w") as fh:
        fh.truncate(size)
    return path


def _link(path: Path, to: str) -> Path:
    path.symlink_to(to)
    return path


SPECIAL = {
    "a FIFO": (_fifo, "FIFO"),
    "a link to /dev/zero": (lambda p: _link(p, "/dev/zero"), "character device"),
    "a link to /dev/urandom": (lambda p: _link(p, "/dev/urandom"), "character device"),
    "a sparse file of 20 GiB": (_sparse, "over the"),
    "a directory": (lambda p: p.mkdir() or p, "directory"),
    "nothing": (lambda p: p, "no such file"),
}


@pytest.mark.parametrize("label", list(SPECIAL))
def test_anything_but_a_small_regular_file_is_refused_at_once(tmp_path, label):
    make, reason = SPECIAL[label]
    path = make(tmp_path / "x.toml")
    started = time.monotonic()
    with pytest.raises(FileRefused) as err:
        read_regular(path, CAP)
    assert time.monotonic() - started < 1.0
    assert reason in str(err.value) and str(err.value).startswith(str(path))
    assert "\n" not in str(err.value)


def test_a_regular_file_is_read_and_a_link_to_one_followed_unless_asked(tmp_path):
    path = tmp_path / "a.toml"
    path.write_bytes(b"x" * CAP)
    assert read_regular(path, CAP) == b"x" * CAP
    link = _link(tmp_path / "b.toml", str(path))
    assert read_regular(link, CAP) == b"x" * CAP
    with pytest.raises(FileRefused, match="symbolic link"):
        read_regular(link, CAP, follow_links=False)
    path.write_bytes(b"x" * (CAP + 1))
    with pytest.raises(FileRefused, match="over the"):
        read_regular(path, CAP)


@pytest.mark.parametrize("label", ["a FIFO", "a link to /dev/zero", "a sparse file of 20 GiB"])
def test_load_case_and_the_cli_refuse_special_case_files(tmp_path, capsys, label):
    make, reason = SPECIAL[label]
    cases = tmp_path / "cases"
    cases.mkdir()
    path = make(cases / "special.toml")
    with pytest.raises(CaseError, match=reason):
        load_case(path)
    assert main(["list", "--cases", str(cases)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and reason in err[0]


REPORTS = Path(__file__).resolve().parents[2] / "reports"


@pytest.mark.parametrize("where", ["results", "stability", "restitution", "baseline", "gates"])
@pytest.mark.parametrize("label", ["a FIFO", "a link to /dev/urandom", "a sparse file of 20 GiB"])
def test_gate_refuses_special_tables_baselines_and_gates_files(tmp_path, capsys, where, label):
    make, reason = SPECIAL[label]
    run = tmp_path / "run"
    base = tmp_path / "base"
    for d in (run, base):
        d.mkdir()
        for name in ("results", "stability", "restitution"):
            (d / f"{name}.csv").write_bytes((REPORTS / f"{name}.csv").read_bytes())
    argv = ["gate", "--results", str(run / "results.csv"), "-q"]
    if where in ("results", "stability", "restitution"):
        (run / f"{where}.csv").unlink()
        make(run / f"{where}.csv")
    elif where == "baseline":
        (base / "results.csv").unlink()
        make(base / "results.csv")
        argv += ["--baseline", str(base)]
    else:
        argv += ["--gates", str(make(tmp_path / "gates.toml"))]
    started = time.monotonic()
    assert main(argv) == 2
    assert time.monotonic() - started < 30.0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and reason in err[0] and "Traceback" not in err[0]
