"""Write ``tests/baselines/quick/``: the tables of ``truestep run --quick`` on this revision.

``.ci/run`` compares a fresh quick run with them, cell by cell (``truestep gate
--baseline tests/baselines/quick --identical``): the same revision and package versions
must give the same numbers on any machine. Run this after a change that moves numbers on
purpose, and commit the result::

    python tools/maintenance/refresh_quick_baseline.py
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "tests" / "baselines" / "quick"
KEPT = ("results.csv", "stability.csv", "restitution.csv", "run.json")


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
    print(f"wrote {BASELINE.relative_to(ROOT)}/ ({', '.join(KEPT)})")


if __name__ == "__main__":
    main()
