"""What a sweep's own process costs, by what the process that forks it has imported.

Every sweep of ``truestep run`` runs in a process forked from the run's own (see
:mod:`truestep.runtime.isolation`), and that process holds every engine the run asked
for. A fork copies the parent's page tables and its end tears them down: the cost grows
with the parent's memory, not with the sweep. This script measures it in one process, in
three stages of imports (truestep with the reference's loops; then the light engines;
then Warp's and Drake's): the parent's resident memory, and for each stage the median
wall and system seconds of one isolated sweep against the same sweep run in the process
itself.

Usage: ``python benchmarks/fork_cost.py [--repeats N]``. Run it with a warm numba cache
on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import time

from truestep import numerics

numerics.set_environment()

from truestep.adapters import get_adapter  # noqa: E402
from truestep.cases.loader import CASE_DIR, load_case  # noqa: E402
from truestep.execution.runner import UNTIMED, preload, sweep_call  # noqa: E402
from truestep.runtime.isolation import run_isolated  # noqa: E402

STAGES = (
    ("truestep and the reference", ("reference",)),
    ("+ scipy, pymunk, pybullet, mujoco", ("scipy", "pymunk", "pybullet", "mujoco")),
    ("+ mujoco-warp, newton, drake", ("mujoco-warp", "newton", "drake")),
)
"""The engines imported at each stage, on top of the stages before it."""


def _resident_mb() -> float:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * resource.getpagesize() / 1e6


def _system_s() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_stime + children.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=15, help="isolated sweeps per stage (default 15)")
    args = parser.parse_args()
    preload()
    case = load_case(CASE_DIR / "free-fall.toml")
    dts = list(case.sweep(adaptive=False, quick=True))
    fn, fn_args, limit = sweep_call(case, "reference", "rk4", dts, UNTIMED)
    fn(*fn_args)
    print(f"one sweep: {case.name} reference/rk4, {len(dts)} steps, untimed")
    head = ("memory MB", "in-process ms", "isolated ms", "system ms")
    print(f"{'parent holds':36s} " + " ".join(f"{h:>13s}" for h in head))
    for label, engines in STAGES:
        for engine in engines:
            get_adapter(engine)
        here, walls, system = [], [], []
        for _ in range(args.repeats):
            started = time.perf_counter()
            fn(*fn_args)
            here.append(time.perf_counter() - started)
            sys_before, started = _system_s(), time.perf_counter()
            outcome = run_isolated(fn, fn_args, limit)
            walls.append(time.perf_counter() - started)
            system.append(_system_s() - sys_before)
            assert outcome.status == "ok", outcome
        print(
            f"{label:36s} {_resident_mb():13.0f} {1e3 * statistics.median(here):13.1f} "
            f"{1e3 * statistics.median(walls):13.1f} {1e3 * statistics.median(system):13.1f}"
        )


if __name__ == "__main__":
    main()
