"""Engines behind one Adapter protocol, found by entry point; the reference is one of them.

Every engine, the built-in ones included, is registered in the entry-point group
``truestep.adapters`` as ``name = "module:Class"`` (truestep's own in its
``pyproject.toml``); an installed package adds its engine the same way. An adapter that
is importable but not registered is named by its ``module:Class`` instead
(:func:`resolve_engine`), and from then on by its ``name`` in this process and the
processes it forks.

An engine's module is imported only when the engine is asked for. An engine whose
library is missing raises :class:`EngineNotInstalled`, naming the pip line that adds it.
"""

from __future__ import annotations

import contextlib
import functools
import os
import signal
import sys
import threading
from collections.abc import Callable
from importlib import metadata
from types import ModuleType
from typing import Any, Literal

from truestep.adapters.base import Adapter, FixedStepAdapter, Recording, Trajectory
from truestep.runtime.time_limit import guard_seconds

ENTRY_POINT_GROUP = "truestep.adapters"

BUILTIN: dict[str, str] = {
    "reference": "truestep.adapters.reference:ReferenceAdapter",
    "scipy": "truestep.adapters.scipy_ivp:ScipyAdapter",
    "pymunk": "truestep.adapters.pymunk_adapter:PymunkAdapter",
    "pybullet": "truestep.adapters.pybullet_adapter:PybulletAdapter",
    "mujoco": "truestep.adapters.mujoco_adapter:MujocoAdapter",
    "drake": "truestep.adapters.drake_adapter:DrakeAdapter",
    "mujoco-warp": "truestep.adapters.mujoco_warp_adapter:MujocoWarpAdapter",
    "newton": "truestep.adapters.newton_adapter:NewtonAdapter",
}
"""The built-in engines, as ``pyproject.toml`` registers them (a test keeps the two equal).
Read only when truestep's own distribution metadata is absent (a checkout run without
installing it)."""

EXTRAS: dict[str, str] = {
    "pymunk": "pymunk",
    "pybullet": "pybullet",
    "mujoco": "mujoco",
    "drake": "drake",
    "mujoco-warp": "mujoco-warp",
    "newton": "newton",
}
"""Built-in engine -> the optional extra of truestep that installs its library."""

LIBRARIES: dict[str, str] = {"reference": "truestep", "scipy": "scipy", **EXTRAS}
"""Built-in engine -> the distribution that does its stepping: the reference is truestep's
own, scipy is scipy, and each other's extra is named after its library."""

_RESOLVED: dict[str, str] = {}
"""Engines named by ``module:Class`` in this process: adapter name -> target."""


class UnknownEngine(KeyError):
    """An engine name that no entry point registers; ``str()`` is one line."""

    def __str__(self) -> str:
        return str(self.args[0])


class EngineNotInstalled(ImportError):
    """A registered engine whose library cannot be imported.

    ``engine`` is its name, ``missing`` the module that is absent and ``pip`` the line
    that installs it (``pip install "truestep[pymunk]"`` for a built-in engine).
    """

    def __init__(self, engine: str, missing: str, pip: str) -> None:
        self.engine, self.missing, self.pip = engine, missing, pip
        super().__init__(f"engine {engine!r} is not installed ({missing} is missing): {pip}")


SHADOWING: dict[str, str] = {}
"""Built-in engine name -> another package's registration of that name (``module:Class``
and its distribution), which is ignored: a second package cannot replace a built-in
engine by registering its name (:func:`shadowed` says so wherever engines are chosen)."""


@functools.cache
def _entry_points() -> dict[str, str]:
    found: dict[str, str] = {}
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in BUILTIN and ep.value != BUILTIN[ep.name]:
            owner = ep.dist.name if ep.dist is not None else "an unknown package"
            SHADOWING[ep.name] = f"{ep.value} (registered by {owner})"
            continue
        found[ep.name] = ep.value
    try:
        metadata.distribution("truestep")
    except metadata.PackageNotFoundError:
        found = {**BUILTIN, **found}
    return found


