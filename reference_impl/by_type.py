"""What numba needs to pick a scene's kernels by the types of what it holds.

A compiled step is written once against generic calls (``add_forces(scene, ...)``,
``collisions(layout, scene, ...)``); each is a plain Python function (the spec, and what
runs with ``NUMBA_DISABLE_JIT=1``) with a numba ``overload`` that, given the *types* of its
arguments, returns the code for them: the kernels of the force kinds a scene's tuple
holds, in order, or nothing for a part the scene lacks (its field ``None``). numba
compiles a step once for each combination of those types, inlining the code each
overload returns, and caches it with its types; nothing is tested at run time to skip a
part, and no code is written as text.
"""

from __future__ import annotations

from typing import Any

from numba.core import types

BY_TYPE: dict[str, Any] = {"jit_options": {"error_model": "numpy", "_nrt": False}}
"""How a generic call's overload is compiled: inlined into the step that makes it, as the
kernels it calls are (:data:`~truestep.reference_impl.forces_kernels.KERNEL`)."""


def field(record: Any, name: str) -> Any:
    """The numba type of field ``name`` of the NamedTuple type ``record``."""
    return record.types[record.fields.index(name)]


def is_none(record: Any, name: str) -> bool:
    """Whether field ``name`` of ``record`` is ``None`` (a part the scene lacks)."""
    return isinstance(field(record, name), types.NoneType)


def kernel(kind: Any, role: str) -> Any:
    """What the class of a kind (a NamedTuple type) carries as ``role``: its kernel of
    that role (``add``, ``at``, ``energy``, ``cut``) or a constant (``pointwise``)."""
    return getattr(kind.instance_class, role)
