"""A disk that fills (here: a file size limit, ``ulimit -f``) while the report is written:
exit 2 with one line naming what could not be written, the previous report untouched,
the finished sweeps kept for ``--resume``."""

from __future__ import annotations

import resource
import subprocess
import sys

from kill_helpers import snapshot

from truestep.runtime.folder import MARKER, MARKER_TEXT


def test_a_full_disk_is_exit_2_with_one_line_and_the_old_report_survives(tmp_path):
    old = tmp_path / "rep"
    old.mkdir()
    (old / MARKER).write_text(MARKER_TEXT)
    (old / "results.csv").write_text("the previous report\n")
    before = snapshot(old)

    def small_files() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (24 * 1024, 24 * 1024))

    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "truestep",
            "run",
            "--quick",
            "--engines",
            "reference",
            "--cases",
            "free-fall",
            "--out",
            "rep",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=small_files,
    )
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert run.returncode == 2, run.stderr
    assert "Traceback" not in run.stderr and lines[-1].startswith("truestep: error: cannot write")
    assert "File too large" in lines[-1] and "holds the previous report" in lines[-1]
    assert sum(line.startswith("truestep: error") for line in lines) == 1
    assert snapshot(old) == before
    assert (tmp_path / ".rep.partial" / "journal.json").is_file()
