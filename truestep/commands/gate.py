"""``truestep gate``: a run's gates and its baseline comparison checked
(:func:`truestep.api.gate`), the verdicts printed and written for CI (JUnit, markdown,
JSON, ``$GITHUB_STEP_SUMMARY``). Exit 0 when everything checked holds and something was
checked, 1 otherwise, 2 on bad input."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from truestep.commands import common
from truestep.commands.common import UsageError
from truestep.runtime.visible import visible
from truestep.tables.spec import compared


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``gate`` command's parser, under ``sub``."""
    gate = sub.add_parser(
        "gate",
        help="check gates (and a baseline) against a run's tables",
        description="Check the gates of the case files, and of --gates files, "
        "against a run's tables; with --baseline, compare the run with an earlier "
        "one row by row. Exit 0 when everything checked holds and something was "
        "checked, 1 otherwise, 2 on bad input.",
    )
    gate.add_argument(
        "--results",
        default="reports/results.csv",
        metavar="FILE",
        help="the run's results.csv; stability.csv and restitution.csv are read from "
        "beside it (default: reports/results.csv)",
    )
    gate.add_argument(
        "--cases",
        default=None,
        metavar="ITEMS",
        help=common.CASES_HELP.replace("every case of the library", "the cases of the results"),
    )
    common.limit_arguments(gate, "the results (those the run read with --limit)")
    gate.add_argument(
        "--gates",
        action="append",
        default=[],
        metavar="FILE",
        help="a gates file ([[gates]] tables with a `cases` pattern; optional "
        "[baseline] tolerances); repeatable",
    )
    gate.add_argument(
        "--declared-orders",
        action="store_true",
        help="also gate every fixed-step method's fitted order against the order "
        "its engine declares, on every smooth case with an exact solution",
    )
    gate.add_argument(
        "--baseline",
        default=None,
        metavar="DIR",
        help="an earlier run's output directory to compare with, row by row",
    )
    gate.add_argument(
        "--engines",
        default=None,
        metavar="NAMES",
        help="only the verdicts and baseline rows of these engines (comma-separated names, or "
        "module:Class of an adapter, whose declared facts --declared-orders then reads); the rows "
        "a gate or --time-against compares with are read whatever their engine",
    )
    gate.add_argument(
        "--identical",
        action="store_true",
        help="with --baseline: also require every non-timing cell to equal the "
        "baseline's, bit for bit (when both runs' run.json name the same packages "
        "and floating-point environment; else says why not and uses tolerances)",
    )
    gate.add_argument(
        "--require-identical",
        action="store_true",
        help="--identical, and a baseline that cannot be compared bit for bit (other package "
        "versions or floating-point environment, or no run.json) fails the gate instead of "
        "falling back to tolerances: for CI that pins the packages its baseline was made with",
    )
    gate.add_argument(
        "--tolerance",
        action="append",
        default=[],
        metavar="QUANTITY=X",
        help=f"override a baseline tolerance ({', '.join(compared())}); repeatable",
    )
    gate.add_argument(
        "--time-against",
        default=None,
        metavar="ENGINE/METHOD",
        help="compare wall time with the baseline as a ratio to this engine/method's "
        "rows of the same case and step (off by default)",
    )
    gate.add_argument("--junit", default=None, metavar="FILE", help="write a JUnit XML report")
    gate.add_argument(
        "--markdown",
        default=None,
        metavar="FILE",
        help="write a markdown summary (also appended to $GITHUB_STEP_SUMMARY when set)",
    )
    gate.add_argument("--json", default=None, metavar="FILE", help="write every verdict as JSON")
    gate.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="print gates that held and baseline rows that got better or appeared",
    )
    gate.add_argument("-q", "--quiet", action="store_true", help="do not print gates not evaluated")
    gate.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from truestep.api import GateInputError, GateRequest, gate

    request = GateRequest(
        results=Path(args.results),
        baseline=None if not args.baseline else Path(args.baseline),
        gates=tuple(args.gates),
        cases=args.cases,
        engines=args.engines,
        declared_orders=args.declared_orders,
        identical=args.identical,
        require_identical=args.require_identical,
        tolerances=tuple(args.tolerance),
        time_against=args.time_against,
        limits=tuple(args.limit),
        trust_limits=args.trust_limits,
    )
    try:
        report = gate(request)
    except GateInputError as err:
        raise UsageError(str(err)) from None
    for line in report.console(verbose=args.verbose, quiet=args.quiet):
        print(line)
    try:
        report.write(
            junit=args.junit,
            markdown=args.markdown,
            json=args.json,
            step_summary=os.environ.get("GITHUB_STEP_SUMMARY") or None,
        )
    except OSError as err:
        raise UsageError(
            f"cannot write {visible(err.filename or 'an output')}: {err.strerror or err}"
        ) from None
    return 0 if report.passed else 1