def shadowed() -> list[str]:
    """One line per built-in engine name another package also registers: that
    registration is ignored (name the class by ``module:Class`` to run it)."""
    _entry_points()
    return [
        f"engine {name}: another package registers this built-in name as {what}; ignored "
        f"(run it as --engines {what.split(' ')[0]})"
        for name, what in SHADOWING.items()
    ]


def registered() -> dict[str, str]:
    """Every engine this process knows: name -> ``module:Class``, built-in ones first."""
    found = {**_entry_points(), **_RESOLVED}
    order = [n for n in BUILTIN if n in found] + sorted(n for n in found if n not in BUILTIN)
    return {n: found[n] for n in order}


def truestep_target(engine: str) -> bool:
    """Whether engine ``engine`` is registered as a class of one of truestep's own modules
    (``truestep.…:Class``), read from its registration without importing it."""
    module = registered().get(engine, "").partition(":")[0]
    return module == "truestep" or module.startswith("truestep.")


def pip_line(engine: str) -> str:
    """The command that installs what ``engine`` needs."""
    if engine in EXTRAS:
        return f'pip install "truestep[{EXTRAS[engine]}]"'
    return f"pip install the package that provides engine {engine!r}"


GUARDED_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
"""The signal handlers an adapter module's import may not change for truestep."""


def _import_guarded(engine: str, module: str) -> ModuleType:
    """Import an adapter's module as code truestep did not write: what it prints goes to
    standard error (standard output is truestep's: tables, ``list``), and the working
    directory, the handlers of :data:`GUARDED_SIGNALS` and the signal mask are put back as
    they were (a module that ignores or blocks SIGTERM would make the run impossible to
    stop before the supervisor's grace ends). A module that
    calls ``sys.exit`` while it loads, or does not load within
    :data:`~truestep.cases.plugins.IMPORT_S` seconds, is an :class:`UnknownEngine` that
    says so."""
    from truestep.cases.plugins import IMPORT_S, ImportEndedProcess, import_within
    from truestep.runtime.time_limit import TimeLimitExceeded

    cwd = os.getcwd()
    handlers = {s: signal.getsignal(s) for s in GUARDED_SIGNALS}
    main = threading.current_thread() is threading.main_thread()
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, []) if main else None
    try:
        with contextlib.redirect_stdout(sys.stderr):
            return import_within(module, f"importing {module}")
    except SystemExit as err:
        raise UnknownEngine(f"engine {engine!r}: importing {module} called sys.exit({err.code!r})") from None
    except ImportEndedProcess as err:
        raise UnknownEngine(f"engine {engine!r}: {err}") from None
    except TimeLimitExceeded:
        raise UnknownEngine(
            f"engine {engine!r}: importing {module} gave no answer within {IMPORT_S:g} s"
        ) from None
    finally:
        with contextlib.suppress(OSError):
            os.chdir(cwd)
        if main:
            for s, h in handlers.items():
                if h is not None and signal.getsignal(s) is not h:
                    signal.signal(s, h)
        if mask is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _load_class(engine: str, target: str) -> type:
    module, _, cls = target.partition(":")
    try:
        mod = _import_guarded(engine, module)
    except ModuleNotFoundError as err:
        missing = err.name or module
        if missing == module or module.startswith(missing + "."):
            raise UnknownEngine(f"engine {engine!r}: module {module!r} is not importable") from None
        raise EngineNotInstalled(engine, missing, pip_line(engine)) from None
    try:
        return getattr(mod, cls)
    except AttributeError:
        raise UnknownEngine(f"engine {engine!r}: {module} has no attribute {cls!r}") from None


def adapter_class(name: str) -> type:
    """The adapter class of engine ``name`` (registered, or ``module:Class``), imported."""
    if ":" in name:
        name = resolve_engine(name)
    targets = registered()
    if name not in targets:
        raise UnknownEngine(f"unknown engine {name!r}; known: {', '.join(targets)}")
    return _load_class(name, targets[name])


