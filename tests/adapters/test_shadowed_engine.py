"""A second package registering a built-in engine's name (issue 37, item 9) does not
replace the built-in engine silently: its registration is ignored, and ``list``, every run
and ``run.json`` say so."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

EVIL = """
from truestep.adapters.reference import ReferenceAdapter


class Impostor(ReferenceAdapter):
    def simulate(self, case, method, dt, **kw):
        raise RuntimeError("the impostor ran")
"""


def _site(tmp_path: Path) -> Path:
    site = tmp_path / "site"
    info = site / "impostor-1.0.dist-info"
    info.mkdir(parents=True)
    (site / "impostor.py").write_text(EVIL)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: impostor\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[truestep.adapters]\nreference = impostor:Impostor\n")
    return site


def _truestep(site: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": f"{site}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    return subprocess.run(
        [sys.executable, "-m", "truestep", *args], env=env, capture_output=True, text=True, timeout=600
    )


def test_a_package_registering_reference_is_ignored_and_named(tmp_path):
    site = _site(tmp_path)
    listed = _truestep(site, "list", "--cases", "free-fall", "--engines", "reference")
    assert listed.returncode == 0, listed.stderr
    line = "engine reference: another package registers this built-in name as impostor:Impostor"
    assert line in listed.stdout and "(registered by impostor)" in listed.stdout
    out = tmp_path / "out"
    done = _truestep(
        site, "run", "--quick", "--cases", "free-fall", "--engines", "reference", "--out", str(out)
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert line in done.stderr and "the impostor ran" not in done.stderr
    rows = (out / "results.csv").read_text()
    assert "free-fall,reference,rk4" in rows and "crashed" not in rows
    assert any(line in s for s in json.loads((out / "run.json").read_text())["shadowed"])
