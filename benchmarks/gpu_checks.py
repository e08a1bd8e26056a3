"""Issue 39's checks on a GPU, in one call: the reference's device kernel against its CPU
path bit for bit, particle-steps per second against Newton on the same GPU, and the twin
rows of the Warp engines (GPU against Warp's CPU device).

Meant for a machine lent with a CUDA GPU (the device README: one short prepared script,
one call). Three parts, each printed with its target and written to ``--out``
(``gpu_checks.json``):

1. **Scaling** (first: its runs are forked, and CUDA must not be started in this process
   before): ``truestep bench`` on the rain at ``--sizes`` particles, the reference and
   Newton ``semi-implicit`` both on ``--device``, then the reference on every CPU core
   (``--threads``). Target: the reference at 1e6 particles at least 5 times Newton's
   particle-steps per second on the same GPU.
2. **The reference's kernel, bit for bit**: every library scene the device kernel models
   (:func:`~truestep.reference_impl.warp_particles.device_reason`), with both of its
   methods at the scene's coarsest step, on ``--device`` against the compiled CPU path:
   records equal, or the largest difference. The kernel is compiled without fused
   multiply-adds; the target is equality.
3. **Twin rows**: Newton's and MuJoCo Warp's methods on ``--device`` and on Warp's CPU
   device, quick cases, largest final-position difference over the scene's size
   (the float32 band: 1e-5 of the scene; beyond it the row is named).

``--device cpu`` is a dry run on a machine without a GPU (Warp's CPU device in part 2 and
3's place of the GPU): it checks the script, not the GPU. Usage: ``python
benchmarks/gpu_checks.py [--device cuda:0] [--sizes 1e3,1e4,1e5,1e6] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

SPEED_TARGET = 5.0
"""The reference on the GPU against Newton semi-implicit on the same GPU, at 1e6 particles."""
FLOAT32_BAND = 1e-5
"""A twin row's final positions may differ by this much of the scene's size (float32 round-off
compounded over a run); beyond it the twin parts."""
SCHEME = "symplectic-euler"
"""The reference's method set against Newton's ``semi-implicit``: the same scheme (velocity
first, then positions with the new velocity)."""
TWIN_CASES = ("bouncing-ball", "particle-rain", "sliding-contact", "hanging-cloth")
TWIN_SKIPS = {("mujoco-warp", "particle-rain"): "its 1000 bodies take 14 to 72 s a run on Warp's CPU device"}
"""Twins left out to keep the call short, and why."""


def scaling(device: str, sizes: list[float], threads: int, out: Path) -> dict[str, Any]:
    """Part 1: particle-steps per second by engine, device and n (``truestep bench``)."""
    from truestep import api

    engines = ["reference"] + (["newton"] if _installed("newton") else [])
    gpu = api.bench(engines, sizes=sizes, out=out / "bench-gpu", device={e: device for e in engines})
    cpu = api.bench(["reference"], sizes=sizes, out=out / "bench-cpu", threads=threads)
    rows = [
        {
            "engine": r.engine,
            "method": r.method,
            "n": int(r.n),
            "device": r.device,
            "threads": threads if table is cpu else 1,
            "status": r.status,
            "rate": float(r.particle_steps_per_s),
        }
        for table in (gpu, cpu)
        for r in table.itertuples(index=False)
    ]
    ratio = None
    biggest = max(int(s) for s in sizes)
    ours = [
        r["rate"]
        for r in rows
        if (r["engine"], r["method"], r["device"], r["n"]) == ("reference", SCHEME, device, biggest)
    ]
    theirs = [
        r["rate"]
        for r in rows
        if r["engine"] == "newton"
        and r["method"] == "semi-implicit"
        and r["n"] == biggest
        and r["status"] == "ok"
    ]
    if ours and theirs:
        ratio = ours[0] / theirs[0]
    print(f"\n1. particle-steps per second, rain ({device}; reference on the CPU with {threads} threads)")
    for r in rows:
        print(
            f"   {r['engine']:10s} {r['method']:17s} {r['device']:7s} n={r['n']:<9d} {r['status']:9s} "
            f"{r['rate']:.3g}"
        )
    words = "not measured (no Newton row)" if ratio is None else f"{ratio:.2f}x"
    verdict = "" if ratio is None else ("meets" if ratio >= SPEED_TARGET else "MISSES")
    print(f"   reference {SCHEME} / Newton semi-implicit, n={biggest}, {device}: {words}")
    print(f"   target {SPEED_TARGET}x {verdict}")
    return {"rows": rows, "ratio_at_largest": ratio, "target": SPEED_TARGET}


def kernel_bits(device: str) -> list[dict[str, Any]]:
    """Part 2: the device kernel's records against the compiled CPU path's."""
    import numpy as np

    from truestep.adapters import warp_runtime
    from truestep.api import select_cases
    from truestep.reference_impl import warp_particles
    from truestep.reference_impl.compiled import run_compiled

    warp_runtime.start()
    found = []
    print(f"\n2. the reference's kernel on {device} against its compiled CPU path (target: equal)")
    for case in select_cases(["*"]):
        for method in warp_particles.KICK_DRIFT:
            if warp_particles.device_reason(case.model, method) is not None:
                continue
            n_steps, h = case.steps_for(max(case.dts))
            on = warp_particles.run(
                case.particles, method, h, n_steps, device=device, max_records=case.max_records
            )
            cpu, _ = run_compiled(case.particles, method, n_steps * h, h, max_records=case.max_records)
            equal = (
                np.array_equal(on.x, cpu.x) and np.array_equal(on.v, cpu.v) and np.array_equal(on.t, cpu.t)
            )
            worst = float(np.nanmax(np.abs(on.x - cpu.x))) if on.x.shape == cpu.x.shape else float("nan")
            found.append({"case": case.name, "method": method, "equal": equal, "max_dx_m": worst})
            print(
                f"   {case.name:20s} {method:17s} {'equal' if equal else f'DIFFER, max |dx| {worst:.3g} m'}"
            )
    return found


def twins(device: str) -> list[dict[str, Any]]:
    """Part 3: the Warp engines on ``device`` against Warp's CPU device, final positions."""
    import numpy as np

    from truestep.adapters import adapter_class
    from truestep.api import select_cases

    found = []
    print(f"\n3. twin rows: {device} against Warp's CPU device (band {FLOAT32_BAND:g} of the scene)")
    for engine in ("newton", "mujoco-warp"):
        if not _installed(engine.replace("-", "_")):
            print(f"   {engine}: not installed, not measured")
            continue
        cls = adapter_class(engine)
        here, there = cls(device="cpu"), cls(device=device)
        for case in select_cases(list(TWIN_CASES)):
            if (engine, case.name) in TWIN_SKIPS:
                print(f"   {engine:11s} {case.name:20s} left out: {TWIN_SKIPS[engine, case.name]}")
                continue
            for method in here.methods:
                if method in here.adaptive_methods or here.missing(case, method):
                    continue
                dt = case.quick_dts[0]
                a, b = here.simulate(case, method, dt), there.simulate(case, method, dt)
                scale = max(float(case.error_scale), 1e-12)
                if a.status != "ok" or b.status != "ok":
                    row = {"status": f"{a.status} / {b.status}", "parts": a.status != b.status}
                else:
                    diff = float(np.max(np.abs(np.asarray(a.x[-1]) - np.asarray(b.x[-1]))))
                    row = {"max_dx": diff, "of_scene": diff / scale, "parts": diff / scale > FLOAT32_BAND}
                row.update(engine=engine, case=case.name, method=method, dt=dt)
                found.append(row)
                said = row.get("status") or f"{row['max_dx']:.3g} m ({row['of_scene']:.2g} of the scene)"
                print(
                    f"   {engine:11s} {case.name:20s} {method:14s} {said}{'  PARTS' if row['parts'] else ''}"
                )
    return found


