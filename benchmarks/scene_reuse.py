"""What a timed run spends outside its timed region, with a row's scene built once or afresh.

A row's warm-up, measured and timed runs (3 to 25 of them for a short row) each call
``adapter.simulate``, on the timed runs' core. MuJoCo, Newton and pybullet build the
row's scene once and reuse it (MuJoCo's compiled model, Newton's scene with its arrays
copied back, pybullet's client emptied by ``resetSimulation``); this script times a
row's timed run (:func:`~truestep.execution.timing.timed_case`: three records) both ways,
:data:`CALLS` calls each after one, the two ways alternating, and prints for each engine
and scene the stepping (the run's ``wall_s``) and the time outside it, median per call.
Measured 2026-12-07 (stop 68): outside the stepping, MuJoCo's free-fall 1.47 -> 0.65 ms,
its rain 76 -> 14 ms; Newton's free-fall 5.8 -> 0.6 ms, its rain 22.9 -> 2.6 ms;
pybullet's free-fall 16.3 -> 3.6 ms.

Usage: ``python benchmarks/scene_reuse.py`` on an otherwise idle machine (about a minute).
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

from truestep.adapters import get_adapter
from truestep.adapters import mujoco_adapter as mj
from truestep.adapters import newton_adapter as nt
from truestep.adapters import pybullet_adapter as pb
from truestep.cases import library, load_case
from truestep.execution.timing import timed_case

CASES = ("free-fall", "bouncing-ball", "hanging-cloth", "particle-rain")
CALLS = 5
"""Timed calls per way and round, after one untimed."""
ROUNDS = 2


def afresh(engine: str) -> Any:
    """The adapter of ``engine`` with its scene built afresh for every run (as before stop 68)."""
    adapter: Any = type(get_adapter(engine))()
    if engine == "mujoco":
        adapter.build = lambda c, m, h: mj.build(c, m, h, contact_steps=adapter.contact_steps)
    elif engine == "newton":
        adapter.build = lambda c, m, h: nt.build(c, m, h, device=adapter.device)
    else:
        adapter.build = lambda c, m, h: pb._Run(
            c.particles, pb.build_scene(c.particles, h, clean=m == "clean")
        )
        adapter.close = lambda run: pb.p.disconnect(run.scene.client)
    return adapter


def per_call(adapter: Any, case: Any, method: str, dt: float) -> tuple[float, float]:
    """Seconds per ``adapter.simulate`` call in all and of its stepping (``wall_s``), over
    :data:`CALLS` calls."""
    start, stepping = time.perf_counter(), 0.0
    for _ in range(CALLS):
        stepping += adapter.simulate(case, method, dt).wall_s
    return (time.perf_counter() - start) / CALLS, stepping / CALLS


def main() -> None:
    layout = argparse.RawDescriptionHelpFormatter
    argparse.ArgumentParser(description=__doc__, formatter_class=layout).parse_args()
    cases = library()
    print(f"{'engine':9s} {'case':15s} {'stepping ms':>12s} {'outside, reused':>16s} {'afresh':>8s}")
    for engine in ("mujoco", "newton", "pybullet"):
        reused, fresh = get_adapter(engine), afresh(engine)
        method = reused.methods[0]
        for name in CASES:
            case = load_case(cases[name])
            if reused.missing(case, method) or getattr(reused, "skip", lambda *a: None)(case, method):
                continue
            lean, dt = timed_case(reused, case, method), case.dts[-1]
            samples: dict[str, list[tuple[float, float]]] = {"reused": [], "afresh": []}
            for adapter in (reused, fresh):
                adapter.simulate(lean, method, dt)
            for r in range(ROUNDS):
                ways = (("reused", reused), ("afresh", fresh))
                for way, adapter in ways if r % 2 == 0 else ways[::-1]:
                    samples[way].append(per_call(adapter, lean, method, dt))
            step = statistics.median(s for _, s in samples["reused"] + samples["afresh"])
            outside = {w: statistics.median(t - s for t, s in v) for w, v in samples.items()}
            print(
                f"{engine:9s} {name:15s} {step * 1e3:12.2f} {outside['reused'] * 1e3:16.2f} "
                f"{outside['afresh'] * 1e3:8.2f}"
            )


if __name__ == "__main__":
    main()
