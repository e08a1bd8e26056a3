"""What Drake's watch adds to a row it times from its watched run (``light_watch``).

A long Drake row whose steps take a millisecond or more is timed from its watched run
(:func:`truestep.execution.timing.timed_from_watched`): that run makes the same
``AdvanceTo`` calls as a plain one and copies the state after each. This script measures
what that copy costs on such rows: after a short warm-up, a watched and a plain run one
after the other, :data:`PAIRS` times in one process, the first of each pair alternating
(the run after another runs a percent faster or slower here, whichever it is); it prints
each kind's median wall time and their ratio (measured 2026-12-07: 0.997 to 1.012, the
spread of single runs of a few seconds on this machine).

Usage: ``python benchmarks/light_watch.py`` on an otherwise idle machine (about a minute).
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics

from truestep.adapters import get_adapter
from truestep.cases import library, load_case

ROWS = (
    ("stiff-cloth", "implicit_euler", 1e-3),
    ("stiff-cloth", "radau1", 1e-3),
    ("stiff-cloth", "radau3", 1e-3),
    ("hanging-cloth", "radau3", 4e-3),
)
"""(case, Drake method, step in s): rows of the full run timed from their watched run."""
PAIRS = 4


def main() -> None:
    layout = argparse.RawDescriptionHelpFormatter
    argparse.ArgumentParser(description=__doc__, formatter_class=layout).parse_args()
    drake, cases = get_adapter("drake"), library()
    for name, method, dt in ROWS:
        case = load_case(cases[name])
        drake.simulate(dataclasses.replace(case, duration=max(0.05 * case.duration, dt)), method, dt)
        watched, plain = [], []
        for k in range(PAIRS):
            for monitor in (True, False) if k % 2 == 0 else (False, True):
                wall = drake.simulate(case, method, dt, monitor=monitor).wall_s
                (watched if monitor else plain).append(wall)
        w, p = statistics.median(watched), statistics.median(plain)
        print(f"{name:14s} {method:15s} {dt:g} s  watched {w:7.3f} s  plain {p:7.3f} s  ratio {w / p:.4f}")


if __name__ == "__main__":
    main()
