"""Python's cyclic garbage collector around a run: off while the engines are imported, and
blind to what was alive before the run's first process is forked.

Importing every engine makes about a million objects that live as long as the process. A
full collection walks all of them and finds nearly nothing: the collector starts one each
time the long-lived objects have grown by a quarter, so a quick run paid for many of them
before its first row, a large part of its start, and more later. With the collector off
during the imports and those objects frozen (:func:`gc.freeze`) for the run, no
collection walks them again, in the run's process or in the processes it forks (which
would also copy every page of them that a collection touches).

Both are scoped: the collector's state, and the objects frozen, are put back as they were
when the block ends, so that calling :func:`truestep.run` from a user's program changes
nothing of that program's collector once it returns.
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator


@contextlib.contextmanager
def paused() -> Iterator[bool]:
    """The block with the cyclic collector off; as before after it. Yields whether it was
    on. Reference counting still frees what the block drops: only cycles wait."""
    was_on = gc.isenabled()
    gc.disable()
    try:
        yield was_on
    finally:
        if was_on:
            gc.enable()


@contextlib.contextmanager
def frozen(*, collecting: bool = True) -> Iterator[None]:
    """The block with every object alive on entry left out of the collector's passes
    (:func:`gc.freeze`) and given back to it at the end (:func:`gc.unfreeze`); the collector
    is on in the block where ``collecting``, and as before after it. Where objects are
    frozen already (:func:`settle`, or the program's own), they stay so.

    Entered inside :func:`paused`, the objects made during the pause are frozen before
    any collection walks them (once the collector is on again, the first collection would
    walk them all, and after the engines' imports they are many)."""
    was_on = gc.isenabled()
    froze = not gc.get_freeze_count()
    if froze:
        gc.freeze()
    if collecting:
        gc.enable()
    try:
        yield
    finally:
        if froze:
            gc.unfreeze()
        if not was_on:
            gc.disable()


def settle() -> None:
    """Freeze every object alive now for the rest of the process: for truestep's own
    command process only, whose engines and modules live to its end (a program that calls
    :func:`truestep.run` gets :func:`frozen`, scoped to the run)."""
    gc.freeze()
