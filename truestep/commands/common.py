"""What the commands share: the usage error (exit 2), messages to standard error, the
``--limit`` and ``--results`` options, case selection (through :mod:`truestep.api`), and
the refusal of an empty or enclosing output folder."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from truestep.cases.limits import CEILING
from truestep.cases.limits import KEYS as LIMIT_KEYS
from truestep.runtime.visible import visible

if TYPE_CHECKING:
    from truestep.cases.case import Case

CASES_HELP = (
    "cases: names or shell globs of the case library, case files and directories, "
    "comma-separated (default: every case of the library); each item must match"
)
ENGINES_HELP = (
    "engines: registered names or module:Class of an adapter, comma-separated "
    "(default: every installed engine)"
)


class UsageError(Exception):
    """Bad command-line input: printed as one line, exit code 2."""


def say(msg: str) -> None:
    """A line for the user on standard error, with hidden characters shown."""
    print(visible(msg), file=sys.stderr)


class Parser(argparse.ArgumentParser):
    """argparse's parser, except that help and usage that cannot be written (standard
    output on a full device) raise :class:`OSError` rather than pass in silence: the
    command then says so and ends 2 (argparse would exit 0 after ``--help`` wrote nothing)."""

    def _print_message(self, message: str, file: Any = None) -> None:
        if message:
            (file or sys.stderr).write(message)


def limit_arguments(parser: argparse.ArgumentParser, whose: str) -> None:
    """``--limit`` and ``--trust-limits``, alike for ``run`` and ``gate`` (a case run under
    a raised limit is gated under the same limit)."""
    parser.add_argument(
        "--limit",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="set a cost limit for every case, over the defaults and the case "
        "files' [limits] (keys: " + ", ".join(LIMIT_KEYS) + "); repeatable",
    )
    parser.add_argument(
        "--trust-limits",
        action="store_true",
        help=f"the cases of {whose} are trusted: --limit may raise a limit beyond "
        "the ceiling a case file cannot pass ("
        + ", ".join(f"{k} {getattr(CEILING, k):.3g}" for k in LIMIT_KEYS)
        + ")",
    )


def results_argument(parser: argparse.ArgumentParser) -> None:
    """``--results FILE`` of a command that reads a run's folder (``baseline save``,
    ``history add`` and ``export``)."""
    parser.add_argument(
        "--results",
        default="reports/results.csv",
        metavar="FILE",
        help="the run's results.csv; its other tables and run.json beside it (default: reports/results.csv)",
    )


def load(
    selection: str, limit_items: list[str] | None = None, *, quick: bool = False, trust_limits: bool = False
) -> list[Case]:
    """The cases of a ``--cases`` selection under the ``--limit`` items
    (:func:`truestep.api.select_cases`; a bad limit item is a :class:`UsageError`)."""
    from truestep.api import select_cases
    from truestep.cases.limits import LimitError

    try:
        return select_cases(selection, quick=quick, limits=limit_items or (), trust_limits=trust_limits)
    except LimitError as err:
        raise UsageError(str(err)) from None


def folder(value: str, option: str) -> Path:
    """The folder ``option`` names, refused when the value is empty or blank (``--out
    "$OUTDIR"`` with the variable unset must not mean the working folder) or names the
    working folder or one above it (truestep replaces the folder it writes whole, and a
    shell left in a folder replaced under it is in none)."""
    if not value.strip():
        raise UsageError(f"{option}: an empty path (an unset variable?): name the folder")
    path = Path(value)
    here = Path.cwd().resolve()
    whole = path.resolve()
    if whole == here or whole in here.parents:
        raise UsageError(
            f"{option}: {visible(value)} is the working folder or one above it, which truestep "
            "would replace whole: name a folder inside it"
        )
    return path
