"""Every script in ``benchmarks/`` and ``tools/`` answers ``--help`` and does nothing else
(issue 38, item 5): ``refresh_quick_baseline.py --help`` started a quick run that overwrote the
committed baseline; the two campaigns failed at import (``fuzz_strategies`` had moved)."""

from __future__ import annotations

import json
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


def test_the_gpu_checks_dry_run_on_the_cpu_finds_the_kernel_equal_and_a_missing_gpu_is_one_line(tmp_path):
    """``benchmarks/gpu_checks.py`` is run only where a GPU is lent: its part 2 (the
    reference's device kernel against the compiled path) runs here on Warp's CPU device
    (``--device cpu``), so that the script the next GPU session carries is known to work;
    asked for a GPU this machine lacks, it says so in one line and exits 2."""
    pytest.importorskip("warp")
    from truestep.adapters.devices import cuda_devices

    script = str(ROOT / "benchmarks" / "gpu_checks.py")
    out = tmp_path / "checks"
    done = subprocess.run(
        [sys.executable, script, "--device", "cpu", "--parts", "2", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    record = json.loads((out / "gpu_checks.json").read_text())
    pairs = record["kernel_bits"]
    assert len(pairs) >= 12 and all(p["equal"] for p in pairs)
    if cuda_devices() == 0:
        refused = subprocess.run(
            [sys.executable, script, "--device", "cuda:0", "--out", str(tmp_path / "none")],
            capture_output=True,
            text=True,
            timeout=120,
            cwd=ROOT,
        )
        assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) == 1
        assert not (tmp_path / "none").exists()
