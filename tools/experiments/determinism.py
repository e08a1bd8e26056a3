"""Does the same revision give the same numbers under other conditions? Count them.

Runs ``truestep run`` (any checkout's, through the ``truestep`` executable given) in pairs
of conditions and counts the non-timing cells of ``results.csv``, ``stability.csv`` and
``restitution.csv`` that differ between the two runs of each pair, and the picks of the
report (the cheapest run per case and accuracy, the family recommendations) that change.
It reads only the files a run writes, so it measures old and new code alike::

    python tools/experiments/determinism.py --truestep .venv/bin/truestep --out /tmp/det \\
        --cases spring-chain,hanging-cloth,earth-orbit --pairs threads,load,cluster,again
    python tools/experiments/determinism.py --truestep .venv/bin/truestep --out /tmp/det \\
        --pairs published     # a full run against the committed reports/

Pairs: ``threads`` (OPENBLAS_NUM_THREADS=1 against 2), ``load`` (idle against two busy
processes on the machine), ``cluster`` (local against ``--scheduler local:2``), ``again``
(the same command twice: the picks that timing noise moves), ``published`` (a run of
every case against ``--published``, default ``reports/``).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

MACHINE = {"wall_s", "wall_s_spread", "repeats", "host", "case_source"}
"""Columns that depend on the machine (truestep.execution.runner.MACHINE_COLUMNS, restated so that
this script reads the tables of any version)."""
KEYS = {
    "results": ["case", "engine", "method", "dt_kind", "dt"],
    "stability": ["case", "engine", "method"],
    "restitution": ["engine", "method", "dt", "e_set", "bounce"],
}


def _busy() -> None:
    while True:
        pass


def run(
    truestep: str,
    out: Path,
    cases: str | None,
    *,
    env: dict | None = None,
    extra: tuple[str, ...] = (),
    load: int = 0,
) -> float:
    """One ``truestep run`` into ``out`` (with ``load`` busy processes beside it); seconds."""
    busy = [mp.Process(target=_busy, daemon=True) for _ in range(load)]
    for p in busy:
        p.start()
    try:
        argv = [truestep, "run", "--out", str(out), *extra]
        if cases:
            argv += ["--cases", cases]
        start = time.perf_counter()
        proc = subprocess.run(
            argv, env={**os.environ, **(env or {})}, capture_output=True, text=True, check=False
        )
        if proc.returncode != 0:
            sys.exit(f"{' '.join(argv)} failed ({proc.returncode}): {proc.stderr[-2000:]}")
        return time.perf_counter() - start
    finally:
        for p in busy:
            p.kill()


def differing_cells(a: Path, b: Path) -> dict[str, int]:
    """Per table: cells of non-timing columns that differ (rows on one side only count
    once per column); exact comparison, NaN equal to NaN."""
    out = {}
    for name, keys in KEYS.items():
        pa, pb = a / f"{name}.csv", b / f"{name}.csv"
        if not (pa.exists() and pb.exists()):
            continue
        x, y = (
            pd.read_csv(pa, dtype=str, keep_default_na=False),
            pd.read_csv(pb, dtype=str, keep_default_na=False),
        )
        columns = [c for c in x.columns if c in set(y.columns) and c not in MACHINE]
        merged = x[columns].merge(y[columns], on=keys, how="outer", suffixes=("_a", "_b"), indicator=True)
        lonely = int((merged["_merge"] != "both").sum()) * len(columns)
        both = merged[merged["_merge"] == "both"]
        diff = sum(int((both[f"{c}_a"] != both[f"{c}_b"]).sum()) for c in columns if c not in keys)
        out[name] = diff + lonely
    return out


RUN = re.compile(r"[\w.-]+ / [\w.-]+ \((?:dt|tol) [^)]*\)")
BOLD = re.compile(r"\*\*([^*]+)\*\*")


def picks(report: Path) -> dict[str, tuple[str, str]]:
    """The picks an ``index.md`` states, times and ratios left out, as ``(named, group)``:
    for each cell of the cheapest-run table the run it names by wall time and the runs
    it names as tied with it; for each family sentence the first run named for accuracy
    per second and every run it names there (runs tied with it, and the next)."""
    text = (report / "index.md").read_text()
    found: dict[str, tuple[str, str]] = {}
    summary = text.split("## Summary", 1)[-1].split("\n## ", 1)[0]
    rows = [line for line in summary.splitlines() if line.startswith("|")]
    if rows:
        header = [c.strip() for c in rows[0].strip("|").split("|")]
        for line in rows[2:]:
            cells = [c.strip() for c in line.strip("|").split("|")]
            for col, cell in zip(header[1:], cells[1:], strict=False):
                by_wall = cell.split("; fewest evaluations", 1)[0]
                runs = RUN.findall(by_wall)
                named = runs[0] if runs else by_wall
                found[f"cheapest {cells[0]} {col}"] = (named, " | ".join(sorted(runs)))
    choose = text.split("## Which engine, which method", 1)[-1].split("\n## ", 1)[0]
    for line in choose.splitlines():
        if line.startswith("- **"):
            family = BOLD.findall(line)[0]
            speed = line.split("for accuracy per second, ", 1)[-1].split(";", 1)[0]
            names = re.findall(r"\*\*([\w.-]+ / [\w.-]+)\*\*", speed)
            found[f"family {family}"] = (names[0] if names else "", ", ".join(sorted(names)))
    return found


def changed_picks(a: Path, b: Path) -> tuple[int, int, int, list[str]]:
    """(cells whose named run changed, cells whose tie group changed, cells, which)."""
    pa, pb = picks(a), picks(b)
    keys = sorted(set(pa) | set(pb))
    named = [k for k in keys if pa.get(k, ("", ""))[0] != pb.get(k, ("", ""))[0]]
    group = [k for k in keys if pa.get(k, ("", ""))[1] != pb.get(k, ("", ""))[1]]
    return (
        len(named),
        len(group),
        len(keys),
        [f"{k}: {pa.get(k)} -> {pb.get(k)}" for k in keys if k in named or k in group],
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n", 1)[0])
    parser.add_argument("--truestep", required=True, help="the truestep executable to run")
    parser.add_argument("--out", required=True, type=Path, help="where the runs go")
    parser.add_argument("--cases", default=None, help="--cases of every run but `published`")
    parser.add_argument("--pairs", default="threads,load,cluster,again")
    parser.add_argument("--published", type=Path, default=Path("reports"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    base = args.out / "base"
    lines = []

    def report(pair: str, a: Path, b: Path, seconds: str) -> None:
        cells = differing_cells(a, b)
        named, group, total, which = changed_picks(a, b)
        lines.append(
            f"{pair:10s} cells differing {sum(cells.values()):5d} {cells}  picks: "
            f"named run changed {named}/{total}, tie group changed {group}/{total}  "
            f"({seconds})"
        )
        print(lines[-1], flush=True)
        for k in which[:40]:
            print(f"    {k}", flush=True)

    pairs = args.pairs.split(",")
    if any(p in pairs for p in ("threads", "load", "cluster", "again")):
        t0 = run(args.truestep, base, args.cases, env={"OPENBLAS_NUM_THREADS": "1"})
    for pair in pairs:
        if pair == "threads":
            t = run(args.truestep, args.out / "threads2", args.cases, env={"OPENBLAS_NUM_THREADS": "2"})
            report(pair, base, args.out / "threads2", f"{t0:.0f} s / {t:.0f} s")
        elif pair == "load":
            t = run(args.truestep, args.out / "loaded", args.cases, env={"OPENBLAS_NUM_THREADS": "1"}, load=2)
            report(pair, base, args.out / "loaded", f"{t0:.0f} s / {t:.0f} s loaded")
        elif pair == "cluster":
            t = run(
                args.truestep,
                args.out / "cluster",
                args.cases,
                env={"OPENBLAS_NUM_THREADS": "1"},
                extra=("--scheduler", "local:2"),
            )
            report(pair, base, args.out / "cluster", f"{t0:.0f} s / {t:.0f} s on local:2")
        elif pair == "again":
            t = run(args.truestep, args.out / "again", args.cases, env={"OPENBLAS_NUM_THREADS": "1"})
            report(pair, base, args.out / "again", f"{t0:.0f} s / {t:.0f} s")
        elif pair == "published":
            t = run(args.truestep, args.out / "full", None)
            report(pair, args.published, args.out / "full", f"{t:.0f} s against {args.published}")
        else:
            sys.exit(f"unknown pair {pair!r}")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
