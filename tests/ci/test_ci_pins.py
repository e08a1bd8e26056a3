"""CI compares its quick run with the committed quick baseline bit for bit, and cannot fall
back to tolerances unseen: ``.ci/run`` installs the versions the baseline records
(``.ci/constraints.txt``, written with the baseline) and gates with
``--require-identical``. Before, a fresh install took the newest pandas (3.1.2, the
baseline's 3.1.1) and the gate printed "not comparable bit for bit ... compared with
tolerances only" and passed, as it had with ``distributed`` before."""

from __future__ import annotations

import json
import re
import runpy
from pathlib import Path

from truestep import numerics

ROOT = Path(__file__).resolve().parents[2]
CI = ROOT / ".ci" / "run"
CONSTRAINTS = ROOT / ".ci" / "constraints.txt"
BASELINE = ROOT / "tests" / "baselines" / "quick"
REFRESH = ROOT / "tools" / "maintenance" / "refresh_quick_baseline.py"


def test_the_constraints_pin_every_package_the_quick_baseline_records_at_its_version():
    recorded = json.loads((BASELINE / "run.json").read_text())["numerics"]["packages"]
    pins = dict(
        line.split("==") for line in CONSTRAINTS.read_text().splitlines() if line and not line.startswith("#")
    )
    assert pins == {name: v for name, v in recorded.items() if name != "truestep"}
    assert set(numerics.PACKAGES) - {"truestep"} <= set(pins)  # every package a run records
    refresh = runpy.run_path(str(REFRESH))
    assert refresh["CONSTRAINTS"] == CONSTRAINTS
    assert CONSTRAINTS.read_text() == refresh["constraints"](BASELINE / "run.json")


def test_ci_installs_with_the_constraints_and_requires_the_quick_run_identical():
    script = CI.read_text()
    installs = re.findall(r"^python -m pip install .*$", script, flags=re.MULTILINE)
    project = [line for line in installs if "-e " in line or "./examples/" in line]
    assert len(project) == 2, installs
    assert all(line.endswith("-c .ci/constraints.txt") for line in project), project
    gates = re.findall(r"^truestep gate .*$", script, flags=re.MULTILINE)
    assert gates and all("--require-identical" in line for line in gates), gates
