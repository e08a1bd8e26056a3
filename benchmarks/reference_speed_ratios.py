"""Issue 21's speed rows in one process, without pytest: each row a ratio of runs timed in
turn (the functions of ``benchmarks/test_reference_speed.py``), printed.

Usage: ``python benchmarks/reference_speed_ratios.py [CASE ...]``. It prints the cost per
step of every fixed-step reference method and MuJoCo's Euler on harmonic-oscillator
(ns), the rain's reference/lecture against pymunk at 1 ms (with both errors), and, for
each case named, every fixed-step reference method against the fastest engine at every
step of its sweep where that engine takes at least ``SHARED_MIN_S``. Run it with a warm
numba cache (a first run compiles), on an otherwise idle machine.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import test_reference_speed as speed

from truestep.adapters import get_adapter
from truestep.cases.loader import CASE_DIR, load_case
from truestep.execution.runner import measure


def per_step() -> None:
    """ns per step on harmonic-oscillator at 2 ms, every fixed-step method and MuJoCo's Euler."""
    case, dt = load_case(CASE_DIR / "harmonic-oscillator.toml"), 2e-3
    steps = case.steps_for(dt)[0]
    runs = [speed.timed("reference", case, m, dt) for m in speed.FIXED]
    walls = speed.interleave([*runs, speed.timed("mujoco", case, "Euler", dt)])
    print(f"harmonic-oscillator, {steps} steps of {dt * 1e3:g} ms, ns per step:")
    for name, wall in zip([*speed.FIXED, "mujoco/Euler"], walls, strict=True):
        print(f"  {name:18s} {wall / steps * 1e9:9.1f}")


def rain() -> None:
    """The rain at 1 ms: reference/lecture against pymunk/default, and their errors."""
    case = load_case(CASE_DIR / "particle-rain.toml")
    ours, theirs = speed.interleave(
        [speed.timed("reference", case, "lecture", 1e-3), speed.timed("pymunk", case, "default", 1e-3)]
    )
    error = {
        e: measure(case, get_adapter(e).simulate(case, m, 1e-3))["error"]
        for e, m in (("reference", "lecture"), ("pymunk", "default"))
    }
    work = case.model.n * case.steps_for(1e-3)[0]
    print(
        f"rain 1 ms: reference/lecture {ours * 1e3:.3f} ms, pymunk/default "
        f"{theirs * 1e3:.3f} ms: {theirs / ours:.1f}x; error {error['reference']:.3g} vs "
        f"{error['pymunk']:.3g} m; {work / ours:.3g} particle-steps/s"
    )


def shared(name: str) -> None:
    """Every fixed-step reference method against the fastest engine on case ``name``."""
    case = load_case(CASE_DIR / f"{name}.toml")
    for dt in case.dts:
        engines = [
            (e, m)
            for e in speed.ENGINES
            for m, d, adaptive, why in speed.plan(case, e, quick=False)
            if not why and not adaptive and d == dt and speed.runs_ok(e, case, m, dt)
        ]
        if not engines:
            continue
        first = {em: speed.timed(em[0], case, em[1], dt)() for em in engines}
        fastest = min(first, key=first.get)
        if first[fastest] < speed.SHARED_MIN_S:
            continue
        ours = [
            m
            for m in speed.FIXED
            if not speed.plan_skips(case, m) and speed.runs_ok("reference", case, m, dt)
        ]
        walls = speed.interleave(
            [speed.timed(fastest[0], case, fastest[1], dt)]
            + [speed.timed("reference", case, m, dt) for m in ours]
        )
        ratios = ", ".join(f"{m} {walls[0] / w:.1f}x" for m, w in zip(ours, walls[1:], strict=True))
        print(f"{name} dt={dt:g} vs {fastest[0]}/{fastest[1]} {walls[0] * 1e3:.4f} ms: {ratios}")


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0] if __doc__ else None)
    parser.add_argument("cases", nargs="*", metavar="CASE", help="cases to compare against every engine too")
    began = time.perf_counter()
    cases = parser.parse_args().cases
    per_step()
    rain()
    for case_name in cases:
        shared(case_name)
    print(f"took {time.perf_counter() - began:.0f} s")
