"""What installed packages add to the scene library, found by entry point.

Three groups; code comes only from installed packages, never from a case file:

- ``truestep.cases``: ``name = "package"`` or ``"module:attr"``, a directory of case files
  (a package's own directory, or an attribute that is a path, or a callable returning
  one); truestep registers its own ``cases/`` this way;
- ``truestep.exact``: ``name = "module:function"``, an exact solution
  ``fn(case, t) -> Exact`` that ``[reference] exact = "name"`` selects
  (:mod:`truestep.cases.exact` says what it returns and looks it up);
- ``truestep.systems``: ``name = "module:Class"``, a
  :class:`~truestep.reference_impl.system.System` subclass constructed as
  ``Class(y0, **params)`` that ``[ode] system = "name"`` selects.
"""

from __future__ import annotations

import functools
import importlib
import signal
import sys
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from types import ModuleType
from typing import Any

from truestep.reference_impl import odes
from truestep.reference_impl.system import System
from truestep.runtime.time_limit import guard_seconds

CASES_GROUP, EXACT_GROUP, SYSTEMS_GROUP = "truestep.cases", "truestep.exact", "truestep.systems"

CASE_DIR = Path(__file__).resolve().parent
"""truestep's own case library: the directory of this package."""

BUILTIN_SYSTEMS: dict[str, type[System]] = {
    "circle-field": odes.CircleField,
    "kepler": odes.KeplerProblem,
    "arenstorf": odes.Arenstorf,
}
"""The lecture's ODE systems: ``[ode] system`` name -> class."""


IMPORT_ENV = "TRUESTEP_IMPORT_S"
"""The environment variable that sets :data:`IMPORT_S` (seconds, positive)."""
IMPORT_S = guard_seconds(IMPORT_ENV, 300.0)
"""Seconds an installed package's module has to import, a plugin's adapter to be made and
read (:func:`truestep.adapters.get_adapter`), and a case library's callable to name its
directory (code truestep did not write: a licence check or a network disk that never
answers ends as an error naming the entry, not as a run that never starts). 300 unless
:data:`IMPORT_ENV` says (a CI that would rather fail a hung plugin sooner)."""


class PluginError(ValueError):
    """An entry point that cannot be used; ``str()`` names the group, the entry and why."""


class ImportEndedProcess(Exception):
    """A module of another package whose import, tried first in a forked process, ended
    that process (``os._exit``, a signal, a crash) or interrupted it: imported here, it
    would have ended truestep's. ``str()`` says which."""


def import_within(module: str, what: str) -> ModuleType:
    """``importlib.import_module(module)`` within :data:`IMPORT_S` seconds (a
    :class:`~truestep.runtime.time_limit.TimeLimitExceeded` past it, naming ``what``).

    A module of another package, not imported yet, is first imported in a forked process
    (:func:`_tried_apart`): one whose import ends its process is an
    :class:`ImportEndedProcess`, and truestep's process goes on. Its import's side effects
    (a file it writes, a line it prints) therefore happen twice; truestep's own modules
    are imported once."""
    from truestep.runtime.time_limit import time_limit

    if module not in sys.modules and module.partition(".")[0] != "truestep":
        _tried_apart(module, what)
    with time_limit(IMPORT_S, what):
        return importlib.import_module(module)


def _tried_apart(module: str, what: str) -> None:
    """Import ``module`` in a forked process first (within :data:`IMPORT_S` seconds):
    :class:`ImportEndedProcess` where that ends or interrupts the process. An import that
    raises is left to the import here, which raises the same, as its callers say."""
    from truestep.runtime.isolation import how_it_ended, run_isolated
    from truestep.runtime.time_limit import TimeLimitExceeded

    out = run_isolated(_import_here, (module,), IMPORT_S)
    if out.status == "timeout":
        raise TimeLimitExceeded(what)
    if out.status != "ok":
        ended = how_it_ended(out.message)
        raise ImportEndedProcess(f"{what} ended the process it was first tried in ({ended})")
    if out.value != "ok":
        raise ImportEndedProcess(f"{what} {out.value}")


