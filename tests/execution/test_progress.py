"""Progress lines: done / total, elapsed and remaining, on a terminal and in a log."""

from __future__ import annotations

import io
import re

from truestep.execution.progress import Progress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_plain_lines_in_a_log_say_done_total_elapsed_and_left():
    log = io.StringIO()
    with Progress(3, "sweep", stream=log) as p:
        for k in range(3):
            p.done(f"row {k}")
    lines = log.getvalue().splitlines()
    assert len(lines) == 3
    assert re.match(r"\[1/3\] sweep +\d+\.\d s elapsed, +~\d+ s left  row 0$", lines[0])
    assert lines[2].startswith("[3/3] sweep") and "~0 s left" in lines[2]


def test_a_terminal_gets_a_bar_with_each_line_above_it():
    tty = Terminal()
    with Progress(2, "sweep", stream=tty) as p:
        p.done("row 0")
        p.done("row 1")
    out = tty.getvalue()
    assert "row 0\n" in out and "row 1\n" in out and "sweep:" in out and "/2 [" in out


def test_a_callers_say_gets_the_lines_only():
    got: list[str] = []
    with Progress(2, "sweep", say=got.append) as p:
        p.done("a")
        p.done("b")
    assert got == ["a", "b"]
