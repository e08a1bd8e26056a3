"""``truestep history add | show | export``: runs kept by commit (:mod:`truestep.ci.history`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from truestep.commands import common
from truestep.commands.common import UsageError


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``history`` command's parser, under ``sub``."""
    hist = sub.add_parser(
        "history",
        help="keep runs by commit and show a quantity over commits",
        description="A history is a folder of runs saved by the project's git revision "
        "(as `truestep baseline save` saves one). `add` saves a run; `show` prints one "
        "row's quantity over the saved commits and names the commits where it stepped; "
        "`export` writes a run as the JSON github-action-benchmark reads.",
    )
    steps = hist.add_subparsers(dest="action", required=True, metavar="ACTION")
    h_add = steps.add_parser("add", help="save a run into the history under the project's git revision")
    h_show = steps.add_parser("show", help="a row's quantity over the saved commits, and where it stepped")
    h_export = steps.add_parser(
        "export", help="a run as github-action-benchmark JSON (customSmallerIsBetter)"
    )
    for p in (h_add, h_show):
        p.add_argument(
            "--store",
            default=".truestep-history",
            metavar="DIR",
            help="the history's folder (default: .truestep-history)",
        )
    for p in (h_add, h_export):
        common.results_argument(p)
    h_show.add_argument(
        "quantity", metavar="QUANTITY", help="a numeric column of results.csv (error, wall_s, nfev ...)"
    )
    h_show.add_argument("--case", required=True)
    h_show.add_argument("--engine", required=True)
    h_show.add_argument("--method", required=True)
    h_show.add_argument("--dt", type=float, default=None, help="the row's step (or tolerance)")
    h_show.add_argument(
        "--tolerance",
        type=float,
        default=None,
        metavar="X",
        help="relative change that is a step (default: the baseline's tolerance for the quantity, else 0.1)",
    )
    h_export.add_argument("--out", default="-", metavar="FILE", help="where to write (default: stdout)")
    hist.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """``truestep history add | show | export`` (:func:`truestep.api.history_add`,
    :func:`truestep.api.history`, :func:`truestep.api.benchmark_json`)."""
    import json

    from truestep import api

    try:
        if args.action == "add":
            entry = api.history_add(args.results, args.store)
            print(f"added {args.results} to {args.store} as {entry['folder']}")
            return 0
        if args.action == "export":
            try:
                runs = api.benchmark_json(args.results)
            except api.TableError as err:
                raise UsageError(str(err)) from None
            text = json.dumps(runs, indent=1) + "\n"
            if args.out == "-":
                sys.stdout.write(text)
            else:
                Path(args.out).write_text(text)
            return 0
        kept = api.history(
            args.quantity,
            args.case,
            args.engine,
            args.method,
            dt=args.dt,
            store=args.store,
            tolerance=args.tolerance,
        )
    except api.HistoryError as err:
        raise UsageError(str(err)) from None
    points, found, tol = kept.points, set(kept.stepped), kept.tolerance
    if not points:
        raise UsageError(f"{args.store}: no saved run (truestep history add first)")
    moved = kept.another_machine
    for k, p in enumerate(points):
        mark = ""
        if k in found:
            before = points[k - 1].value
            mark = f"  <- stepped: {before:.6g} -> {p.value:.6g}"
        if k in moved:
            mark += f"  [timed on another machine from here: {moved[k]}]"
        dirty = "+" if p.dirty else " "
        print(f"{p.revision[:12]}{dirty} {p.value:.6g} ({p.status}){mark}")
    print(
        f"{len(found)} step(s) in {len(points)} commits (a change of more than {tol:g}, relative, "
        "between the medians of up to 3 commits on either side)"
    )
    return 0
