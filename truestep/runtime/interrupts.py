"""SIGTERM, SIGINT and SIGHUP during ``truestep run``: kill the children, unwind, say so.

Inside :func:`handled`, the first SIGTERM, SIGINT or SIGHUP kills every live child process
(:func:`truestep.runtime.isolation.kill_children`) and raises :class:`Interrupted` where the main
thread is, so every ``finally`` on the way out runs (staging folders are removed, the
previous report stays). Later signals only kill children again: the unwinding itself is
not interrupted.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

HANDLED = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)


class Interrupted(BaseException):
    """A handled signal arrived. A ``BaseException``, so that no ``except Exception``
    that turns a failure into a row swallows it. ``published``: the new report was
    already in place when it arrived."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum
        self.published = False


@contextmanager
def handled() -> Iterator[None]:
    """Turn SIGTERM, SIGINT and SIGHUP into :class:`Interrupted` while inside (main thread only;
    elsewhere nothing changes). The previous handlers are restored on the way out."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    from truestep.runtime.isolation import kill_children

    fired: list[int] = []

    def on_signal(signum: int, _frame: object) -> None:
        kill_children()
        if not fired:
            fired.append(signum)
            raise Interrupted(signum)

    previous = {s: signal.signal(s, on_signal) for s in HANDLED}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
