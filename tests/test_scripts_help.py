"""Every script in ``benchmarks/`` and ``tools/`` answers ``--help`` and does nothing else
(issue 38, item 5): ``refresh_quick_baseline.py --help`` started a quick run that overwrote the
committed baseline; the two campaigns failed at import (``fuzz_strategies`` had moved)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted(
    p
    for p in [*(ROOT / "benchmarks").glob("*.py"), *(ROOT / "tools").glob("*/*.py")]
    if not p.name.startswith("test_")
)
BASELINE = ROOT / "tests" / "baselines" / "quick"


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_help_answers_and_changes_nothing(script):
    before = {p.name: p.stat().st_mtime_ns for p in BASELINE.iterdir()}
    done = subprocess.run(
        [sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=120, cwd=ROOT
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("usage:"), done.stdout[:300]
    assert "Traceback" not in done.stderr
    assert {p.name: p.stat().st_mtime_ns for p in BASELINE.iterdir()} == before