def _import_here(module: str) -> str:
    """In a forked process: import ``module``; ``"ok"`` when it loads or raises (the
    caller's own import says why), else what it did to the process."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        importlib.import_module(module)
    except KeyboardInterrupt:
        return "interrupted its own process (SIGINT)"
    except BaseException:  # the caller's own import raises the same and says so
        pass
    return "ok"


@functools.cache
def _group(group: str) -> dict[str, str]:
    return {ep.name: ep.value for ep in metadata.entry_points(group=group)}


def _load(group: str, name: str, value: str) -> Any:
    from truestep.runtime.time_limit import TimeLimitExceeded

    module, _, attr = value.partition(":")
    try:
        obj: Any = import_within(module, f"importing {module}")
        for part in filter(None, attr.split(".")):
            obj = getattr(obj, part)
    except TimeLimitExceeded:
        raise PluginError(
            f"entry point {group} {name} = {value!r}: importing {module} gave no answer within {IMPORT_S:g} s"
        ) from None
    except ImportEndedProcess as err:
        raise PluginError(f"entry point {group} {name} = {value!r}: {err}") from None
    except (Exception, SystemExit) as err:  # a broken plugin is a clear error, not a traceback
        raise PluginError(f"entry point {group} {name} = {value!r}: {type(err).__name__}: {err}") from None
    return obj


def _directory_of(name: str, value: str, obj: Any) -> Any:
    """The directory a case library's entry point names: a module's own, or what the
    attribute is or (a callable) returns, within :data:`IMPORT_S` seconds."""
    from truestep.runtime.time_limit import TimeLimitExceeded, time_limit

    if isinstance(obj, ModuleType):
        return Path(obj.__file__).parent if obj.__file__ else None
    if not callable(obj):
        return obj
    try:
        with time_limit(IMPORT_S, f"{value}()"):
            return obj()
    except TimeLimitExceeded:
        raise PluginError(
            f"entry point {CASES_GROUP} {name} = {value!r}: calling it gave no answer within {IMPORT_S:g} s"
        ) from None
    except (Exception, SystemExit) as err:
        raise PluginError(
            f"entry point {CASES_GROUP} {name} = {value!r}: calling it raised {type(err).__name__}: {err}"
        ) from None


def case_directories() -> list[tuple[str, Path]]:
    """(entry-point name, directory) of every installed case library, truestep's first."""
    dirs = [("truestep", CASE_DIR)]
    for name, value in sorted(_group(CASES_GROUP).items()):
        where = _directory_of(name, value, _load(CASES_GROUP, name, value))
        if not isinstance(where, str | Path) or not Path(where).is_dir():
            raise PluginError(f"entry point {CASES_GROUP} {name} = {value!r}: {where!r} is not a directory")
        if not any(Path(where).glob("*.toml")):
            package = value.partition(":")[0].split(".")[0]
            raise PluginError(
                f"entry point {CASES_GROUP} {name} = {value!r}: {where} holds no case files (*.toml); "
                "an install that is not editable ships them only when the package declares them, "
                f'e.g. [tool.setuptools.package-data] {package} = ["*.toml"] in its pyproject.toml'
            )
        if Path(where).resolve() != CASE_DIR:
            dirs.append((name, Path(where)))
    return dirs


def find_entry(group: str, name: str, builtin: dict, fits: Callable[[Any], bool], kind: str) -> Any:
    """``builtin[name]``, else the object the entry point ``name`` of ``group`` names
    (checked by ``fits``), else ``None``."""
    if name in builtin:
        return builtin[name]
    value = _group(group).get(name)
    if value is None:
        return None
    obj = _load(group, name, value)
    if not fits(obj):
        raise PluginError(f"entry point {group} {name} = {value!r}: not {kind}")
    return obj


def names_with_entries(group: str, builtin: dict) -> list[str]:
    return [*builtin, *sorted(set(_group(group)) - set(builtin))]


def ode_system(name: str) -> type[System] | None:
    """The ODE system class registered as ``name`` (the lecture's or installed), or ``None``."""
    return find_entry(
        SYSTEMS_GROUP,
        name,
        BUILTIN_SYSTEMS,
        lambda c: isinstance(c, type) and issubclass(c, System),
        "a System subclass",
    )


def system_names() -> list[str]:
    """Every ODE system name: the lecture's, then installed ones."""
    return names_with_entries(SYSTEMS_GROUP, BUILTIN_SYSTEMS)
