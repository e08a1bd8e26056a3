"""What a compiled derivative buys the engines that call one back at every evaluation
(Drake's integrators, scipy's ``solve_ivp``; issue 34, item 3). Per case, the seconds of
one call of the system's Python derivative and of its compiled twin
(``System.compiled_derivative``), and whether both give the same bits on random states;
then a few Drake rows run both ways, their wall times and whether the runs are the same;
then the reference's rows whose step has no compiled loop (implicit Euler's Newton
iteration), which call the twin since stop 73: ``ReferenceAdapter(compiled=False)`` (the
numpy derivative) against the default, alternated, the median of three each.
A timing check, so a benchmark, never a unit test::

    python benchmarks/compiled_derivative.py             # every case, Drake's and the reference's rows
    python benchmarks/compiled_derivative.py --no-drake --no-reference  # the derivatives only
"""

from __future__ import annotations

import argparse
import timeit

import numpy as np

DRAKE_ROWS = (
    ("earth-orbit", "bogacki_shampine3", 1e-6),
    ("long-orbit", "runge_kutta3", 0.05),
    ("stiff-cloth", "implicit_euler", 1e-3),
    ("hanging-cloth", "runge_kutta3", 2e-3),
)
"""(case, Drake method, step or tolerance) of the rows run with each derivative."""
REFERENCE_ROWS = (
    ("stiff-cloth", "implicit-euler", 2.5e-4),
    ("hanging-cloth", "implicit-euler", 2e-3),
    ("rope-pendulum", "implicit-euler", 5e-4),
    ("kepler-orbit", "implicit-euler", 1e-3),
)
"""(case, reference method, step) of the numpy-path rows run with each derivative."""


def _seconds(fn, y: np.ndarray) -> float:
    """Seconds of one call ``fn(y, 0.0)``: the least of 3 means over 2000 calls."""
    return min(timeit.repeat(lambda: fn(y, 0.0), number=2000, repeat=3)) / 2000


def derivatives(states: int) -> None:
    from truestep.adapters.reference import build_system
    from truestep.cases import load_cases

    rng = np.random.default_rng(0)
    print(f"{'case':22s} {'python us':>10s} {'compiled us':>12s}  same bits on {states} states")
    for case in load_cases("*"):
        system = build_system(case)
        fast = system.compiled_derivative()
        if fast is None:
            print(f"{case.name:22s} {'-':>10s} {'-':>12s}  no compiled twin")
            continue
        y0 = system.get_state()
        same = all(
            np.array_equal(fast(y, t), system.derivative(y, t))
            for y, t in (
                (y0 * (1 + 0.2 * rng.standard_normal(y0.shape)), float(rng.uniform(0, case.duration)))
                for _ in range(states)
            )
        )
        slow_s, fast_s = (_seconds(fn, y0) for fn in (system.derivative, fast))
        print(f"{case.name:22s} {slow_s * 1e6:10.2f} {fast_s * 1e6:12.2f}  {same}")


def drake_rows() -> None:
    from truestep.adapters.drake_adapter import DrakeAdapter
    from truestep.cases import load_cases

    cases = {c.name: c for c in load_cases("*")}
    print(f"\n{'drake row':42s} {'python s':>9s} {'compiled s':>11s}  same run")
    for name, method, dt in DRAKE_ROWS:
        slow = DrakeAdapter(compiled=False).simulate(cases[name], method, dt)
        fast = DrakeAdapter().simulate(cases[name], method, dt)
        same = (fast.nfev, fast.steps) == (slow.nfev, slow.steps) and np.array_equal(fast.x, slow.x)
        print(f"{name + ' ' + method + f' {dt:g}':42s} {slow.wall_s:9.2f} {fast.wall_s:11.2f}  {same}")


def reference_rows() -> None:
    import statistics

    from truestep.adapters.reference import ReferenceAdapter
    from truestep.cases import load_cases

    cases = {c.name: c for c in load_cases("*")}
    print(f"\n{'reference row':42s} {'python s':>9s} {'compiled s':>11s}  same run")
    for name, method, dt in REFERENCE_ROWS:
        runs: dict[bool, list] = {True: [], False: []}
        for twin in (True, False) * 3:
            runs[twin].append(ReferenceAdapter(compiled=twin).simulate(cases[name], method, dt))
        fast, slow = runs[True][0], runs[False][0]
        same = (fast.nfev, fast.steps) == (slow.nfev, slow.steps) and np.array_equal(fast.x, slow.x)
        slow_s, fast_s = (statistics.median(r.wall_s for r in runs[k]) for k in (False, True))
        print(f"{name + ' ' + method + f' {dt:g}':42s} {slow_s:9.2f} {fast_s:11.2f}  {same}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=20, help="random states compared per case (default 20)")
    parser.add_argument("--no-drake", action="store_true", help="leave out the Drake rows")
    parser.add_argument("--no-reference", action="store_true", help="leave out the reference's rows")
    args = parser.parse_args()
    derivatives(args.states)
    if not args.no_drake:
        drake_rows()
    if not args.no_reference:
        reference_rows()


if __name__ == "__main__":
    main()