def _installed(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="cuda:0", help="the GPU (default cuda:0; cpu: a dry run)")
    parser.add_argument("--sizes", default="1e3,1e4,1e5,1e6", help="rain particle counts (default 1e3..1e6)")
    parser.add_argument("--threads", type=int, default=len(os.sched_getaffinity(0)), help="CPU threads")
    parser.add_argument("--out", default="gpu-checks", help="folder for gpu_checks.json and the bench tables")
    parser.add_argument("--parts", default="1,2,3", help="which parts to run (default 1,2,3)")
    args = parser.parse_args()
    from truestep import numerics
    from truestep.adapters.devices import cuda_devices

    numerics.set_environment()
    if args.device != "cpu" and cuda_devices() == 0:
        print(f"gpu_checks: {args.device}: this machine has no CUDA device Warp can use", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    parts = {p.strip() for p in args.parts.split(",")}
    start = time.perf_counter()
    record: dict[str, Any] = {"device": args.device}
    steps = (
        (
            "1",
            "scaling",
            lambda: scaling(args.device, [float(x) for x in args.sizes.split(",")], args.threads, out),
        ),
        ("2", "kernel_bits", lambda: kernel_bits(args.device)),
        ("3", "twins", lambda: twins(args.device)),
    )
    for part, name, run in steps:
        if part in parts:
            began = time.perf_counter()
            record[name] = run()
            record[f"{name}_s"] = round(time.perf_counter() - began, 1)
            print(f"   ({record[f'{name}_s']} s)")
    record["seconds"] = round(time.perf_counter() - start, 1)
    (out / "gpu_checks.json").write_text(json.dumps(record, indent=1, default=str))
    print(f"\n{record['seconds']} s; written {out / 'gpu_checks.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