def get_adapter(name: str) -> Adapter:
    """The adapter of engine ``name`` (a registered name or ``module:Class``).

    truestep's own adapters are made here. An adapter of another package is plugin code:
    in truestep's process this is a :class:`~truestep.adapters.plugin_view.PluginView`, the
    data of one made and read in a forked process (once per class), whose methods are
    called in forked processes; in a process truestep forked to run it (an isolated
    child) it is the adapter itself.

    Raises :class:`UnknownEngine` for a name nothing registers, and for an adapter whose
    construction raises, ends or hangs its process (the error is one line naming it), and
    :class:`EngineNotInstalled` when the engine's library is missing.
    """
    from truestep.runtime.isolation import in_isolated_child

    cls = adapter_class(name)
    if cls.__module__.split(".")[0] != "truestep" and not in_isolated_child():
        adapter: Any = _VIEWS.get(cls) or _view(name, cls)
    else:
        try:
            adapter = cls()
        except (Exception, SystemExit) as err:
            raise UnknownEngine(
                f"engine {name!r}: its adapter {cls.__module__}.{cls.__qualname__} could not be made: "
                f"{type(err).__name__}: {str(err)[:200]}"
            ) from None
    _check_methods(name, adapter)
    return adapter


_VIEWS: dict[type, Any] = {}
"""The view of each adapter class of another package, made once (:func:`_view`)."""


def _view(name: str, cls: type) -> Any:
    """Make an adapter of another package, and read its public attributes, in a forked
    process (:func:`~truestep.adapters.plugin_view.probe`), and hold what came back as data
    (:class:`~truestep.adapters.plugin_view.PluginView`). One whose ``__init__``, or a
    property read, ends, interrupts or hangs that process, or whose ``__init__`` raises, is
    an :class:`UnknownEngine` saying so, and truestep's process goes on."""
    from truestep.adapters.plugin_view import RAISED, PluginView, probe
    from truestep.cases.plugins import IMPORT_S
    from truestep.runtime.isolation import how_it_ended, run_isolated

    what = f"its adapter {cls.__module__}.{cls.__qualname__}"
    out = run_isolated(probe, (cls,), IMPORT_S)
    if out.status == "timeout":
        raise UnknownEngine(f"engine {name!r}: making {what} gave no answer within {IMPORT_S:g} s")
    if out.status != "ok":
        raise UnknownEngine(
            f"engine {name!r}: making {what} ended the process it was first tried in "
            f"({how_it_ended(out.message)})"
        )
    if isinstance(out.value, str):
        raise UnknownEngine(f"engine {name!r}: {what} {out.value}")
    for attribute in ("name", "methods", "adaptive_methods"):
        kind, detail = out.value.get(attribute, (None, None))
        if kind == RAISED:
            raise UnknownEngine(f"engine {name!r}: reading {what}'s {attribute} {detail}")
    _VIEWS[cls] = view = PluginView(name, cls, out.value, ask=plugin_answer, failed=PluginFailed)
    return view


def _check_methods(name: str, adapter: Any) -> None:
    """An adapter's ``methods`` are distinct non-empty strings and its ``adaptive_methods``
    some of them (a method listed twice would make two rows of one key, which no table
    reader takes): else :class:`UnknownEngine`, naming what is wrong."""
    methods = getattr(adapter, "methods", None)
    if not isinstance(methods, (tuple, list)) or not all(isinstance(m, str) and m for m in methods):
        raise UnknownEngine(
            f"engine {name!r}: its adapter's methods must be a tuple of names, got {methods!r:.100}"
        )
    twice = sorted({m for m in methods if methods.count(m) > 1})
    if twice:
        raise UnknownEngine(f"engine {name!r}: its adapter lists the method {twice[0]!r} twice in methods")
    adaptive = getattr(adapter, "adaptive_methods", ())
    if not isinstance(adaptive, (tuple, list, set, frozenset)) or any(m not in methods for m in adaptive):
        raise UnknownEngine(
            f"engine {name!r}: its adapter's adaptive_methods must be some of its methods, "
            f"got {adaptive!r:.100}"
        )


