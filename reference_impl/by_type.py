"""What numba needs to pick a scene's kernels by the types of what it holds.

A compiled step is written once against generic calls (``add_forces(scene, ...)``,
``passes_collide(scene, ...)``, ``run_tile(method, layout, ...)``); each is a plain Python
function (the spec, and what runs with ``NUMBA_DISABLE_JIT=1``) with a numba ``overload``
that, given the *types* of its arguments, returns the code for them: the kernels of the
force kinds a scene's tuple holds, in order, or nothing for a part the scene lacks (its
field ``None``). numba compiles a step once for each combination of those types and
caches it with its types; nothing is tested at run time to skip a part, and no code is
written as text. What a loop holds beyond a scene's types (the tableau patterns of its
methods) rides in a :class:`Tag`.
"""

from __future__ import annotations

from typing import Any

from numba import njit
from numba.core import types
from numba.core.imputils import lower_constant
from numba.extending import (
    NativeValue,
    models,
    register_model,
    typeof_impl,
    unbox,
)

CALLED: dict[str, Any] = {
    "error_model": "numpy",
    "_nrt": False,
    "no_cpython_wrapper": True,
    "no_cfunc_wrapper": True,
}
"""How a function only ever called from compiled code is compiled: without the wrappers
Python (or C) would call it through, and without reference counting (a loop has none)."""
BY_TYPE: dict[str, Any] = {"jit_options": CALLED}
"""How a generic call's overload is compiled: on its own and called (LLVM then inlines the
small ones into the step). Not inlined by numba (``inline="always"``): numba 0.68 loses
the stores to an array held in a record, in a loop of a function it has itself inlined,
when an overload is inlined there too (numba issue 10037; the tiles' ``flags`` were never
set)."""


INLINE: dict[str, Any] = {"error_model": "numpy", "inline": "always"}
"""How the links of a :func:`fold` are compiled: into the overload that calls them."""


def fold(kinds: Any, first: Any, then: Any) -> Any:
    """A chain of calls over a tuple of kinds (its numba type ``kinds``): ``first`` (a
    function of the chain's arguments), then, for each kind ``k`` at index ``i`` in order,
    the function ``then(previous, i, k)`` returns (which calls ``previous``, the chain so
    far, and the kind's kernel on ``kinds[i]``); each link compiled into the overload that
    calls the chain, so that one generic call is one function however many kinds a scene
    holds."""
    chain = njit(**INLINE)(first)
    for i, kind in enumerate(kinds):
        chain = njit(**INLINE)(then(chain, i, kind))
    return chain


def field_type(record: Any, name: str) -> Any:
    """The numba type of field ``name`` of the NamedTuple type ``record``."""
    return record.types[record.fields.index(name)]


def is_none(record: Any, name: str) -> bool:
    """Whether field ``name`` of ``record`` is ``None`` (a part the scene lacks)."""
    return isinstance(field_type(record, name), types.NoneType)


def kernel(kind: Any, role: str) -> Any:
    """What the class of a kind (a NamedTuple type) carries as ``role``: its kernel of
    that role (``add``, ``at``, ``energy``, ``cut``) or a constant (``pointwise``)."""
    return getattr(kind.instance_class, role)


class Tag:
    """A value that carries ``key`` (a hashable constant: a method's pattern, the name of
    an acceleration) in its numba type, :class:`TagType`: a generic call given a tag is
    compiled for its key. It holds no data at run time."""

    __slots__ = ("key",)

    def __init__(self, key: Any) -> None:
        self.key = key

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Tag) and other.key == self.key

    def __hash__(self) -> int:
        return hash(("Tag", self.key))

    def __repr__(self) -> str:
        return f"Tag({self.key!r})"


class TagType(types.Type):
    """The numba type of a :class:`Tag`: one type for each key."""

    def __init__(self, key: Any) -> None:
        self.key_value = key
        super().__init__(name=f"Tag({key!r})")

    @property
    def key(self) -> Any:
        return self.key_value


@typeof_impl.register(Tag)
def _typeof_tag(value: Tag, c: Any) -> TagType:
    return TagType(value.key)


register_model(TagType)(models.OpaqueModel)


@unbox(TagType)
def _unbox_tag(typ: TagType, obj: Any, c: Any) -> NativeValue:
    return NativeValue(c.context.get_dummy_value())


@lower_constant(TagType)
def _tag_constant(context: Any, builder: Any, typ: TagType, value: Tag) -> Any:
    return context.get_dummy_value()


def tag_key(typ: Any) -> Any:
    """The key of a :class:`TagType`."""
    return typ.key_value
