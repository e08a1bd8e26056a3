"""What an engine's watch adds to a row it times from its watched run (``light_watch``).

A long row of long steps of an engine whose watch is light is timed from its watched run
(:func:`truestep.execution.timing.timed_from_watched`): Drake's makes the same
``AdvanceTo`` calls as a plain one and copies the state after each; the reference's
implicit Euler and Dormand-Prince keep every step's state (Dormand-Prince keeps every
accepted step in a plain run too). This script measures what that costs on such rows:
after a short warm-up, a watched and a plain run one after the other, :data:`PAIRS` times
in one process, the first of each pair alternating (the run after another runs a percent
faster or slower here, whichever it is); it prints each kind's median wall time and their
ratio, and what the watch added a step. Measured 2026-12-07: Drake's fixed-step rows
0.8 to 1.9 microseconds a step (ratios 0.995 to 1.003 on steps of a millisecond or more,
1.019 to 1.035 on steps of 53 to 78 microseconds), its error-controlled rows 1.004 to
1.018 (the same code in the timed region: the noise of single runs here); the
reference's 0.988 to 1.018. Hence ``COPY_HIDDEN_STEP_S`` (0.2 ms) for fixed steps.

Usage: ``python benchmarks/light_watch.py [--engine drake|reference]`` on an otherwise
idle machine (about a minute each).
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics

from truestep.adapters import get_adapter
from truestep.cases import library, load_case

ROWS = {
    "drake": (
        ("stiff-cloth", "implicit_euler", 1e-3),
        ("stiff-cloth", "radau1", 1e-3),
        ("stiff-cloth", "radau3", 1e-3),
        ("hanging-cloth", "radau3", 4e-3),
        ("arenstorf-orbit", "implicit_euler", 5.000063e-4),
        ("arenstorf-orbit", "radau3", 5.000063e-4),
        ("arenstorf-orbit", "explicit_euler", 5.000063e-4),
        ("earth-orbit", "bogacki_shampine3", 1e-6),
        ("stiff-spring", "radau3-ec", 1e-8),
    ),
    "reference": (
        ("stiff-cloth", "implicit-euler", 6.25e-5),
        ("stiff-cloth", "implicit-euler", 2.5e-4),
        ("mass-ratio-chain", "implicit-euler", 6.25e-4),
        ("particle-rain", "dopri5", 1e-4),
        ("long-orbit", "dopri5", 1e-8),
    ),
}
"""Per engine, (case, method, step in s): rows of the full run timed from their watched run."""
PAIRS = 4


def main() -> None:
    layout = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=layout)
    parser.add_argument("--engine", choices=sorted(ROWS), default="drake", help="whose rows (default drake)")
    engine = parser.parse_args().engine
    adapter, cases = get_adapter(engine), library()
    for name, method, dt in ROWS[engine]:
        case = load_case(cases[name])
        adapter.simulate(dataclasses.replace(case, duration=max(0.05 * case.duration, dt)), method, dt)
        watched, plain = [], []
        for k in range(PAIRS):
            for monitor in (True, False) if k % 2 == 0 else (False, True):
                run = adapter.simulate(case, method, dt, monitor=monitor)
                (watched if monitor else plain).append(run.wall_s)
        w, p = statistics.median(watched), statistics.median(plain)
        steps = max(run.steps, 1)
        print(
            f"{name:16s} {method:17s} {dt:<11.6g} watched {w:7.3f} s  plain {p:7.3f} s  ratio {w / p:.4f}  "
            f"step {1e6 * p / steps:6.1f} us, watch {1e6 * (w - p) / steps:+.2f} us a step"
        )


if __name__ == "__main__":
    main()
