"""``truestep bench``: particle-steps per second against n on the rain scene."""

from __future__ import annotations

import argparse
import math
import time

from truestep.commands import common
from truestep.commands.common import UsageError
from truestep.runtime.visible import visible

BENCH_BUDGET_MAX_S = 86400.0
"""The longest ``truestep bench --budget`` (a day): a budget of ``inf`` or ``1e308``
overflowed the step counts it sizes, with a traceback."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``bench`` command's parser, under ``sub``."""
    from truestep.execution.bench_defaults import BUDGET_S, SIZES  # light: not the API

    sizes = ",".join(f"{n:.0e}".replace("e+0", "e") for n in SIZES)
    bench = sub.add_parser(
        "bench",
        help="particle-steps per second against n on the rain scene",
        description="How cost grows with work: run the particle-rain scene with "
        "n particles (1e2 to 1e6) through every fixed-step method of every engine, "
        "one timed run at a time in a process of its own, and print "
        "particle-steps per second with the fraction of the copy bandwidth "
        "measured in the same run; write DIR/scaling.csv and "
        "DIR/figures/scaling.png. Sizes that do not fit in the budget are "
        "rows that say so.",
    )
    bench.add_argument("--engines", default=None, metavar="NAMES", help=common.ENGINES_HELP)
    bench.add_argument("--out", default="bench", metavar="DIR", help="output directory (default: bench)")
    bench.add_argument(
        "--budget",
        default=BUDGET_S,
        type=float,
        metavar="S",
        help=f"seconds for the timed runs (default: {BUDGET_S:g}; one warm-up per "
        "engine/method comes on top); each engine/method gets an equal share of "
        "what is left, and skips the sizes that would not fit",
    )
    bench.add_argument(
        "--sizes",
        default=sizes,
        metavar="N,N,...",
        help=f"particle counts, comma-separated (default: {sizes})",
    )
    bench.add_argument(
        "--threads",
        default=1,
        type=int,
        metavar="N",
        help="threads of the engines that take a count: the reference steps its tiles of "
        "independent particles N at a time (default 1; its rows say so); every other "
        "engine runs as it does",
    )
    bench.add_argument(
        "--device",
        default=None,
        metavar="DEVICE",
        help="where the engines that take a device compute, as `truestep run --device` takes it: "
        "cuda:0 for every one of them, newton=cuda:0 for one (default: every engine on the CPU; "
        "each row names its device)",
    )
    bench.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """``truestep bench``: the sizes and budget checked, then :func:`truestep.api.bench`,
    its table printed."""
    import pandas as pd

    from truestep.api import MAX_PARTICLES, DeviceError, OutRefused, bench, select_engines

    try:
        sizes = [float(s) for s in args.sizes.split(",") if s.strip()]
    except ValueError:
        sizes = []
    if not sizes or not all(math.isfinite(n) and n >= 1 for n in sizes):
        raise UsageError(
            f"--sizes: expected particle counts of 1 or more, comma-separated, got {args.sizes!r}"
        )
    if max(sizes) > MAX_PARTICLES:
        raise UsageError(
            f"--sizes: {max(sizes):g} particles is over the {MAX_PARTICLES:g} a scene may have "
            "(the rain scene is read as a case, under the default limits)"
        )
    if not 0 < args.budget <= BENCH_BUDGET_MAX_S:
        raise UsageError(
            f"--budget: expected seconds above 0 and at most {BENCH_BUDGET_MAX_S:g}, got {args.budget:g}"
        )
    if args.threads < 1:
        raise UsageError(f"--threads: expected a whole number of at least 1, got {args.threads}")
    folder = common.folder(args.out, "--out")
    engines = select_engines(args.engines, say=common.say)
    if not engines:
        raise UsageError("--engines: no engine is installed")
    start = time.perf_counter()
    try:
        table = bench(
            engines, sizes=sizes, budget_s=args.budget, out=folder, threads=args.threads, device=args.device
        )
    except DeviceError as err:
        raise UsageError(f"--device: {err}") from None
    except OutRefused as err:
        raise UsageError(str(err)) from None
    bandwidth = table.attrs["bandwidth_bytes_per_s"]
    shown = table.assign(note=table["note"].str.slice(0, 100))
    with pd.option_context(
        "display.width",
        250,
        "display.max_rows",
        None,
        "display.max_colwidth",
        100,
        "display.float_format",
        "{:.4g}".format,
    ):
        print("\n".join(visible(line) for line in shown.to_string(index=False).splitlines()))
    per_step = table.attrs["bytes_per_particle_step"]
    print(
        f"copy bandwidth {bandwidth / 1e9:.2f} GB/s (numpy copy, best of 5, measured in this "
        f"run) = {bandwidth / per_step:.3g} particle-steps/s at {per_step} B per particle-step "
        f"(positions and velocities, float64, read and written)"
    )
    warm = table.attrs["warmup_s"]
    print(
        f"wrote {table.attrs['csv']} and {table.attrs['figure']} in {time.perf_counter() - start:.1f} s: "
        f"the table took {table.attrs['elapsed_s']:.1f} s of the {args.budget:g} s budget "
        f"(compiling and warm-ups {warm:.1f} s of it)"
    )
    return 0
