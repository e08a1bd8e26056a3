"""A wall-clock limit for computations the harness makes in its own process on case data
(exact solutions, measuring a run), so that a case that would hang one ends as that
case's rows, not the run.

:func:`time_limit` uses ``SIGALRM`` (``setitimer``), so it interrupts Python code and
numpy calls between their C loops; it works in the main thread of a POSIX process and
is a no-op elsewhere (a worker thread, Windows), where the per-run process timeouts of
:mod:`truestep.runtime.isolation` still hold.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import threading
import time
from collections.abc import Iterator


class TimeLimitExceeded(BaseException):
    """A computation under :func:`time_limit` ran past its limit (a ``BaseException``, so
    that the ``except Exception`` of the code it interrupts does not swallow it)."""


def guard_seconds(variable: str, default: float) -> float:
    """A guard's limit, s: the environment ``variable`` where it holds a positive, finite
    number of seconds, else ``default`` (a value that is not one is ignored, as
    ``TRUESTEP_STOP_GRACE_S`` is). Read when the guard's module is imported: set it before
    the command starts."""
    try:
        value = float(os.environ.get(variable, ""))
    except ValueError:
        return default
    return value if math.isfinite(value) and value > 0 else default


def _usable() -> bool:
    return hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def time_limit(seconds: float, what: str = "the computation") -> Iterator[None]:
    """Raise :class:`TimeLimitExceeded` in the block if it runs over ``seconds`` (s).

    Nested limits are honoured (the inner one may not outlast the outer one's alarm:
    the earlier deadline wins and the outer one is restored afterwards).
    """
    if not _usable() or seconds <= 0:
        yield
        return

    def expire(signum, frame) -> None:
        raise TimeLimitExceeded(f"{what} took longer than {seconds:g} s")

    outer_left, _ = signal.getitimer(signal.ITIMER_REAL)
    start = time.monotonic()
    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds if not outer_left else min(seconds, outer_left))
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        if outer_left:
            signal.setitimer(signal.ITIMER_REAL, max(1e-3, outer_left - (time.monotonic() - start)))
