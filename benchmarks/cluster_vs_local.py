"""A run on real ``dask scheduler`` and ``dask worker`` processes on 127.0.0.1, beside the
same run on this machine alone: wall times side by side, and every column but the timing
ones and ``host`` compared.

    python benchmarks/cluster_vs_local.py [--cases ITEMS] [--engines NAMES] [--workers N]
                                          [--quick] [--out DIR]

Starts a scheduler on a free port and ``N`` single-threaded workers (default: one per
core), runs ``truestep run`` locally into ``DIR/local`` and with ``--scheduler`` into
``DIR/cluster``, prints both wall times and whether the tables agree (exit 1 if not),
and stops the cluster.
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

TIMING = {"wall_s", "repeats", "host"}
BIN = Path(sys.executable).parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def timed_run(args: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(
        [str(BIN / "truestep"), "run", *args],
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    return time.perf_counter() - start


def differences(a: Path, b: Path) -> list[str]:
    out = []
    for name in ("results", "stability", "restitution"):
        x, y = pd.read_csv(a / f"{name}.csv"), pd.read_csv(b / f"{name}.csv")
        cols = [c for c in x.columns if c not in TIMING]
        if list(x.columns) != list(y.columns) or not x[cols].equals(y[cols]):
            out.append(name)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--cases", default="free-fall,harmonic-oscillator,spring-chain,bouncing-ball,hanging-cloth"
    )
    parser.add_argument("--engines", default="reference,pymunk,pybullet,mujoco")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", default="bench/cluster")
    args = parser.parse_args()
    out = Path(args.out)
    common = ["--cases", args.cases, "--engines", args.engines] + (["--quick"] if args.quick else [])
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    scheduler = subprocess.Popen(
        [str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
        **quiet,
    )
    workers = subprocess.Popen(
        [
            str(BIN / "dask"),
            "worker",
            address,
            "--nworkers",
            str(args.workers),
            "--nthreads",
            "1",
            "--no-dashboard",
        ],
        **quiet,
    )
    try:
        time.sleep(3.0)  # the workers connect
        local = timed_run([*common, "--out", str(out / "local")])
        cluster = timed_run([*common, "--out", str(out / "cluster"), "--scheduler", address])
    finally:
        for p in (workers, scheduler):
            p.terminate()
            p.wait(timeout=30)
    differ = differences(out / "local", out / "cluster")
    hosts = pd.read_csv(out / "cluster" / "results.csv")["host"].dropna().unique()
    print(f"cases {args.cases}; engines {args.engines}{' (quick)' if args.quick else ''}")
    print(f"local run:   {local:7.1f} s wall")
    print(
        f"cluster run: {cluster:7.1f} s wall ({args.workers} single-threaded workers at "
        f"{address}; hosts {', '.join(map(str, hosts))})"
    )
    print("non-timing columns: " + ("identical" if not differ else "DIFFER in " + ", ".join(differ)))
    return 1 if differ else 0


if __name__ == "__main__":
    raise SystemExit(main())