ANSWER_ENV = "TRUESTEP_ANSWER_S"
"""The environment variable that sets :data:`ANSWER_S` (seconds, positive)."""
ANSWER_S = guard_seconds(ANSWER_ENV, 300.0)
"""Seconds within which an adapter must answer a question truestep asks it (``missing``,
``duplicate``, ``skip``, ``same_steps``: each reads a scene and answers at once): a guard
against a question that never returns (a licence server that never answers), not a
bound on its cost, so that no row's verdict depends on how fast the machine is. 300
unless :data:`ANSWER_ENV` says (a CI that would rather fail a hung plugin sooner). A
question that hangs is asked once: the engine's later questions of that name fail at
once (:data:`_HUNG`)."""
_HUNG: dict[tuple[str, str], float] = {}
"""The questions (engine, call) that gave no answer within their limit in this process,
with the limit: asked again, with other arguments, they fail at once, saying so, instead
of holding the run up for another limit each."""
PREPARE_ALL_S = 1800.0
"""Seconds an adapter's ``prepare_all`` has to compile what a run needs (a cold cache
compiles for minutes)."""
PREPARE_S = 600.0
"""Seconds an adapter's ``prepare(case, method)`` has to compile or load what one scene and
method need (a cold cache compiles a scene's kernels first)."""


def plugin_answer(
    engine: str,
    what: str,
    fn: Callable[..., Any],
    *args: Any,
    limit_s: float | None = None,
    apart: bool | Literal["only"] = True,
    **kwargs: Any,
) -> Any:
    """``fn(*args, **kwargs)``, a call truestep makes to an adapter (``missing``,
    ``duplicate``, ``skip``, ``same_steps``, ``prepare``, ``prepare_all``): an exception it
    raises (``SystemExit`` too), or a call still running after ``limit_s`` seconds (default
    :data:`ANSWER_S`), becomes :class:`PluginFailed`, whose text names the engine and the
    call ``what``.

    A question (``apart``, the default) to an adapter of another package than truestep is
    asked in a forked process (:func:`truestep.runtime.isolation.run_isolated`), once per
    engine, call and arguments: plugin code that ends or crashes its process is then a
    :class:`PluginFailed` saying how ("ended the process it was asked in (exit status 0)"),
    and truestep's process goes on; its answer comes back as data. ``apart="only"`` (a
    ``prepare``, whose answer is nothing): a plugin's call is made in a forked process
    only, never in truestep's own, so that plugin code cannot end truestep's process on a
    later call either; what it leaves on disk (a compiled cache) is there for the runs, and
    what it leaves in memory dies with that process (the runs prepare it in their own
    processes, outside their timed runs). truestep's own adapters' ``prepare`` runs here,
    where the runs forked later inherit its work. ``apart=False`` and truestep's own
    adapters: called here, where the limit
    interrupts Python code and numpy between its C loops
    (:func:`truestep.runtime.time_limit.time_limit`), not compiled code that never returns
    to Python."""
    from truestep.runtime.time_limit import TimeLimitExceeded, time_limit

    limit_s = ANSWER_S if limit_s is None else limit_s
    hung = _HUNG.get((engine, what))
    if hung is not None:
        raise PluginFailed(f"{engine}: {what} not asked again: it gave no answer within {hung:g} s before")
    if apart and not _own_code(engine):
        return _answer_apart(engine, what, fn, args, kwargs, limit_s, keep=apart != "only")
    try:
        with time_limit(limit_s, f"{engine}: {what}"):
            return fn(*args, **kwargs)
    except TimeLimitExceeded:
        raise _hung(engine, what, limit_s) from None
    except (Exception, SystemExit) as err:
        raise PluginFailed(f"{engine}: {what} raised {type(err).__name__}: {str(err)[:300]}") from None


def _hung(engine: str, what: str, limit_s: float) -> PluginFailed:
    """The failure of a call that gave no answer within ``limit_s`` s, kept in
    :data:`_HUNG` so that the engine's next call of that name is not made."""
    _HUNG[(engine, what)] = limit_s
    return PluginFailed(f"{engine}: {what} gave no answer within {limit_s:g} s")


