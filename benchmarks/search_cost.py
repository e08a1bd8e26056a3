"""Where a stability search's work goes: its runs by the part of the search that made them.

A search (:func:`truestep.measures.stability.search_case`) makes its runs in five parts:
the first bracket (the bisection over the case's ``[dt_lo, dt_hi]``, or from a peer's
bracket), the monotone probes (0.9 and 0.5 of the limit found, and a search again below
one that fails), the confirmation (a run at the limit :data:`~truestep.measures.stability.CONFIRM`
times as long, and a search again where it fails), the check against an exact limit, and
the nudged runs (a start moved by a few float32 ulps, where no exact limit is known). This
script runs the searches a full run makes for the engines and cases it is given, exactly
as the run makes them (the same hint from a correctness peer's search, made here first),
and prints, per search and in all, each part's runs, steps and seconds, and any run made
twice with the same step, length and start. Steps are what a run costs; the seconds are
this machine's. It changes nothing: the searches' results are the published ones.

Usage: ``python benchmarks/search_cost.py --engines mujoco --cases rope-pendulum,stiff-cloth``
(the default: MuJoCo's and pybullet's searches of the three cloth and rope cases, about
two minutes). A method the adapter says steps as another (``duplicate`` or ``same_steps``) is
not searched, as in the full run.
"""

from __future__ import annotations

import argparse
import collections
import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from truestep.adapters import get_adapter
from truestep.adapters.base import duplicate_of, facts_of
from truestep.cases import load_cases
from truestep.cases.exact import stability_limit
from truestep.execution.analyses import _hint_of, _peer_of
from truestep.measures import stability

PARTS = {
    "_first_bracket": "bracket",
    "_confirmed": "confirm",
    "_not_above_exact": "exact",
    "_roundoff_interval": "nudged",
}
"""The search's functions whose runs (and the searches again they start) make each part; a
run outside all of them is a monotone probe's (or the search again below a failed one)."""
ORDER = ("bracket", "probes", "confirm", "exact", "nudged")


@dataclass
class Ledger:
    """The runs of one search: ``(part, dt, steps, nudged, seconds)`` each."""

    runs: list[tuple[str, float, int, bool, float]] = field(default_factory=list)
    part: list[str] = field(default_factory=list)

    def now(self) -> str:
        return self.part[0] if self.part else "probes"


LEDGER = Ledger()


def _in_part(name: str, fn):
    """``fn`` whose runs count to the part :data:`PARTS` names (the outermost part wins: a
    search again inside the confirmation is the confirmation's)."""

    @functools.wraps(fn)
    def wrapped(*args, **kwargs):
        LEDGER.part.append(PARTS[name])
        try:
            return fn(*args, **kwargs)
        finally:
            LEDGER.part.pop()

    return wrapped


def _recorded(simulate, start_x0: np.ndarray | None):
    """``simulate`` whose every run goes into :data:`LEDGER`."""

    def run(case, dt):
        steps = round(case.duration / dt)
        x0 = getattr(case.scene, "x0", getattr(case.scene, "y0", None))
        nudged = start_x0 is not None and x0 is not None and not np.array_equal(x0, start_x0)
        t = time.perf_counter()
        traj = simulate(case, dt)
        LEDGER.runs.append((LEDGER.now(), dt, steps, nudged, time.perf_counter() - t))
        return traj

    return run


def _search(engine: str, case, method: str) -> tuple[stability.SearchResult, list]:
    """One search as the full run makes it, its runs recorded."""
    adapter = get_adapter(engine)
    hint = None
    peer = _peer_of(adapter, case, method)
    if peer is not None:
        other = get_adapter(peer.engine)
        found = stability.search_case(case, lambda c, dt: other.simulate(c, method, dt), exact=peer.exact)
        hint = _hint_of(peer.engine, found)
    exact = stability_limit(case, facts_of(adapter, method))
    LEDGER.runs.clear()
    start = getattr(case.scene, "x0", getattr(case.scene, "y0", None))
    simulate = _recorded(lambda c, dt: adapter.simulate(c, method, dt), start)
    result = stability.search_case(case, simulate, exact=exact, hint=hint)
    return result, list(LEDGER.runs)


def _twin(adapter, case, method: str, methods: list[str]) -> bool:
    """Whether the full run takes ``method``'s search from another method's (the adapter's
    ``same_steps``: the same steps bit for bit) searched before it."""
    same = getattr(adapter, "same_steps", None)
    twin = same(case, method) if same is not None else None
    return twin is not None and twin[0] in methods[: methods.index(method)]


def _line(label: str, runs: list) -> str:
    parts = collections.defaultdict(lambda: [0, 0, 0.0])
    for part, _dt, steps, _n, seconds in runs:
        parts[part][0] += 1
        parts[part][1] += steps
        parts[part][2] += seconds
    steps = sum(p[1] for p in parts.values()) or 1
    cells = "  ".join(
        f"{part} {parts[part][0]:2d} runs {100 * parts[part][1] / steps:3.0f}% of steps "
        f"{parts[part][2]:5.1f} s"
        for part in ORDER
        if part in parts
    )
    return f"{label:50s} {len(runs):3d} runs {sum(r[4] for r in runs):6.1f} s | {cells}"


def main() -> None:
    layout = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=layout)
    parser.add_argument("--engines", default="mujoco,pybullet", help="engines (default mujoco,pybullet)")
    parser.add_argument(
        "--cases", default="rope-pendulum,stiff-cloth,hanging-cloth", help="cases with a [stability] search"
    )
    parser.add_argument("--methods", default="", help="only these methods (default: every fixed-step one)")
    args = parser.parse_args()
    for name in PARTS:
        setattr(stability, name, _in_part(name, getattr(stability, name)))
    every = []
    for case in load_cases(args.cases):
        if case.stability is None:
            continue
        for engine in args.engines.split(","):
            adapter = get_adapter(engine)
            methods = [m for m in adapter.methods if m not in adapter.adaptive_methods]
            if args.methods:
                methods = [m for m in methods if m in args.methods.split(",")]
            for method in methods:
                if adapter.missing(case, method) or duplicate_of(adapter, case, method) is not None:
                    continue
                if _twin(adapter, case, method, methods):
                    continue
                if hasattr(adapter, "prepare"):
                    adapter.prepare(case, method)
                result, runs = _search(engine, case, method)
                every += runs
                same = collections.Counter((dt, steps, n) for _p, dt, steps, n, _s in runs)
                twice = sum(c - 1 for c in same.values() if c > 1)
                limit = result.dt_limit if math.isfinite(result.dt_limit) else float("nan")
                said = f", {twice} run(s) made twice" if twice else ""
                print(_line(f"{case.name} {engine} {method} ({limit:.5g} s{said})", runs), flush=True)
    print(_line("all", every))


if __name__ == "__main__":
    main()
