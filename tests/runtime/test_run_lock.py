"""One run per ``--out``: a second is refused at once naming the first; a lock whose run
is gone is taken over, and ``--resume`` of that run works."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

from truestep.cli import main
from truestep.runtime.run_lock import LockBusy, RunLock, lock_path

RUN = ["run", "--quick", "--engines", "reference", "--cases", "free-fall"]

HOLD = """
import sys, time
from pathlib import Path
from truestep.runtime.run_lock import RunLock
lock = RunLock(Path(sys.argv[1]))
lock.acquire()
print("held", flush=True)
time.sleep(60)
"""


@pytest.fixture()
def held(tmp_path):
    """``tmp_path/rep`` locked by another process, as a running truestep run locks it."""
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(tmp_path / "rep")], stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout.readline().strip() == "held"
    yield proc
    proc.kill()
    proc.wait()


def test_a_second_run_is_refused_at_once_naming_the_first(tmp_path, held, capsys):
    (tmp_path / "alias").symlink_to(tmp_path)
    for out in (tmp_path / "rep", tmp_path / "alias" / "rep", f"{tmp_path}/./rep/"):
        started = time.monotonic()
        assert main([*RUN, "--out", str(out)]) == 2
        assert time.monotonic() - started < 10
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"pid {held.pid}" in err[0] and "started" in err[0]
    assert main([*RUN, "--resume", str(tmp_path / "rep")]) == 2
    assert f"pid {held.pid}" in capsys.readouterr().err
    assert not (tmp_path / "rep").exists() and not (tmp_path / ".rep.partial").exists()


def test_the_lock_is_one_per_folder_and_released(tmp_path):
    lock = RunLock(tmp_path / "rep")
    lock.acquire()
    with pytest.raises(LockBusy, match=f"pid {os.getpid()}"):
        RunLock(tmp_path / "rep").acquire()
    with RunLock(tmp_path / "other"):
        pass
    lock.release()
    assert not lock_path(tmp_path / "rep").exists()
    with RunLock(tmp_path / "rep"):
        assert json.loads(lock_path(tmp_path / "rep").read_text())["pid"] == os.getpid()


def test_a_lock_whose_run_is_gone_is_taken_over(tmp_path, held, capsys):
    held.kill()
    held.wait()
    assert lock_path(tmp_path / "rep").exists()
    assert main([*RUN, "--out", str(tmp_path / "rep")]) == 0
    assert f"took over the lock of truestep run pid {held.pid}" in capsys.readouterr().err
    assert not lock_path(tmp_path / "rep").exists()


def test_a_link_in_the_locks_place_is_refused(tmp_path):
    (tmp_path / ".rep.lock").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(LockBusy, match="symbolic link"):
        RunLock(tmp_path / "rep").acquire()
    assert not (tmp_path / "elsewhere").exists()
