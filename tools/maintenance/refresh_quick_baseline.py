"""Write ``tests/baselines/quick/``: the tables of ``truestep run --quick`` on this revision.

``.ci/run`` compares a fresh quick run with them, cell by cell (``truestep gate
--baseline tests/baselines/quick --identical``): the same revision and package versions
must give the same numbers on any machine. Run this after a change that moves numbers on
purpose, and commit the result::

    python tools/maintenance/refresh_quick_baseline.py

It also writes ``.ci/constraints.txt``: the versions of the packages the baseline's
``run.json`` records, which ``.ci/run`` installs (``pip install -c``), so that CI's gate
(``--require-identical``) compares bit for bit instead of falling back to tolerances the
day one of them releases (a fresh install takes the newest).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "tests" / "baselines" / "quick"
KEPT = ("results.csv", "stability.csv", "restitution.csv", "run.json")
CONSTRAINTS = ROOT / ".ci" / "constraints.txt"
"""The pins ``.ci/run`` installs with: :func:`constraints` of the baseline's ``run.json``."""


def constraints(run_json: Path) -> str:
    """The text of :data:`CONSTRAINTS` for a run record: ``name==version`` for every
    package it records but truestep itself, sorted."""
    packages = json.loads(run_json.read_text())["numerics"]["packages"]
    pins = [f"{name}=={version}" for name, version in sorted(packages.items()) if name != "truestep"]
    head = [
        "# Written by tools/maintenance/refresh_quick_baseline.py from tests/baselines/quick/run.json:",
        "# the versions the quick baseline was made with. .ci/run installs with these constraints so",
        "# that its gate compares bit for bit (--require-identical); do not edit by hand.",
    ]
    return "\n".join([*head, *pins]) + "\n"


def main() -> None:
    import argparse

    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()  # --help does nothing else
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "quick"
        subprocess.run(
            [sys.executable, "-m", "truestep", "run", "--quick", "--out", str(out)], check=True, cwd=ROOT
        )
        BASELINE.mkdir(parents=True, exist_ok=True)
        for name in KEPT:
            shutil.copyfile(out / name, BASELINE / name)
    CONSTRAINTS.write_text(constraints(BASELINE / "run.json"))
    print(f"wrote {BASELINE.relative_to(ROOT)}/ ({', '.join(KEPT)}) and {CONSTRAINTS.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
