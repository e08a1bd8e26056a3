"""``truestep run``: the main job, :func:`truestep.run` with the report in ``--out``."""

from __future__ import annotations

import argparse
import signal
from pathlib import Path

from truestep.commands import common
from truestep.commands.common import UsageError
from truestep.runtime.visible import visible

RUN_BUDGET_S = 6 * 3600.0
"""The default wall-clock budget of a whole ``truestep run``, s."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``run`` command's parser, under ``sub``."""
    run = sub.add_parser(
        "run",
        help="run the matrix and the analyses, write the tables and the report",
        description="Run every case with every engine and method that can model "
        "it, the stability searches and the restitution sweep; write results.csv, "
        "stability.csv, restitution.csv, scorecard.csv, index.md, index.html and figures/. The "
        "report is put in place as a whole: a run that fails or is killed leaves "
        "the previous one as it was. SIGTERM or SIGINT stops the run (exit 128 + "
        "the signal); its finished sweeps are kept for --resume.",
    )
    run.add_argument(
        "--quick",
        action="store_true",
        help="short sweeps of the quick cases, no energy or lecture figures (CI smoke run)",
    )
    run.add_argument("--cases", default="*", metavar="ITEMS", help=common.CASES_HELP)
    run.add_argument("--engines", default=None, metavar="NAMES", help=common.ENGINES_HELP)
    run.add_argument(
        "--out", default=None, metavar="DIR", help="output directory (default: reports, or the --resume DIR)"
    )
    run.add_argument(
        "--resume",
        nargs="?",
        const="",
        default=None,
        metavar="DIR",
        help="continue the interrupted run whose --out was DIR (default: --out): "
        "take its finished sweeps (and analyses) from .DIR.partial beside it and "
        "run the rest; the cases, engines, their code, --quick and truestep version must be "
        "the same (else exit 2). Without --resume a run starts afresh",
    )
    common.limit_arguments(run, "this run")
    run.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run the sweeps and the untimed analyses on a Dask cluster: "
        "tcp://HOST:PORT of a running `dask scheduler`, or local:N for a "
        "LocalCluster of N single-threaded worker processes; one timed run per "
        "host at a time (needs truestep[dask])",
    )
    run.add_argument(
        "--device",
        default=None,
        metavar="DEVICE",
        help="where the engines that take a device (mujoco-warp, newton) compute: cpu "
        "(the default), cuda or cuda:N for every one of them, or ENGINE=DEVICE pairs, "
        "comma-separated (newton=cuda:0,mujoco-warp=cpu); every other engine computes on the "
        "CPU. A device this machine lacks, or an engine that takes none, exits 2 before "
        "anything runs",
    )
    run.add_argument(
        "--budget",
        type=float,
        default=RUN_BUDGET_S,
        metavar="S",
        help=f"wall-clock budget of the whole run, s (default {RUN_BUDGET_S:g}): work "
        "still running when it ends, and work not started, are timeout rows that say "
        "so, and the report is written",
    )
    run.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """``truestep run``: sweep, analyses, report; checkpointed for ``--resume``.

    SIGTERM or SIGINT stops the run: the children are killed, the staging folder is
    removed, the previous report stays as it was, and the exit code is 128 + the signal
    with one line that says so. Finished sweeps (and the analyses, once done) stay in the
    journal beside ``--out`` (:func:`truestep.api.resumable`) until the report is published.
    """
    if args.out is not None:  # `--out "$OUTDIR"`, unset: not reports/
        common.folder(args.out, "--out")
    from truestep.api import Interrupted, interruptible, resumable

    with interruptible():
        try:
            return _run(args)
        except Interrupted as err:
            out = args.out or args.resume or "reports"
            where = (
                f"the new report is in {out}/"
                if err.published
                else f"{out}/ holds the previous report, untouched"
            )
            kept = resumable(Path(args.resume or out))
            then = (
                f"; the same command with --resume continues from the {kept[0]} finished sweeps in {kept[1]}"
                if kept is not None
                else ""
            )
            common.say(f"truestep: interrupted by {signal.Signals(err.signum).name}: {where}{then}")
            return 128 + err.signum
        except OSError as err:  # a full disk, a file too large, a folder gone: one line
            out = args.out or args.resume or "reports"
            what = visible(err.filename) if err.filename else "the report or its checkpoints"
            raise UsageError(
                f"cannot write {what}: {err.strerror or err}; {out}/ holds the "
                "previous report, untouched (finished sweeps are kept for "
                "--resume)"
            ) from None


def _run(args: argparse.Namespace) -> int:
    """``truestep run`` once its arguments are checked: :func:`truestep.run` (the one
    experiment driver, :mod:`truestep.execution.experiment`) with the report in ``--out``."""
    from truestep.api import (
        ClusterError,
        DeviceError,
        JournalError,
        LockBusy,
        OutRefused,
        check_report_folder,
        engines_for_run,
        run,
    )

    args.out = args.out or args.resume or "reports"
    if not 0 < args.budget < float("inf"):
        raise UsageError(f"--budget: must be a positive number of seconds, got {args.budget:g}")
    engines = engines_for_run(args.engines, say=common.say)
    if not engines:
        raise UsageError("--engines: no engine is installed")
    cases = common.load(args.cases, args.limit, quick=args.quick, trust_limits=args.trust_limits)
    out = Path(args.out)
    try:
        check_report_folder(out)
        tables = run(
            cases,
            engines,
            quick=args.quick,
            out=out,
            progress=None,
            resume=None if args.resume is None else (args.resume or args.out),
            scheduler=args.scheduler,
            budget=args.budget,
            lecture_figures=not args.quick,
            argv=_reproduce(args),
            device=args.device,
        )
    except DeviceError as err:
        raise UsageError(f"--device: {err}") from None
    except JournalError as err:
        raise UsageError(f"--resume: {err}") from None
    except (LockBusy, OutRefused, ClusterError) as err:
        raise UsageError(str(err)) from None
    laps = tables.seconds
    try:
        print(
            f"wrote {visible(out)}/ ({len(tables.results)} result rows) in {sum(laps.values()):.1f} s: "
            f"sweep {laps['sweep']:.1f} s, analyses {laps['analyses']:.1f} s, report {laps['report']:.1f} s",
            flush=True,
        )
    except OSError as err:  # stdout full or gone: the report is published all the same
        raise UsageError(
            f"the new report is in {visible(out)}/, but standard output could not be written: "
            f"{err.strerror or err}"
        ) from None
    return 0


def _reproduce(args: argparse.Namespace) -> list[str]:
    """The ``truestep run`` arguments that reproduce this run."""
    argv = ["run"] + (["--quick"] if args.quick else [])
    if args.cases != "*":
        argv += ["--cases", args.cases]
    if args.engines:
        argv += ["--engines", args.engines]
    if args.out != "reports":
        argv += ["--out", args.out]
    if args.device:
        argv += ["--device", args.device]
    return argv
