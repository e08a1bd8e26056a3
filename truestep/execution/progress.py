"""Progress of long runs, as a person reads it: done / total, elapsed and remaining time.

On a terminal a tqdm bar (tqdm is small, kept and does exactly this), with each finished
item's line printed above it; elsewhere (CI logs, pipes) plain lines that say the same:
``[ 12/240]   3.1 s elapsed, ~58 s left  <line>``. A caller that passes its own
``say`` (the Python API, the pytest plugin) gets each line and nothing else.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

from truestep.runtime.visible import visible


class Progress:
    """Counts ``total`` items of work labelled ``label``; :meth:`done` marks one finished.

    ``say``: where the lines go instead of the terminal (no bar, no counts); ``stream``:
    the terminal or log (default standard error).
    """

    def __init__(
        self,
        total: int,
        label: str,
        *,
        say: Callable[[str], None] | None = None,
        stream: TextIO | None = None,
    ) -> None:
        self.total, self.label, self.say = max(int(total), 0), label, say
        self.stream = stream or sys.stderr
        self.count = 0
        self.start = time.perf_counter()
        self.bar = None
        if say is None and self.total and self.stream.isatty():
            from tqdm import tqdm

            self.bar = tqdm(
                total=self.total, desc=label, unit="run", file=self.stream, dynamic_ncols=True, leave=False
            )

    def elapsed(self) -> float:
        return time.perf_counter() - self.start

    def remaining(self) -> float:
        """Seconds left at the pace so far (NaN before anything finished)."""
        if not self.count:
            return float("nan")
        return self.elapsed() / self.count * max(self.total - self.count, 0)

    def done(self, line: str = "", n: int = 1) -> None:
        """``n`` items finished; ``line`` says what the last one gave (hidden characters
        of names in it shown, :func:`truestep.runtime.visible.visible`)."""
        self.count += n
        line = visible(line)
        if self.say is not None:
            if line:
                self.say(line)
            return
        if self.bar is not None:
            if line:
                self.bar.write(line, file=self.stream)
            self.bar.update(n)
            return
        left = self.remaining()
        width = len(str(self.total))
        eta = f"~{left:.0f} s left" if left == left else ""
        print(
            f"[{self.count:{width}d}/{self.total}] {self.label} {self.elapsed():6.1f} s "
            f"elapsed, {eta:>12s}  {line}".rstrip(),
            file=self.stream,
            flush=True,
        )

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
