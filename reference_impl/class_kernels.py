"""Constants and compiled kernels a ``typing.NamedTuple`` class carries beside its fields.

A NamedTuple's body may declare only fields (anything else is not a field to a type
checker), yet the scene's force kinds, the methods and the layouts are NamedTuples (numba
passes them to compiled code as records) that also name their kernels, read when a step
is compiled (``type(kind).add``, ``type(layout).start``:
:mod:`~truestep.reference_impl.by_type`). :func:`carries` attaches them after the class
is made.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T", bound=type)


def carries(**attributes: Any) -> Callable[[T], T]:
    """A class decorator that sets each of ``attributes`` on the class."""

    def attach(cls: T) -> T:
        for name, value in attributes.items():
            setattr(cls, name, value)
        return cls

    return attach
