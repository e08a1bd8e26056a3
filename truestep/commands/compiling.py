"""``truestep compile``: the reference's loops (and the engines' kernels) compiled ahead."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``compile`` command's parser, under ``sub``."""
    comp = sub.add_parser(
        "compile",
        help="compile the reference's loops ahead (a build step)",
        description="Compile the reference implementation's loops for every "
        "case of the library and of the figures and every fixed-step method, "
        "on every core, into numba's on-disk cache, as a first `truestep run` "
        "does before its first timed run (long when the cache is empty; a second "
        "call only loads them); with MuJoCo Warp or Newton "
        "installed, also their kernels for every scene they run, into Warp's "
        "kernel cache, each in a process of its own beside the reference's.",
    )
    comp.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """``truestep compile``: compile the reference's loops for every case file of the library
    and of the figures, every fixed-step method, on every core, into numba's cache (what a
    first ``truestep run`` does before its first timed run), and the kernels of each
    installed engine that has a ``warm`` hook (Warp's engines) into its own cache, each
    engine in a forked process beside the reference's compile
    (:func:`truestep.api.compile_ahead`): a build step for a fresh machine. Exit 1 where an
    engine's kernels failed to compile (one line says which)."""
    from truestep.api import compile_ahead

    return 1 if compile_ahead(say=_say) else 0


def _say(line: str) -> None:
    print(line, flush=True)
