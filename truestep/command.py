"""The ``truestep`` command's entry point: a process of truestep's own, which computes as
every truestep run does (:func:`truestep.numerics.set_environment`, before numpy loads)."""

from __future__ import annotations

import contextlib
import errno

from truestep import numerics

STREAM_ERRORS = (errno.ENOSPC, errno.EIO, errno.EDQUOT, errno.EFBIG)
"""Errors of a write to standard output that end a command with one line (exit 2), not a
traceback: a full disk or device (``> /dev/full``), a failed terminal or file."""


def main(argv: list[str] | None = None) -> int:
    """Set the numerical environment, then run :func:`truestep.cli.main` in a worker process
    that a small supervisor watches (:func:`truestep.runtime.supervisor.supervised`): code
    of a plugin that ends the process, leaves processes behind or ignores a signal cannot
    end the command quietly. Output cut short by its reader (``truestep list | head``) ends
    the command quietly, as ``cat`` does."""
    numerics.set_environment()
    from truestep.runtime.supervisor import supervised

    return supervised(lambda: _command(argv))


def _command(argv: list[str] | None) -> int:
    import os
    import sys

    from truestep.cli import main as run_command

    try:
        try:
            return run_command(argv)
        finally:  # here, where a full or broken stdout is said, not at exit (--help too)
            sys.stdout.flush()
    except BrokenPipeError:
        # the reader is gone: point stdout at /dev/null so that Python's exit flush is quiet
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, as a shell reports a command its pipe closed
    except OSError as err:
        if err.errno not in STREAM_ERRORS or err.filename is not None:
            raise
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        with contextlib.suppress(OSError):
            print(f"truestep: error: cannot write standard output: {err.strerror}", file=sys.stderr)
        return 2
