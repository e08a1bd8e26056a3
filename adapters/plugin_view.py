"""What truestep's own process holds of an adapter of another package: data, never the object.

A plugin's adapter is code truestep did not write, and so is everything it does when it
is made (``__init__``) or read (a property). truestep makes it, and reads every public
attribute of it, once, in a forked process (:func:`probe`): an attribute that is plain
data (what :func:`truestep.runtime.plain_data.loads` builds: numbers, strings,
containers of them, truestep's own records) comes back as its value; a method comes back
as its name and signature; anything else as what it is (its type, or what reading it
raised). truestep's process then holds a :class:`PluginView` of that record in place of
the adapter:

- reading an attribute returns its value (an attribute that raised when read raises
  :class:`~truestep.adapters.PluginFailed` saying so); one that is not plain data (method
  facts whose step matrix is a function, say) is the class's own attribute of that name,
  read statically (``inspect.getattr_static``: no property or ``__getattr__`` of the
  plugin runs), else an ``AttributeError`` naming its type;
- calling a method there makes the call on a real adapter in a forked process
  (:func:`truestep.adapters.plugin_answer`): plugin code that ends, hangs or crashes that
  process is a :class:`~truestep.adapters.PluginFailed` naming the plugin and the call;
- in a process truestep forked to run the engine (an isolated child,
  :func:`truestep.runtime.isolation.in_isolated_child`), the view makes the real adapter
  there, once, and calls it: the runs step the plugin's own code, contained.

``inspect.signature`` of a method read from a view is the plugin's (truestep asks whether
``simulate`` takes ``monitor``).
"""

from __future__ import annotations

import inspect
import pickle
from collections.abc import Callable, Mapping
from typing import Any

VALUE, METHOD, OPAQUE, RAISED, FACTS = "value", "method", "opaque", "raised", "facts"
"""What the probe found for an attribute: plain data, a method, something else (its type
named), an exception when read (its text), or method facts (:func:`_facts_as_data`)."""

FACTS_ATTRIBUTES = ("method_facts", "schemes")
"""The attributes that map a method to its facts (:func:`truestep.adapters.base.facts_of`)."""

Record = dict[str, tuple[str, Any]]
"""An adapter's public attributes as :func:`probe` reads them: name -> (kind, detail)."""

_NO_DEFAULT = "no default"


def _said(err: BaseException) -> str:
    """What an exception a plugin raised says, in one phrase."""
    if isinstance(err, SystemExit):
        return f"called sys.exit({err.code!r})"
    return f"raised {type(err).__name__}: {str(err)[:200]}"


def _signature(fn: Callable[..., Any]) -> list[tuple[str, str, bool]] | None:
    """A method's parameters as data: (name, kind, whether it has a default); ``None``
    where Python cannot say."""
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return None
    return [(p.name, p.kind.name, p.default is not inspect.Parameter.empty) for p in params]


def _as_data(value: Any) -> tuple[str, Any]:
    """``(VALUE, value)`` where ``value`` crosses a process boundary as data (it is read back
    here by the same rules as in truestep's process; a read-only mapping as a dict), else
    ``(OPAQUE, its type's name)``."""
    from truestep.runtime import plain_data

    if isinstance(value, Mapping) and not isinstance(value, dict):
        value = dict(value)
    try:
        return VALUE, plain_data.loads(pickle.dumps(value))
    except Exception:
        return OPAQUE, type(value).__qualname__


def _facts_as_data(declared: Any) -> tuple[str, Any]:
    """Method facts (method -> a reference method's name or a ``MethodFacts``) as data: a
    record whose step matrix is a reference method's (``MethodFacts.like``, or the
    reference's own record) crosses without it, beside that method's name, and gets it
    back from truestep's own solvers (:func:`_facts_from_data`). A step matrix of the
    plugin's own does not cross: the view reads the class's own attribute statically where
    it has one (:meth:`PluginView.__getattr__`), else the facts come without it (the limits
    on damped modes are then unknown, as for facts declared without one)."""
    import dataclasses

    from truestep.reference_impl.solvers.facts import NAMED, MethodFacts

    if not isinstance(declared, Mapping):
        return _as_data(declared)
    owners = {id(f.stability.step_matrix): m for m, f in NAMED.items() if f.stability is not None}
    entries: dict[Any, Any] = {}
    dropped = False
    for method, spec in declared.items():
        owner = None
        stability = getattr(spec, "stability", None)
        if isinstance(spec, MethodFacts) and stability is not None and stability.step_matrix is not None:
            owner = owners.get(id(stability.step_matrix))
            dropped = dropped or owner is None
            spec = dataclasses.replace(spec, stability=dataclasses.replace(stability, step_matrix=None))
        entries[method] = (spec, owner)
    kind, value = _as_data(entries)
    return (FACTS, (value, dropped)) if kind == VALUE else (kind, value)


