"""``truestep baseline save DIR``: a run's tables kept as a baseline, with their provenance
(:func:`truestep.ci.saved.save`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from truestep.commands import common
from truestep.commands.common import UsageError
from truestep.runtime.visible import visible


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``baseline`` command's parser, under ``sub``."""
    base = sub.add_parser(
        "baseline",
        help="keep a run as a baseline, with its provenance",
        description="Keep a run's tables as a baseline for `truestep gate --baseline DIR`.",
    )
    actions = base.add_subparsers(dest="action", required=True, metavar="ACTION")
    save = actions.add_parser(
        "save",
        help="save a run's tables and their provenance into DIR",
        description="Copy a run's results.csv, stability.csv, restitution.csv and "
        "run.json into DIR cell for cell, without the host name or absolute paths "
        "(made relative to the working directory, the project's root), beside a "
        "provenance.json: the truestep that ran them, every engine's distribution "
        "version and the project's git revision. DIR must be new, empty, or a "
        "baseline saved before (replaced as a whole); anything else is exit 2.",
    )
    save.add_argument("dir", metavar="DIR", help="the baseline's folder")
    common.results_argument(save)
    save.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """``truestep baseline save DIR``: a run's tables kept as a baseline
    (:func:`truestep.api.save_baseline`)."""
    from truestep.api import BaselineRefused, save_baseline

    try:
        provenance = save_baseline(Path(args.results), common.folder(args.dir, "DIR"))
    except BaselineRefused as err:
        raise UsageError(str(err)) from None
    except OSError as err:
        raise UsageError(
            f"cannot save the baseline: {visible(err.filename or '')} {err.strerror or err}"
        ) from None
    project = provenance["project"]
    where = (
        f"project revision {project['revision'][:12]}" + (" (with changes)" if project["dirty"] else "")
        if project
        else "no git revision (not a checkout)"
    )
    print(f"saved {args.results} as baseline {args.dir} ({provenance['ran_with']}, {where})")
    return 0
