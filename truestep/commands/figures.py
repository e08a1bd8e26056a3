"""``truestep figures``: the lecture's figures."""

from __future__ import annotations

import argparse

from truestep.commands import common
from truestep.commands.common import UsageError


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``figures`` command's parser, under ``sub``."""
    fig = sub.add_parser(
        "figures",
        help="reproduce the lecture's figures",
        description="Draw the lecture's figures into DIR/figures.",
    )
    fig.add_argument("--out", default="reports", metavar="DIR", help="output directory (default: reports)")
    fig.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """``truestep figures``: the lecture's figures (:func:`truestep.api.lecture_figures`)."""
    from truestep.api import OutRefused, lecture_figures

    try:
        drawn = lecture_figures(common.folder(args.out, "--out"))
    except OutRefused as err:
        raise UsageError(str(err)) from None
    for path, caption in drawn:
        print(f"{path}: {caption}")
    return 0
