"""Steps composed from what a scene declares: code written once, compiled against its kernels.

The driver (:mod:`~truestep.reference_impl.integrate_kernels`), the steps of each method
and layout (:mod:`~truestep.reference_impl.solvers.explicit_rk_kernels`,
:mod:`~truestep.reference_impl.solvers.splitting_kernels`, :mod:`~truestep.reference_impl.tiles`)
and the derivative (:mod:`~truestep.reference_impl.particles_kernels`) are written once,
against *slots*: named placeholders (:func:`slot`) for what a scene may or may not have,
its force kinds, impulses and planes, an energy monitor, the method's step. A run fills
the slots (:func:`~truestep.reference_impl.step_slots.slots_for`): a kernel, a few lines of
glue that call the kernels of the kinds the scene declares in order (:func:`glue`), or
nothing. :func:`instantiate` then compiles the driver with every slot it reaches filled:
a copy of each function that names a slot (directly or through what it calls), whose
globals hold the fillings, all compiled into one loop (numba inlines functions compiled
with ``inline='always'`` before it types them). A part the scene lacks is no code at all;
nothing is tested at run time to skip it.

numba caches the compiled loop on disk under a name made from its fillings and the source
of every module of the reference implementation (:data:`FINGERPRINT`), so a changed kernel
is compiled afresh, never taken stale from the cache. With ``NUMBA_DISABLE_JIT=1`` the
same composition runs as Python.
"""

from __future__ import annotations

import hashlib
import inspect
from pathlib import Path
from types import FunctionType
from typing import Any

from numba import njit
from numba.core.dispatcher import Dispatcher

INLINE: dict[str, Any] = {"error_model": "numpy", "inline": "always"}
"""How composed functions are compiled: into the loop that calls them."""
COLD: dict[str, Any] = {"cache": True, "error_model": "numpy", "_nrt": False}
"""How the rarely called parts of a loop are compiled (a tile's start, a collision pass, a
particle stepped again alone, the stop after a blow-up): on their own, called, so that
numba does not copy them into the loop (it copies a function it inlines once for every
place that calls it, a cost that grows with the square of the loop's size)."""
COPY_COLD: dict[str, Any] = {"error_model": "numpy", "_nrt": False}
"""How a copy of a rarely called part is compiled (:func:`instantiate`)."""
LOOP: dict[str, Any] = {"cache": True, "error_model": "numpy", "_nrt": False, "nogil": True}
"""How a composed loop is compiled: cached on disk, without numba's reference counting
(its arrays all come from Python, which holds them while it runs; it allocates none), so
that passing arrays between the functions it is made of costs nothing, and without
Python's lock while it runs, so that threads may step a run's tiles at once."""


def source_fingerprint(folder: Path) -> str:
    """A hash of the name and source of every Python module under ``folder`` (its
    subfolders too), in the order of their paths."""
    digest = hashlib.sha256()
    for path in sorted(folder.rglob("*.py")):
        digest.update(path.relative_to(folder).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:12]


FINGERPRINT = source_fingerprint(Path(__file__).parent)
"""A hash of the source of every module of the reference implementation (this module's
folder): part of the name under which a compiled loop is cached, so that a change to any
of them, whatever a loop is made of, compiles the loops afresh (numba's own cache checks
only the file of the function it compiles)."""


class Slot:
    """A placeholder for a part of a step that depends on the scene (see the module
    docstring): its name, parameters and docstring say what a filling must do."""

    def __init__(self, fn) -> None:
        self.name = fn.__name__
        self.params = list(inspect.signature(fn).parameters)
        self.__doc__ = fn.__doc__

    def __call__(self, *args):
        raise RuntimeError(f"slot {self.name} called before it was filled (compose.instantiate)")

    def __repr__(self) -> str:
        return f"<slot {self.name}({', '.join(self.params)})>"


def slot(fn) -> Slot:
    """Declare ``fn`` (its signature and docstring; its body is never run) a slot."""
    return Slot(fn)


def glue(s: Slot, body: list[str], names: dict) -> Dispatcher:
    """A filling for slot ``s``: a function of its parameters whose ``body`` (lines of
    Python) may call ``names``; compiled inline."""
    source = f"def {s.name}({', '.join(s.params)}):\n" + "".join(
        f"    {line}\n" for line in body or ["return None"]
    )
    namespace = dict(names)
    exec(compile(source, f"<{s.name} of a compiled step>", "exec"), namespace)
    fn = namespace[s.name]
    fn.__doc__ = source
    return njit(**INLINE)(fn)


