"""An A/A timing comparison: the example project's solver (``examples/leapfrog-lab``, an
engine stepped from Python) run twice, unchanged, then compared with ``truestep gate
--baseline ... --time-against reference/verlet`` both ways. It must pass: a CI that times
an unchanged solver must not report it slower (issue 36, item 6). A timing check, so a
benchmark, never a unit test; run it on a quiet and on a loaded machine::

    python tools/experiments/aa_timing.py [--runs 2]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "leapfrog-lab"
CASES = (
    "free-fall,harmonic-oscillator,damped-oscillator,spring-damper-pair,bouncing-ball,"
    f"{EXAMPLE / 'leapfrog_lab' / 'cases'}"
)
ENGINES = "leapfrog_lab.adapter:LeapfrogAdapter,reference"


def _truestep(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": f"{EXAMPLE}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    return subprocess.run([sys.executable, "-m", "truestep", *args], env=env, capture_output=True, text=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2, help="quick runs of the same revision (default 2)")
    args = parser.parse_args()
    failed = 0
    with tempfile.TemporaryDirectory() as tmp:
        outs = []
        for k in range(args.runs):
            out = Path(tmp) / f"run{k}"
            done = _truestep("run", "--quick", "--cases", CASES, "--engines", ENGINES, "--out", str(out))
            if done.returncode != 0:
                print(done.stderr[-2000:])
                return 2
            outs.append(out)
        for a in outs:
            for b in outs:
                if a == b:
                    continue
                done = _truestep(
                    "gate",
                    "--results",
                    str(b / "results.csv"),
                    "--baseline",
                    str(a),
                    "--time-against",
                    "reference/verlet",
                    "-q",
                )
                worse = [line for line in done.stdout.splitlines() if line.startswith("WORSE")]
                print(f"{b.name} against {a.name}: exit {done.returncode}, {len(worse)} rows slower")
                for line in worse:
                    print(f"  {line}")
                failed += done.returncode != 0
    print("A/A: " + ("passed" if not failed else f"FAILED in {failed} comparison(s)"))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
