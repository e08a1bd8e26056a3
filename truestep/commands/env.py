"""``truestep env``: the variables that give this machine truestep's numbers."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``env`` command's parser, under ``sub``."""
    env = sub.add_parser(
        "env",
        help="print the environment that gives truestep's numbers",
        description="Print, as shell export lines, the variables truestep sets "
        "in its own processes so that every machine computes the same numbers "
        "(one BLAS thread, the same OpenBLAS kernels, numpy's SIMD dispatch up "
        'to AVX2). Start Dask workers after `eval "$(truestep env)"`.',
    )
    env.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """``truestep env``: the variables that give this machine truestep's numbers, as shell
    ``export`` lines (for processes truestep does not start itself: Dask workers)."""
    import shlex

    from truestep.api import environment

    for key, value in environment().items():
        print(f"export {key}={shlex.quote(value)}")
    return 0
