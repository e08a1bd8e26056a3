"""What an isolated child sends back, read as data: arrays, plain values and truestep's own
records, never an object that runs code of its own in truestep's process.

A child's result is pickled there and unpickled here. Plain ``pickle.loads`` would call
whatever callable the bytes name: an engine's result object whose ``__reduce__`` names
``os._exit`` ends truestep with status 0 and no report, one that names ``time.sleep``
hangs it past every timeout. :func:`loads` resolves only the names of :data:`ALLOWED`
and the dataclasses of truestep's own modules (:class:`~truestep.adapters.base.Trajectory`,
:class:`~truestep.execution.timing.TimedRuns`, ...), built field by field, and members of its
enumerations (:class:`~truestep.reference_impl.features.Feature`), looked up by value; any other name
is :class:`Refused`, and the call's row says which name it was.
"""

from __future__ import annotations

import dataclasses
import enum
import importlib
import io
import pickle
from typing import Any

ALLOWED: frozenset[tuple[str, str]] = frozenset(
    {
        ("numpy", "dtype"),
        ("numpy", "ndarray"),
        ("numpy._core.multiarray", "_reconstruct"),
        ("numpy._core.multiarray", "scalar"),
        ("numpy.core.multiarray", "_reconstruct"),
        ("numpy.core.multiarray", "scalar"),
        ("builtins", "complex"),
        ("builtins", "set"),
        ("builtins", "frozenset"),
        ("builtins", "bytearray"),
        ("builtins", "slice"),
        ("collections", "OrderedDict"),
        ("pathlib", "PosixPath"),
        ("pathlib", "PurePosixPath"),
        ("pathlib", "Path"),
    }
)
"""The names a child's result may use besides truestep's dataclasses: numpy's arrays,
dtypes and scalars (an object array's items are read by the same rules), the builtin
containers pickle names, and paths (the figures a drawing process wrote)."""

OWN_PACKAGE = "truestep."
"""The modules whose dataclasses a result may hold (records with fields, no behaviour at
construction)."""


class Refused(pickle.UnpicklingError):
    """A result names something :func:`loads` does not build: ``name`` is ``module.name``."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.name = name


class _Unpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        if (module, name) in ALLOWED:
            return super().find_class(module, name)
        if module.startswith(OWN_PACKAGE) and "." not in name:
            found = getattr(importlib.import_module(module), name, None)
            if isinstance(found, type) and (dataclasses.is_dataclass(found) or issubclass(found, enum.Enum)):
                return found  # a record built field by field, or a member looked up by value
        raise Refused(f"{module}.{name}")


def loads(data: bytes) -> Any:
    """The value pickled in ``data``, built from :data:`ALLOWED` names and truestep's
    dataclasses only; :class:`Refused` (naming what) for anything else."""
    return _Unpickler(io.BytesIO(data)).load()


def refused_words(err: Refused) -> str:
    """How a row says its result was refused."""
    return (
        f"its result holds {err.name}, which truestep does not build from an engine's process "
        "(a result crosses as arrays, plain values and truestep's own records)"
    )
