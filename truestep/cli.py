"""The ``truestep`` command line: the parser of every command (:mod:`truestep.commands`, a
module each) and :func:`main`, which runs one and turns bad input into one line.

Exit codes: 0 success; 1 a gate failed, something got worse than the baseline, or
nothing was checked; 2 bad input (one line naming the file, the field and the reason,
no traceback; nothing already written is touched).
"""

from __future__ import annotations

import argparse
import sys

from truestep import __version__
from truestep.commands import baseline, bench, compiling, env, figures, gate, history, listing, run
from truestep.commands.common import Parser, UsageError
from truestep.runtime.supervisor import DID_NOT_FINISH
from truestep.runtime.visible import visible

__all__ = ["COMMANDS", "UsageError", "build_parser", "main"]

COMMANDS = (run, gate, baseline, history, listing, figures, env, compiling, bench)
"""The commands' modules, in the order ``truestep --help`` lists them."""


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``truestep`` and every command of :data:`COMMANDS`."""
    parser = Parser(
        prog="truestep",
        description="truestep: a verification and benchmark harness for "
        "physically based animation. Exit codes: 0 success, 1 a gate failed or nothing was "
        "checked, 2 bad input.",
    )
    parser.add_argument("--version", action="version", version=f"truestep {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command ``argv`` names (default: ``sys.argv[1:]``) and return its exit code."""
    args = build_parser().parse_args(argv)
    from truestep.adapters import EngineNotInstalled, UnknownEngine
    from truestep.cases.errors import CaseError, SelectionError
    from truestep.cases.plugins import PluginError

    try:
        return args.func(args)
    except (CaseError, UsageError, SelectionError, UnknownEngine, EngineNotInstalled, PluginError) as err:
        print(f"truestep: error: {visible(err)}", file=sys.stderr)
        return 2
    except SystemExit as err:  # argparse is done: only code the command ran gets here
        print(
            f"truestep: error: code the command ran called sys.exit({visible(repr(err.code))}) "
            "(an adapter, a case library or an exact solution): the command did not finish",
            file=sys.stderr,
        )
        return DID_NOT_FINISH


if __name__ == "__main__":
    sys.exit(main())
