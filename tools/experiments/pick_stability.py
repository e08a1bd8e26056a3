"""Do the report's picks move with timing noise? (issue 35, finding 10.) The "cheapest run
to each accuracy" picks (:func:`truestep.measures.picks.cheapest`, by wall time) of the
published ``results.csv`` at several commits, compared pairwise: how many named picks
differ, and how many tie groups (the named run and the runs tied with it within timing
noise). Between full runs whose non-timing cells are identical, only timing can move
them. A timing check, so a benchmark, never a unit test::

    python tools/experiments/pick_stability.py                 # the last 3 commits of reports/results.csv
    python tools/experiments/pick_stability.py REV REV [REV ...]
    python tools/experiments/pick_stability.py --files A.csv B.csv   # results tables from anywhere
"""

from __future__ import annotations

import argparse
import io
import itertools
import subprocess
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]


def _published(rev: str) -> pd.DataFrame:
    text = subprocess.run(
        ["git", "show", f"{rev}:reports/results.csv"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout
    return pd.read_csv(io.StringIO(text))


def _last_revisions(n: int) -> list[str]:
    out = subprocess.run(
        ["git", "log", f"-{n}", "--format=%h", "--", "reports/results.csv"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    return out.split()


def _label(engine: str, method: str, dt: float, kind: str) -> str:
    """A run as the picks' ``tied`` names one."""
    return f"{engine} / {method} ({'tol' if kind == 'tolerance' else 'dt'} {float(dt):.3g})"


def _group(named: str, tied: object) -> set[str]:
    """The named run and the runs tied with it (the picks' ``tied``: "; "-joined)."""
    return {named, *(t for t in (tied if isinstance(tied, str) else "").split("; ") if t)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("revisions", nargs="*", help="commits whose reports/results.csv to compare")
    parser.add_argument("--files", nargs="*", default=[], help="results.csv files to compare instead")
    args = parser.parse_args()
    from truestep.cases.loader import load_cases
    from truestep.measures.picks import cheapest

    if args.files:
        tables = {f: pd.read_csv(f) for f in args.files}
    else:
        revs = args.revisions or _last_revisions(3)
        tables = {r: _published(r) for r in revs}
    if len(tables) < 2:
        print("need two tables or more", file=sys.stderr)
        return 2
    cases = load_cases("*")
    picks = {}
    for name, table in tables.items():
        known = [c for c in cases if c.name in set(table["case"])]
        p = cheapest(table, known)
        picks[name] = p[p["by"] == "wall_s"].reset_index(drop=True)
    for a, b in itertools.combinations(picks, 2):
        left, right = picks[a], picks[b]
        merged = left.merge(right, on=["case", "target"], suffixes=("_a", "_b"))
        named = tied = 0
        for r in merged.itertuples():
            la = _label(r.engine_a, r.method_a, r.dt_a, r.dt_kind_a)
            lb = _label(r.engine_b, r.method_b, r.dt_b, r.dt_kind_b)
            named += la != lb
            tied += _group(la, r.tied_a) != _group(lb, r.tied_b)
        print(f"{a} vs {b}: {named} of {len(merged)} named picks differ; {tied} tie groups differ")
    return 0


if __name__ == "__main__":
    sys.exit(main())
