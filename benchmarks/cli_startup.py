"""How long the ``truestep`` command takes to answer ``--version`` and ``--help``.

Runs each command ``--repeats`` times (default 7) in a fresh process and prints the
median and the spread of the wall time, with the import of the whole package (what
every command paid before the CLI imported its modules lazily) measured the same way
in the same run, for the ratio. Target: 0.5 s or less for ``--version`` and ``--help``
on an idle machine.

Usage: ``python benchmarks/cli_startup.py [--repeats N]``
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import time

COMMANDS = {
    "truestep --version": ["--version"],
    "truestep --help": ["--help"],
    "truestep gate --help": ["gate", "--help"],
}
EVERYTHING = "import truestep.api, truestep.adapters, truestep.cases.loader, pandas, scipy.integrate"


def wall(argv: list[str]) -> float:
    began = time.perf_counter()
    subprocess.run(argv, check=True, capture_output=True)
    return time.perf_counter() - began


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    exe = shutil.which("truestep") or sys.exit("truestep is not on PATH: install the package first")
    rows = {name: [exe, *argv] for name, argv in COMMANDS.items()}
    rows["python -c 'import every module'"] = [sys.executable, "-c", EVERYTHING]
    for argv in rows.values():
        wall(argv)  # warm the file cache
    for name, argv in rows.items():
        times = sorted(wall(argv) for _ in range(args.repeats))
        median = statistics.median(times)
        print(f"{name:34s} median {median:.3f} s  (min {times[0]:.3f}, max {times[-1]:.3f})")


if __name__ == "__main__":
    main()
