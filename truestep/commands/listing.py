"""``truestep list``: the cases with their features and sweeps, the engines with their
methods and capabilities (an engine not installed with the pip line that adds it)."""

from __future__ import annotations

import argparse

from truestep.commands import common
from truestep.runtime.visible import visible


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``list`` command's parser, under ``sub``."""
    lst = sub.add_parser(
        "list",
        help="print cases, engines (installed or not), capabilities and methods",
        description="Print the cases with their features and the engines with "
        "their methods and capabilities; an engine that is not installed is listed "
        "with the pip line that adds it.",
    )
    lst.add_argument("--cases", default="*", metavar="ITEMS", help=common.CASES_HELP)
    lst.add_argument("--engines", default=None, metavar="NAMES", help="engine names, comma-separated")
    lst.add_argument(
        "--quick",
        action="store_true",
        help="the cases a `truestep run --quick` runs (without --cases: those marked for it) "
        "and the steps and tolerances of their quick sweeps",
    )
    lst.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from truestep.api import engines, shadowed

    cases = common.load(args.cases, quick=args.quick)  # as `truestep run --quick` chooses
    print("cases" + (" of a --quick run:" if args.quick else ":"))
    for c in cases:
        print(f"  {c.name:24s} {c.kind:9s} features: {', '.join(sorted(c.features))}")
        steps = ", ".join(f"{h:.4g}" for h in c.sweep(adaptive=False, quick=args.quick))
        tols = ", ".join(f"{t:g}" for t in c.sweep(adaptive=True, quick=args.quick))
        print(f"  {'':24s} {'':9s} steps (s): {steps or '-'}; tolerances: {tols or '-'}")
    print("engines:")
    for line in shadowed():
        print(visible(f"  {line}"))
    names = None if not args.engines else [e.strip() for e in args.engines.split(",")]
    for info in engines(names):
        if info.status != "installed":  # one line each, the list goes on
            print(visible(f"  {info.name:10s} {info.status}"))
            continue
        print(visible(f"  {info.name:10s} methods: {', '.join(info.methods)}"))
        print(visible(f"  {'':10s} capabilities: {', '.join(info.capabilities)}"))
        if info.devices:
            print(
                f"  {'':10s} devices: cpu (the default), or a GPU: truestep run --device {info.name}=cuda:0"
            )
    return 0