def nothing(s: Slot, value: str = "None") -> Dispatcher:
    """The filling of slot ``s`` for a scene that lacks its part: returns ``value`` (the
    name of one of its parameters, or a constant)."""
    return glue(s, [f"return {value}"], {})


def python_function(fn):
    """The Python function of a kernel, compiled or plain."""
    return fn.py_func if isinstance(fn, Dispatcher) else fn


def name_of(fn) -> str:
    """The name of a kernel, compiled or plain."""
    return python_function(fn).__name__


def source_of(filling) -> str:
    """The source of a glue filling (:func:`glue`)."""
    return python_function(filling).__doc__ or ""


def _function(value) -> bool:
    """Whether ``value`` is a function that :func:`instantiate` can copy: compiled, or
    plain Python (as every kernel is with ``NUMBA_DISABLE_JIT=1``)."""
    return isinstance(value, (Dispatcher, FunctionType))


def _reaches(fn, slots: dict, memo: dict) -> bool:
    """Whether ``fn``'s code names a slot, or a function that does."""
    py = python_function(fn)
    if py in memo:
        return memo[py]
    memo[py] = False
    g = getattr(py, "__globals__", {})
    memo[py] = any(
        isinstance(g.get(name), Slot) or (_function(g.get(name)) and _reaches(g[name], slots, memo))
        for name in getattr(getattr(py, "__code__", None), "co_names", ())
    )
    return memo[py]


def instantiate(
    fn,
    slots: dict,
    *,
    options: dict | None = None,
    name: str | None = None,
    _memo: dict | None = None,
    _tag: str | None = None,
) -> Dispatcher:
    """``fn`` compiled with its slots filled from ``slots`` (slot name -> filling), and
    every function it calls that reaches a slot instantiated alike; compiled with
    ``options`` (default :data:`INLINE`) under the qualified ``name`` (default its own,
    tagged with the fillings: :func:`copy_name`)."""
    memo = {} if _memo is None else _memo
    tag = fillings_tag(slots) if _tag is None else _tag
    py = python_function(fn)
    if py in memo:
        return memo[py]
    g = dict(py.__globals__)
    for ident in py.__code__.co_names:
        value = g.get(ident)
        if isinstance(value, Slot):
            value = slots[value.name]
            g[ident] = value
        if _function(value) and _reaches(value, slots, {}):
            g[ident] = instantiate(value, slots, _memo=memo, _tag=tag)
    copy = FunctionType(py.__code__, g, py.__name__, py.__defaults__, py.__closure__)
    copy.__qualname__ = name or copy_name(py.__qualname__, tag)
    copy.__doc__, copy.__module__ = py.__doc__, py.__module__
    memo[py] = njit(**(options or _copy_options(fn)))(copy)
    return memo[py]


def _copy_options(fn) -> dict:
    """How a copy of ``fn`` is compiled: inlined if ``fn`` is, else on its own (not cached:
    its globals are one loop's); never with reference counting (:data:`LOOP`)."""
    inline = getattr(fn, "targetoptions", {}).get("inline", "never")
    return {"error_model": "numpy", "_nrt": False, "inline": inline}


def fillings_tag(slots: dict) -> str:
    """A hash of :data:`FINGERPRINT` and the fillings (each kernel's name, each glue's
    source): the same for the same composition in every process, else different."""
    text = FINGERPRINT + "".join(f"{k}={_label(v)};" for k, v in sorted(slots.items()))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def cache_name(base: str, slots: dict) -> str:
    """A name for a loop compiled with these fillings: ``base`` and :func:`fillings_tag`."""
    return f"{base}_{fillings_tag(slots)}"


def copy_name(qualname: str, tag: str) -> str:
    """The qualified name of a copy made for the fillings tagged ``tag``.

    A copy compiled on its own (not inlined) is a symbol of its loop's machine code, named
    by numba from its qualified name, its types and a counter that starts afresh in every
    process. Two loops loaded from numba's cache into one process may each hold a copy of
    the same function made in a different process with the same count; the linker then
    takes one for both, and one loop runs another's step. The tag keeps the names of
    copies for different fillings apart."""
    return f"{qualname}__{tag}"


def _label(filling) -> str:
    py = python_function(filling)
    if py.__code__.co_filename.startswith("<"):  # glue: its source
        return py.__doc__ or ""
    return f"{py.__module__}.{py.__qualname__}"
