"""The ``truestep`` command's entry point: a process of truestep's own, which computes as
every truestep run does (:func:`truestep.numerics.set_environment`, before numpy loads)."""

from __future__ import annotations

from truestep import numerics


def main(argv: list[str] | None = None) -> int:
    """Set the numerical environment, then run :func:`truestep.cli.main`. Output cut short
    by its reader (``truestep list | head``) ends the command quietly, as ``cat`` does."""
    import os
    import sys

    numerics.set_environment()
    from truestep.cli import main as run_command

    try:
        return run_command(argv)
    except BrokenPipeError:
        # the reader is gone: point stdout at /dev/null so that Python's exit flush is quiet
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, as a shell reports a command its pipe closed