def _lived(fn: Callable[..., Any], kwargs: dict, *args: Any) -> None:
    """``fn(*args, **kwargs)``, its answer dropped (in a forked process: only whether the
    call lived through matters)."""
    fn(*args, **kwargs)


_ANSWERS: dict[tuple, tuple[tuple, Any]] = {}
"""Answers of plugin adapters asked apart, by engine, call and its arguments (a string by
value, anything else by identity: the arguments are kept beside the answer)."""


def _own_code(engine: str) -> bool:
    """Whether engine ``engine``'s adapter is truestep's own code (a built-in engine)."""
    try:
        return adapter_class(engine).__module__.split(".")[0] == "truestep"
    except Exception:
        return False


def _answer_apart(
    engine: str,
    what: str,
    fn: Callable[..., Any],
    args: tuple,
    kwargs: dict,
    limit_s: float,
    *,
    keep: bool = True,
) -> Any:
    """:func:`plugin_answer` of a plugin's call, made in a forked process (memoized);
    ``keep=False``: only whether it lives through it (its answer is not sent back)."""
    from truestep.runtime.isolation import how_it_ended, run_isolated

    key = (engine, what, fn, *(a if isinstance(a, str) else id(a) for a in args), *sorted(kwargs.items()))
    if key in _ANSWERS:
        return _ANSWERS[key][1]
    call = functools.partial(fn, **kwargs) if keep else functools.partial(_lived, fn, kwargs)
    out = run_isolated(call, args, limit_s)
    if out.status == "timeout":
        raise _hung(engine, what, limit_s)
    if out.status != "ok":
        ended = "exit code" in out.message and "died" in out.message
        said = (
            f"ended the process it was asked in ({how_it_ended(out.message)})"
            if ended
            else f"raised {out.message[:300]}"
        )
        raise PluginFailed(f"{engine}: {what} {said}")
    _ANSWERS[key] = (args, out.value)
    return out.value


class PluginFailed(Exception):
    """An adapter's answer to a question truestep asked it in its own process raised: the
    rows that needed the answer are ``crashed`` with this text."""


def resolve_engine(spec: str, say: Callable[[str], None] | None = None) -> str:
    """The engine name for ``spec``: a registered name, or ``module:Class`` of an adapter
    (then registered in this process, and the processes it forks, under the adapter's
    ``name``). A class whose ``name`` another registration holds replaces it in this
    process (a patched copy of an engine under test), and ``say`` is told which."""
    if ":" not in spec:
        if spec not in registered():
            raise UnknownEngine(f"unknown engine {spec!r}; known: {', '.join(registered())}")
        return spec
    cls = _load_class(spec, spec)
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name:
        raise UnknownEngine(f"{spec}: an adapter needs a class attribute `name` (a string)")
    known = registered().get(name)
    if known is not None and known != spec and say is not None:
        say(f"engine {name}: {spec} replaces the registered {known} in this run")
    _RESOLVED[name] = spec
    return name


def engine_status(name: str) -> str:
    """``installed``, or why engine ``name`` cannot run here (one line, with the pip line)."""
    try:
        _load_class(name, registered()[name])
    except EngineNotInstalled as err:
        return f"not installed: {err.pip}"
    except Exception as err:  # an adapter module that fails to import is reported, not raised
        return f"unusable: {type(err).__name__}: {err}"
    return "installed"


def available_engines() -> list[str]:
    """Registered engines whose libraries are installed, built-in ones first."""
    return [n for n in registered() if engine_status(n) == "installed"]


__all__ = [
    "BUILTIN",
    "ENTRY_POINT_GROUP",
    "Adapter",
    "EngineNotInstalled",
    "FixedStepAdapter",
    "PluginFailed",
    "Recording",
    "Trajectory",
    "UnknownEngine",
    "adapter_class",
    "available_engines",
    "engine_status",
    "get_adapter",
    "pip_line",
    "plugin_answer",
    "registered",
    "resolve_engine",
]
