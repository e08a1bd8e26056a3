"""The reference ``dopri5`` against scipy's ``RK45`` in wall time, at equal evaluations.

Run: ``python -m pytest benchmarks/test_dopri5_against_rk45.py --benchmark-enable -q -s``

Both are Dormand-Prince 5(4) with the same RMS error norm, controller and initial step,
on the same right-hand side (the reference system's derivative), so they take the same
steps and make the same evaluations (``nfev``; hanging-cloth is the exception: its step
sequence is set by round-off, see ``tests/reference_impl/test_explicit_rk.py``) and the wall time
compares the integrators' own overhead. For each case and each tolerance of its sweep a
test times, alternately (A B A B ...: machine noise hits both alike),

- **A**, ``get_adapter("reference").simulate(case, "dopri5", tol).wall_s``;
- **B**, ``get_adapter("scipy").simulate(case, "RK45", tol).wall_s``;

each the adapter's own timed region (stepping and recording; building the scene is
outside). One warm-up pair, then :data:`REPEATS` to :data:`MAX_REPEATS` pairs (short runs
repeat more, :data:`MIN_SECONDS`); the ratio is median(A) / median(B), the target at most
:data:`TARGET`. The machine is shared and noisy: compare ratios measured in the same run,
never absolute times across runs. The table printed at the end (``-s``) has the numbers;
``benchmark.extra_info`` keeps every sample.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable

import pytest

from truestep.adapters import get_adapter
from truestep.adapters.base import Trajectory
from truestep.cases.loader import CASE_DIR, load_case

CASES = (
    "arenstorf-orbit",
    "kepler-orbit",
    "close-encounter",
    "circle-field",
    "spring-chain",
    "hanging-cloth",
    "spring-damper-pair",
)
"""The ODE cases and particle scenes both engines run; each at every tolerance of its sweep."""
RUNS = [(name, tol) for name in CASES for tol in load_case(CASE_DIR / f"{name}.toml").tolerances]
REPEATS = 7
"""Fewest timed rounds per test, after one warm-up round."""
MIN_SECONDS = 0.3
"""Short runs repeat until each way has been timed for about this long..."""
MAX_REPEATS = 100
"""... but at most this many rounds."""
WARMUP = 1
TARGET = 1.0
"""dopri5 / RK45: at least as fast."""


@pytest.fixture(scope="module")
def table():
    """Rows collected by the tests, printed at the end of the module (``-s`` shows them):
    (case, tolerance, steps A / B, nfev A / B, median A s, median B s, A / B of the
    medians, A / B of the fastest runs, rounds)."""
    rows: list[tuple[str, float, str, str, float, float, float, float, int]] = []
    yield rows
    print(
        f"\n\nA = reference dopri5, B = scipy RK45, wall_s of adapter.simulate; median of "
        f"{REPEATS}-{MAX_REPEATS} interleaved runs after {WARMUP} warm-up; target A/B <= "
        f"{TARGET:.2f}"
    )
    print(
        f"{'case':20s} {'tol':>7s} {'steps A/B':>11s} {'nfev A/B':>13s} {'A ms':>9s} "
        f"{'B ms':>9s} {'A/B':>6s} {'min A/min B':>11s} {'rounds':>6s}"
    )
    for name, tol, steps, nfev, a, b, ratio, best, rounds in rows:
        flag = "  > target" if ratio > TARGET else ""
        print(
            f"{name:20s} {tol:7.0e} {steps:>11s} {nfev:>13s} {a * 1e3:9.3f} {b * 1e3:9.3f} "
            f"{ratio:6.3f} {best:11.3f} {rounds:6d}{flag}"
        )
    ratios = [row[6] for row in rows]
    if ratios:
        print(
            f"{'all':20s} {'':7s} {'':11s} {'':13s} {'':9s} {'':9s} "
            f"{statistics.median(ratios):6.3f}   (median of the ratios; max {max(ratios):.3f})"
        )


def interleave(benchmark, runs: list[Callable[[], float]]) -> tuple[list[list[float]], int]:
    """Time each of ``runs`` (each returns its own seconds) in turn, round after round.

    One warm-up round, then as many rounds as give the slowest way :data:`MIN_SECONDS`
    of timed runs (:data:`REPEATS` to :data:`MAX_REPEATS`). Returns the timed samples of
    each way, warm-up dropped, and the number of timed rounds.
    """
    samples: list[list[float]] = [[] for _ in runs]

    def one_round() -> None:
        for run, sample in zip(runs, samples, strict=True):
            sample.append(run())

    one_round()
    longest = max(sample[0] for sample in samples)
    rounds = min(MAX_REPEATS, max(REPEATS, math.ceil(MIN_SECONDS / longest)))
    benchmark.pedantic(one_round, rounds=rounds, iterations=1)
    return [sample[WARMUP:] for sample in samples], rounds


@pytest.mark.parametrize(("name", "tol"), RUNS, ids=[f"{n}-{t:g}" for n, t in RUNS])
def test_dopri5_against_rk45(benchmark, table, name, tol):
    case = load_case(CASE_DIR / f"{name}.toml")
    reference, scipy = get_adapter("reference"), get_adapter("scipy")
    last: dict[str, Trajectory] = {}

    def run_dopri5() -> float:
        last["dopri5"] = reference.simulate(case, "dopri5", tol)
        return last["dopri5"].wall_s

    def run_rk45() -> float:
        last["RK45"] = scipy.simulate(case, "RK45", tol)
        return last["RK45"].wall_s

    benchmark.group = f"dopri5 against RK45: {name}"
    (a, b), rounds = interleave(benchmark, [run_dopri5, run_rk45])
    ours, theirs = last["dopri5"], last["RK45"]
    assert ours.status == theirs.status == "ok", (ours.message, theirs.message)
    assert getattr(ours, "path", "numpy") in ("", "numpy")  # the numpy solver, not a compiled loop
    ratio, best = statistics.median(a) / statistics.median(b), min(a) / min(b)
    benchmark.extra_info.update(
        dopri5_s=a,
        rk45_s=b,
        dopri5_median_s=statistics.median(a),
        rk45_median_s=statistics.median(b),
        ratio=ratio,
        ratio_of_minima=best,
        target=TARGET,
        steps=(ours.steps, theirs.steps),
        nfev=(ours.nfev, theirs.nfev),
        rounds=rounds,
    )
    table.append(
        (
            name,
            tol,
            f"{ours.steps}/{theirs.steps}",
            f"{ours.nfev}/{theirs.nfev}",
            statistics.median(a),
            statistics.median(b),
            ratio,
            best,
            rounds,
        )
    )
