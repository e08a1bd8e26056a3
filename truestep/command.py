"""The ``truestep`` command's entry point: a process of truestep's own, which computes as
every truestep run does (:func:`truestep.numerics.set_environment`, before numpy loads)."""

from __future__ import annotations

from truestep import numerics


def main(argv: list[str] | None = None) -> int:
    """Set the numerical environment, then run :func:`truestep.cli.main`."""
    numerics.set_environment()
    from truestep.cli import main as run_command

    return run_command(argv)