def _facts_from_data(entries: dict[Any, Any]) -> dict[Any, Any]:
    """The mapping :func:`_facts_as_data` sent, each step matrix back from its owner."""
    import dataclasses

    from truestep.reference_impl.solvers.facts import NAMED

    out = {}
    for method, (spec, owner) in entries.items():
        if owner is not None:
            matrix = NAMED[owner].stability.step_matrix  # type: ignore[union-attr]
            spec = dataclasses.replace(
                spec, stability=dataclasses.replace(spec.stability, step_matrix=matrix)
            )
        out[method] = spec
    return out


def probe(cls: type) -> Record | str:
    """In a forked process: make an adapter of ``cls`` and read its public attributes
    (:data:`Record`), or what making it did (``"raised ..."``, ``"interrupted its own
    process (SIGINT)"``)."""
    import signal

    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        adapter = cls()
    except KeyboardInterrupt:
        return "interrupted its own process (SIGINT)"
    except BaseException as err:
        return f"could not be made: {type(err).__name__}: {str(err)[:200]}"
    record: Record = {}
    for name in dir(adapter):
        if name.startswith("_"):
            continue
        try:
            value = getattr(adapter, name)
        except KeyboardInterrupt:
            return f"interrupted its own process (SIGINT) when {name} was read"
        except BaseException as err:
            record[name] = (RAISED, _said(err))
            continue
        if callable(value) and not isinstance(value, type):
            record[name] = (METHOD, _signature(value))
        elif name in FACTS_ATTRIBUTES:
            record[name] = _facts_as_data(value)
        else:
            record[name] = _as_data(value)
    return record


def _stand_in_signature(params: list[tuple[str, str, bool]]) -> inspect.Signature:
    """The signature :func:`_signature` read, rebuilt (a default stands for the plugin's)."""
    return inspect.Signature(
        [
            inspect.Parameter(
                name,
                getattr(inspect.Parameter, kind),
                default=_NO_DEFAULT if has_default else inspect.Parameter.empty,
            )
            for name, kind, has_default in params
        ]
    )


class PluginView:
    """truestep's process's view of a plugin's adapter (see the module docstring): made
    from :func:`probe`'s record of an adapter of ``cls``, registered as engine ``engine``;
    a method called here is ``ask(engine, "name()", fn, *args, **kwargs)``
    (:func:`truestep.adapters.plugin_answer`), and an attribute that raised when read
    raises ``failed`` (:class:`truestep.adapters.PluginFailed`)."""

    def __init__(
        self,
        engine: str,
        cls: type,
        record: Record,
        *,
        ask: Callable[..., Any],
        failed: type[Exception],
    ) -> None:
        self._engine, self._cls, self._record = engine, cls, record
        self._ask, self._failed = ask, failed
        self._methods: dict[str, Callable[..., Any]] = {}
        self._real: Any = None

    def __repr__(self) -> str:
        return f"<view of {self._cls.__module__}.{self._cls.__qualname__} (engine {self._engine})>"

    def __dir__(self) -> list[str]:
        return sorted(self._record)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_") or name not in self._record:
            raise AttributeError(name)
        kind, detail = self._record[name]
        if kind == VALUE:
            return detail
        static = inspect.getattr_static(self._cls, name, None)
        plain_static = static is not None and not hasattr(type(static), "__get__")
        if kind == FACTS:
            entries, dropped = detail
            return static if dropped and plain_static else _facts_from_data(entries)
        if kind == METHOD:
            if name not in self._methods:
                self._methods[name] = self._stand_in(name, detail)
            return self._methods[name]
        if kind == RAISED:
            raise self._failed(f"{self._engine}: reading its adapter's {name} {detail}")
        if plain_static:
            return static  # the class's own value, read without running its code
        raise AttributeError(f"{self._engine}: its adapter's {name} is a {detail}, not plain data")

    def real(self) -> Any:
        """The plugin's adapter itself, made in this process once: only in a process
        truestep forked to run it (:func:`truestep.runtime.isolation.in_isolated_child`)."""
        from truestep.runtime.isolation import in_isolated_child

        if not in_isolated_child():
            raise RuntimeError(f"{self!r}: the adapter itself is made only in an isolated child")
        if self._real is None:
            self._real = self._cls()
        return self._real

    def _stand_in(self, name: str, params: list[tuple[str, str, bool]] | None) -> Callable[..., Any]:
        """The method ``name`` as truestep's process calls it: on the real adapter in a
        forked process (or here, in an isolated child), with the plugin's signature."""
        from truestep.runtime.isolation import in_isolated_child

        def call(*args: Any, **kwargs: Any) -> Any:
            if in_isolated_child():
                return getattr(self.real(), name)(*args, **kwargs)
            return self._ask(self._engine, f"{name}()", call, *args, **kwargs)

        call.__name__ = call.__qualname__ = name
        if params is not None:
            call.__signature__ = _stand_in_signature(params)  # type: ignore[attr-defined]
        return call


__all__ = ["PluginView", "Record", "probe"]
