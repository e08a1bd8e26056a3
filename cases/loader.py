"""Load and validate case files (TOML) into :class:`~truestep.cases.case.Case` objects.

Cases are found by name in the case library (truestep's ``cases/`` and the directories
installed packages register, :func:`~truestep.cases.plugins.case_directories`), or by
path: :func:`case_files` takes names, globs, files and directories.
"""

from __future__ import annotations

import fnmatch
import os
import re
import tomllib
import warnings
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from truestep.cases import plugins
from truestep.cases.case import FAMILIES, Case, Gate, OdeSpec, Scene, StabilitySpec, ode_states
from truestep.cases.errors import CaseError, SelectionError
from truestep.cases.exact import exact_named, exact_names
from truestep.cases.fields import Fields, short
from truestep.cases.gate_kinds import GATE_KINDS, GATE_NUMBERS, GateKind
from truestep.cases.limits import (
    DEFAULT,
    MIN_STEP_S,
    Budget,
    Limits,
    check_ceilings,
    override,
    read_limits,
)
from truestep.cases.property_names import PROPERTY_KINDS
from truestep.cases.scene import read_scene
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.system import SecondOrderSystem
from truestep.runtime.files import FileRefused, read_regular
from truestep.runtime.time_limit import TimeLimitExceeded, guard_seconds, time_limit
from truestep.runtime.visible import visible

CASE_DIR = plugins.CASE_DIR
"""truestep's own case library (this folder)."""

ODE_DIMENSIONS = {"circle-field": 2, "kepler": 4, "arenstorf": 4}
"""State dimension of the lecture's ODE systems (installed systems are checked by
constructing them)."""
MAX_FILE_BYTES = 16 * 2**20
"""The largest case or gates file read (16 MiB): a scene bigger than that is built from
blocks, meshes and emitters, not listed particle by particle."""
MAX_NESTING = 32
"""The deepest nesting of tables and arrays a case file may have."""
MAX_SWEEP = 50
"""The most steps (or tolerances) one sweep lists: each is a row per engine and method."""
EXACT_CHECK_ENV = "TRUESTEP_EXACT_CHECK_S"
"""The environment variable that sets :data:`EXACT_CHECK_S` (seconds, positive)."""
EXACT_CHECK_S = guard_seconds(EXACT_CHECK_ENV, 300.0)
"""Seconds within which checking that an exact solution fits its case must end: a guard
against a check that never returns (a solution waiting on a network disk), not a bound on
its cost. The library's own checks (the costliest: the million-particle rain's) end far
within it, so a case is refused for its time only when its check hangs, on any machine,
not for being slow on a slow one. 300 unless :data:`EXACT_CHECK_ENV` says."""
REFERENCE_KEYS = {"exact", "error", "scale", "conservative", "escape_energy"}
PROPERTY_PARAMS = {"v_scale": "nonnegative", "bounces": "count"}
"""``[reference]`` parameters that properties read (:mod:`truestep.measures.properties`)."""


def library() -> dict[str, Path]:
    """Every case of the library by name: truestep's, then installed packages' (a name
    that two libraries both define raises :class:`SelectionError`)."""
    found: dict[str, Path] = {}
    for source, directory in plugins.case_directories():
        for path in sorted(directory.glob("*.toml")):
            if path.stem in found:
                raise SelectionError(
                    f"case {path.stem!r} is defined twice: {found[path.stem]} "
                    f"and {path} (entry point {source!r})"
                )
            found[path.stem] = path
    return found


def _items(selection: str | Iterable[str]) -> list[str]:
    items = selection.split(",") if isinstance(selection, str) else list(selection)
    return [str(i).strip() for i in items if str(i).strip()] or ["*"]


def _path_of(item: str) -> Path:
    """``item`` as a path, ``~`` and ``~user`` expanded (:class:`SelectionError` for a user
    the system does not know)."""
    try:
        return Path(item).expanduser()
    except RuntimeError:
        raise SelectionError(f"--cases: {visible(item)!r}: no such user to expand ~ for") from None


def _is_dir(item: str, path: Path) -> bool:
    """Whether ``path`` is a directory; a name the system cannot even look up (too long,
    say) is :class:`SelectionError`."""
    try:
        return path.is_dir()
    except OSError as err:
        raise SelectionError(f"--cases: {visible(item)[:80]!r}: {err.strerror or err}") from None


def case_files(selection: str | Iterable[str] = "*") -> list[Path]:
    """The case files a selection names, in the order named, each once.

    ``selection`` is a comma-separated string (or a list) of items, each a case name or
    shell glob matched against the library (:func:`library`), a case file, or a
    directory (its ``*.toml`` files). Every item must match at least one case, or
    :class:`SelectionError` names it.
    """
    lib: dict[str, Path] | None = None
    out: dict[Path, Path] = {}
    for item in _items(selection):
        path = _path_of(item)
        if _is_dir(item, path):
            files = sorted(path.glob("*.toml"))
            if not files:
                raise SelectionError(f"--cases: {item!r} is a directory with no *.toml case file")
        elif item.endswith(".toml") or os.path.lexists(path):
            if not os.path.lexists(path):
                raise SelectionError(f"--cases: {item!r}: no such case file")
            files = [path]  # anything but a regular file is refused when it is read
        else:
            lib = library() if lib is None else lib
            files = [p for name, p in lib.items() if fnmatch.fnmatchcase(name, item)]
            if not files:
                raise SelectionError(
                    f"--cases: no case matches {item!r} (known: "
                    f"{', '.join(lib) or 'none'}; a file or directory also works)"
                )
        for f in files:
            out.setdefault(f.resolve(), f)
    return list(out.values())


def load_cases(
    selection: str | Iterable[str] = "*",
    *,
    limits: dict[str, float] | None = None,
    trust_limits: bool = False,
    engines: Iterable[str] | None = None,
) -> list[Case]:
    """Load every case a selection names (:func:`case_files`); raises :class:`CaseError`
    on the first bad file and :class:`SelectionError` when an item matches nothing or
    two cases share a name. ``limits``, ``trust_limits`` and ``engines`` as
    :func:`load_case`."""
    cases = [
        load_case(p, limits=limits, trust_limits=trust_limits, engines=engines) for p in case_files(selection)
    ]
    seen: dict[str, str] = {}
    for c in cases:
        if c.name in seen:
            raise SelectionError(f"two cases are named {c.name!r}: {seen[c.name]} and {c.file}")
        seen[c.name] = c.file
    return cases


def load_case(
    path: str | Path,
    *,
    limits: dict[str, float] | None = None,
    trust_limits: bool = False,
    engines: Iterable[str] | None = None,
) -> Case:
    """Load one case file, validating every field, its cost and its gates.

    The cost limits are :data:`truestep.cases.limits.DEFAULT`, raised or lowered by the
    file's ``[limits]`` table (at most to :data:`~truestep.cases.limits.CEILING`), then by
    ``limits`` (``{"steps": 1e8, ...}``, the command line's ``--limit``; beyond the
    ceiling only with ``trust_limits``). The gates are checked as ``truestep run`` and
    ``truestep gate`` check them: known kinds and numbers, steps the sweep runs, property
    gates naming the case's properties, and engines among ``engines`` (default: every
    registered engine) or ``*``. Raises :class:`CaseError` for anything that cannot be
    used.
    """
    path = Path(path)
    try:
        check_ceilings(limits or {}, trusted=trust_limits, where="limits:")
    except ValueError as err:
        raise CaseError(str(path), "<limits>", str(err)) from None
    try:
        return _load_case(path, limits or {}, engines)
    except (MemoryError, RecursionError, OverflowError) as err:
        raise CaseError(
            str(path), "<file>", f"cannot be loaded: {type(err).__name__}: {str(err)[:80]}"
        ) from None


def _load_case(path: Path, limit_values: dict[str, float], engines: Iterable[str] | None) -> Case:
    file = str(path)
    f = _read_toml(path)
    limits = override(read_limits(f, DEFAULT), limit_values)
    name = path.stem
    if not re.fullmatch(r"[a-z0-9]+(-[a-z0-9]+)*", name) or len(name) > 80:
        raise CaseError(
            file,
            "<name>",
            "case names (the file name) are lower-case ASCII words "
            "and digits joined by dashes, at most 80 characters",
        )

    kind = f.string("kind", choices={"ode", "particles"})
    run = f.sub("run")
    duration = run.number("duration", positive=True)
    if duration < MIN_STEP_S:
        raise run.error(
            "duration", f"{duration:g} s is shorter than the smallest step a case may name, {MIN_STEP_S:g} s"
        )
    dts, quick_dts = _read_steps(run, duration)
    for where, values in (("dt", dts), ("quick_dt", quick_dts)):
        if min(values) < MIN_STEP_S:
            raise run.error(
                where, f"a step of {min(values):g} s is below the smallest a case may name, {MIN_STEP_S:g} s"
            )
    tolerances = run.numbers("tolerances", [1e-4, 1e-6, 1e-8], positive=True, max_length=MAX_SWEEP)
    quick_tolerances = run.numbers("quick_tolerances", tolerances[:2], positive=True, max_length=MAX_SWEEP)
    for where, values in (("dt", dts), ("quick_dt", quick_dts)):
        if max(values) > duration:
            raise run.error(where, f"a step of {max(values):g} s exceeds the duration {duration:g} s")
    tolerances_ok = all(1e-14 <= t < 1 for t in tolerances + quick_tolerances)
    if not tolerances_ok:
        raise run.error(
            "tolerances",
            "every tolerance must lie in 1e-14..1 (below 1e-14 an "
            f"adaptive step cannot meet it in float64), got {short(tolerances)}",
        )
    max_records = run.integer("max_records", 2000, minimum=2, maximum=limits.records)
    timeout_s = run.number("timeout", 120.0, at_least=1.0, at_most=limits.timeout_s)
    in_quick = run.boolean("quick", True)
    skip = []
    for s in run.subs("skip"):
        skip.append((s.string("engine"), s.string("method", "*"), s.text("reason", max_length=500)))
        s.done()
    run.done()
    steps = duration / min(dts + quick_dts)
    if steps > limits.steps:
        raise run.error(
            "dt",
            f"duration / dt = {steps:.3g} steps, over the limit of "
            f"{limits.steps:.3g} (raise it with [limits] steps or --limit steps=N)",
        )

    scene: Scene
    model = None
    if kind == "ode":
        scene = _read_ode(f.sub("ode"), limits)
        if f.has("scene"):
            raise f.error("scene", 'an ode case has no scene (kind = "ode")')
    else:
        scene = model = read_scene(f.sub("scene"), Budget(limits))
        if model.n == 0:
            raise f.error("scene", "the scene has no particles")
    _check_cost(f, limits, steps, max_records, model)
    _check_emitters(f, limits, duration, model)

    ref = f.sub("reference", {})
    exact = ref.string("exact", None)
    error_norm = ref.string("error", "max", choices={"final", "max"})
    error_scale = ref.number("scale", 1.0, positive=True)
    conservative = ref.boolean("conservative", False)
    escape_energy = ref.number("escape_energy", None)
    fn = _exact_fn(ref, exact) if exact is not None else None
    if exact is not None and fn is None:
        raise ref.error("exact", f"no exact solution named {short(exact)}; known: {', '.join(exact_names())}")
    exact_params = _exact_params(ref, fn)
    _check_reference_cost(ref, limits, duration, exact, exact_params, model)
    ref.done()

    stability = _read_stability(f, limits)

    case = Case(
        name=name,
        file=file,
        title=f.text("title", name, max_length=200),
        description=f.text("description", ""),
        scene=scene,
        duration=duration,
        dts=sorted(dts, reverse=True),
        quick_dts=sorted(quick_dts, reverse=True),
        tolerances=sorted(tolerances, reverse=True),
        quick_tolerances=sorted(quick_tolerances, reverse=True),
        exact=exact,
        exact_params=exact_params,
        error_norm=error_norm,
        error_scale=error_scale,
        conservative=conservative,
        escape_energy=escape_energy,
        max_records=max_records,
        gates=_read_gates(f),
        stability=stability,
        properties=_read_properties(f, kind),
        skip=skip,
        hard=f.text("hard", None, max_length=2000),
        tags=f.strings("tags", []),
        family=f.string("family", "other", choices={*FAMILIES, "other"}),
        timeout_s=timeout_s,
        in_quick=in_quick,
    )
    f.raw("limits", None)
    f.done()
    _check_gate_steps(f, case)
    check_case_gates(case, set(_engine_names() if engines is None else engines))
    start = _check_exact(case) if exact is not None else None
    _warn_unmeasured_energy_drift(case, start)
    return case


def _warn_unmeasured_energy_drift(case: Case, start: object) -> None:
    """A ``FutureWarning`` for each ``energy_drift`` gate of a case that never measures its
    energy drift: not conservative, and no exact energy curve to measure it against (no
    exact solution, or one that gives none: its registration says so, or its value at
    ``t = 0``, ``start``, has no energy). Such a gate fails every run ("measured
    nothing"); a later release refuses it when the case loads, and this warning comes
    first, so that a case file that loaded before still loads."""
    gates = [g for g in case.gates if GATE_KINDS[g.kind].needs_energy]
    if not gates or case.conservative:
        return
    if case.exact is not None:
        declared = getattr(exact_named(case.exact), "energy", None)
        gives = declared if declared is not None else (None if start is None else start_energy(start))
        if gives is None or gives:
            return
    for g in gates:
        warnings.warn(
            f"{case.file}: {g.where}: an energy_drift gate on a case that never measures its energy "
            "drift (its energy is not conserved and no exact solution gives the energy curve): it "
            "fails every run; a later release refuses it when the case loads. Gate the error, or a "
            "property, instead.",
            FutureWarning,
            stacklevel=3,
        )


def start_energy(start: object) -> bool:
    """Whether an exact solution's value (:class:`~truestep.cases.exact.Exact`) carries the
    energy along the motion."""
    return getattr(start, "energy", None) is not None


def _engine_names() -> list[str]:
    """Every engine registered in this process (gates may name these or ``*``)."""
    from truestep.adapters import registered

    return list(registered())


def check_case_gates(case: Case, engines: set[str]) -> None:
    """A case's gates must name engines of ``engines`` (or ``*``), and a property gate a
    property of the case: :class:`CaseError` naming the gate's field otherwise."""
    for g in case.gates:
        if GATE_KINDS[g.kind].names_property and g.params["name"] not in case.properties:
            raise CaseError(
                case.file, f"{g.where}.name", f"{short(g.params['name'])} is not in this case's properties"
            )
        if g.engine != "*" and g.engine not in engines:
            raise CaseError(case.file, f"{g.where}.engine", f"unknown engine {short(g.engine)}")


def _read_properties(f: Fields, kind: str) -> list[str]:
    """``properties``: names of properties (:mod:`truestep.cases.property_names`) that read
    this kind of case."""
    names = f.strings("properties", [], choices=set(PROPERTY_KINDS))
    for name in names:
        if PROPERTY_KINDS.get(name, kind) != kind:
            raise f.error(
                "properties",
                f"{short(name)} is a property of {PROPERTY_KINDS[name]} cases; this case is kind = {kind!r}",
            )
    return names


def _check_emitters(f: Fields, limits: Limits, duration: float, model) -> None:
    """An emitter's frames count as steps: ``duration / frame_dt`` within the step limit."""
    for i, e in enumerate(model.emitters if model is not None else []):
        frames = duration / e.frame_dt
        if frames > limits.steps:
            raise f.error(
                f"scene.emitters[{i}].frame_dt",
                f"duration / frame_dt = {frames:.3g} "
                f"frames, over the step limit of {limits.steps:.3g} (raise it with "
                "[limits] steps or --limit steps=N)",
            )


def _check_reference_cost(
    ref: Fields, limits: Limits, duration: float, exact: str | None, params: dict[str, object], model
) -> None:
    """A fixed-step reference run is a run too: its step is at least
    :data:`~truestep.cases.limits.MIN_STEP_S`, its steps and work within the limits."""
    dt = params.get("dt")
    if exact != "reference-run" or not isinstance(dt, float | int) or isinstance(dt, bool):
        return
    if dt < MIN_STEP_S:
        raise ref.error("dt", f"a step of {dt:g} s is below the smallest a case may name, {MIN_STEP_S:g} s")
    steps = duration / dt
    if steps > limits.steps:
        raise ref.error(
            "dt",
            f"duration / dt = {steps:.3g} steps, over the limit of "
            f"{limits.steps:.3g} (raise it with [limits] steps or --limit steps=N)",
        )
    n = model.n if model is not None else 1
    springs = (len(model.springs) + len(model.anchors.i)) if model is not None else 0
    if (n + springs) * steps > limits.work:
        raise ref.error(
            "dt",
            f"the reference run does ({n} + {springs}) x {steps:.3g} = "
            f"{(n + springs) * steps:.3g} updates, over the limit of "
            f"{limits.work:.3g} (raise it with [limits] work or --limit work=N)",
        )


def _check_cost(f: Fields, limits: Limits, steps: float, records: int, model) -> None:
    """Refuse a case whose finest run would do or keep more than ``limits`` allow."""
    n = model.n if model is not None else 1
    springs = (len(model.springs) + len(model.anchors.i)) if model is not None else 0
    work = (n + springs) * steps
    if work > limits.work:
        raise f.error(
            "run.dt",
            f"(particles + springs) x steps = ({n} + {springs}) x "
            f"{steps:.3g} = {work:.3g} updates, over the limit of {limits.work:.3g} "
            "(raise it with [limits] work or --limit work=N)",
        )
    memory_mb = records * n * 48 / 2**20
    if memory_mb > limits.memory_mb:
        raise f.error(
            "run.max_records",
            f"{records} records of {n} particles need "
            f"{memory_mb:.4g} MiB, over the limit of {limits.memory_mb:g} MiB "
            "(raise it with [limits] memory_mb or --limit memory_mb=N)",
        )


def _read_stability(f: Fields, limits: Limits) -> StabilitySpec | None:
    """``[stability]``: a bisection on dt over a horizon, within the step limit."""
    if not f.has("stability"):
        return None
    s = f.sub("stability")
    spec = StabilitySpec(
        horizon=s.number("horizon", at_least=MIN_STEP_S),
        dt_lo=s.number("dt_lo", at_least=MIN_STEP_S),
        dt_hi=s.number("dt_hi", positive=True),
        max_runs=s.integer("max_runs", 30, minimum=3, maximum=1000),
        rel_tol=s.number("rel_tol", 1e-3, positive=True, below=1.0),
        quick=s.boolean("quick", False),
        min_steps=s.integer("min_steps", 5000, minimum=10, maximum=limits.steps),
        budget_s=s.number("budget_s", 300.0, positive=True, at_most=limits.timeout_s),
    )
    if spec.dt_lo >= spec.dt_hi:
        raise s.error("dt_hi", f"must exceed dt_lo ({spec.dt_lo:g})")
    if spec.horizon / spec.dt_lo > limits.steps:
        raise s.error(
            "dt_lo",
            f"horizon / dt_lo = {spec.horizon / spec.dt_lo:.3g} steps, over "
            f"the limit of {limits.steps:.3g} (raise it with [limits] steps)",
        )
    s.done()
    return spec


def _exact_params(ref: Fields, fn) -> dict[str, object]:
    """The ``[reference]`` parameters of the exact solution ``fn`` and of the properties.

    An exact solution that declares its parameters (``fn.params``: name -> ``"positive"``,
    ``"nonnegative"``, ``"count"``, ``"string"``) gets each checked and no other; one that
    does not (an installed one) gets plain numbers, strings and booleans, which its own
    check reads.
    """
    declared = dict(getattr(fn, "params", None) or {}) if fn is not None else {}
    declared.update(PROPERTY_PARAMS)
    open_ended = fn is not None and getattr(fn, "params", None) is None
    out: dict[str, object] = {}
    for key in [k for k in ref.table if k not in REFERENCE_KEYS]:
        what = declared.get(key)
        if what is None and not open_ended:
            known = ", ".join(sorted(set(declared) | REFERENCE_KEYS))
            raise ref.error(short(key).strip("'"), f"unknown field (known here: {known})")
        if what in ("positive", "nonnegative"):
            out[key] = ref.number(key, positive=what == "positive", nonnegative=what == "nonnegative")
        elif what == "count":
            out[key] = ref.integer(key, minimum=1, maximum=1000)
        elif what == "string":
            out[key] = ref.string(key)
        else:
            value = ref.raw(key)
            if isinstance(value, float | int) and not isinstance(value, bool):
                value = ref.number(key)
            elif not isinstance(value, str | bool):
                raise ref.error(key, f"expected a number, a string or a boolean, got {short(value)}")
            out[key] = value
    return out


STEP_FIT = 1e-9
"""How close ``duration / dt`` must be to a whole number (relative): a run takes exactly the
step its row is labelled with."""


def _read_steps(run: Fields, duration: float) -> tuple[list[float], list[float]]:
    """The fixed-step sweep of ``[run]``: ``dt`` and ``quick_dt`` (s), each a whole number
    of steps into the duration, or ``steps`` and ``quick_steps`` (step counts, for a
    duration such as a period that no round step divides; dt = duration / steps)."""
    if run.has("steps"):
        for key in ("dt", "quick_dt"):
            if run.has(key):
                raise run.error(key, "give the sweep as dt or as steps, not both")
        counts = run.numbers("steps", positive=True, max_length=MAX_SWEEP)
        quick = run.numbers("quick_steps", counts[:2], positive=True, max_length=MAX_SWEEP)
        for key, values in (("steps", counts), ("quick_steps", quick)):
            if any(v != round(v) or v > 1e15 for v in values):
                raise run.error(key, f"step counts are whole numbers, got {short(values)}")
        return [duration / n for n in counts], [duration / n for n in quick]
    dts = run.numbers("dt", positive=True, max_length=MAX_SWEEP)
    quick_dts = run.numbers("quick_dt", dts[:2], positive=True, max_length=MAX_SWEEP)
    for key, values in (("dt", dts), ("quick_dt", quick_dts)):
        for dt in values:
            n = duration / dt
            if n >= 1 and abs(n - round(n)) > STEP_FIT * n:
                raise run.error(
                    key,
                    f"{dt:g} s does not divide the duration {duration:.10g} s "
                    f"({n:.6g} steps): the run would take steps of "
                    f"{duration / max(round(n), 1):.6g} s; choose a duration of "
                    "whole steps, or give the sweep as `steps`",
                )
    return dts, quick_dts


def _check_gate_steps(f: Fields, case: Case) -> None:
    """A case's gate that reads one step (or tolerance) must name one that its sweep runs.

    A step that only the full sweep runs is fine: a ``--quick`` run leaves such a gate not
    evaluated, saying so (:func:`truestep.ci.gates.check_gate`). Earlier releases loaded
    such case files, and a user's installed case package is loaded on every command."""
    swept = set(case.dts) | set(case.tolerances)
    for g in case.gates:
        if g.dt is not None and not any(abs(g.dt - s) <= 1e-9 * s for s in swept):
            raise CaseError(
                case.file,
                f"{g.where}.dt",
                f"{g.dt:g} is not a step or tolerance of this case's sweep "
                f"({', '.join(f'{s:g}' for s in sorted(swept))})",
            )


def _exact_fn(ref: Fields, name: str):
    try:
        return exact_named(name)
    except plugins.PluginError as err:
        raise ref.error("exact", str(err)) from None


def _read_ode(o: Fields, limits: Limits) -> OdeSpec:
    """``[ode]``: a registered system, its start ``y0`` (at most six numbers per particle
    the limits allow) and its keyword parameters, checked by building the system and
    evaluating its derivative at the start."""
    name = o.string("system")
    try:
        cls = plugins.ode_system(name)
    except plugins.PluginError as err:
        raise o.error("system", str(err)) from None
    if cls is None:
        raise o.error("system", f"no ODE system named {name!r}; known: {', '.join(plugins.system_names())}")
    raw = o.raw("y0")
    if isinstance(raw, list) and len(raw) > 6 * limits.particles:
        raise o.error(
            "y0",
            f"{len(raw)} numbers, over six per particle of the limit of "
            f"{limits.particles:.3g} (raise it with [limits] particles)",
        )
    y0 = o.array("y0", shape=(ODE_DIMENSIONS[name],) if name in ODE_DIMENSIONS else (None,))
    params = {k: o.number(k) for k in o.table if k not in ("system", "y0")}
    o.done()
    try:
        system = cls(y0, **params)
        dy = np.asarray(system.derivative(y0.copy(), 0.0), float)
    except Exception as err:  # the parameters or the start do not fit the system
        raise o.error(
            "system",
            f"{name!r} cannot be built from y0 and "
            f"{sorted(params) or 'no parameters'}: {type(err).__name__}: {err}",
        ) from None
    if dy.shape != y0.shape:
        raise o.error(
            "y0", f"{name!r} returns a derivative of shape {dy.shape} for a start of shape {y0.shape}"
        )
    return OdeSpec(name, y0, params, second_order=isinstance(system, SecondOrderSystem))


def _check_exact(case: Case) -> object:
    """The named exact solution must fit the scene: its own check if it has one, else it
    is evaluated at ``t = 0`` and must return the scene's start in the trajectory layout.
    Returns that value at ``t = 0`` (``None`` where its own check ran instead)."""
    where = "reference.exact"
    fn = exact_named(case.exact) if case.exact is not None else None
    if fn is None:
        raise CaseError(case.file, where, f"no exact solution named {case.exact!r}")
    kind = getattr(fn, "kind", None)
    if kind is not None and kind != case.kind:
        raise CaseError(
            case.file,
            where,
            f"{case.exact!r} is the exact solution of {kind} cases; this case is kind = {case.kind!r}",
        )
    try:
        with time_limit(EXACT_CHECK_S, f"checking {case.exact!r}"):
            check = getattr(fn, "check", None)
            if check is not None:
                check(case)
                return None
            start = fn(case, np.array([0.0]))
    except TimeLimitExceeded:
        raise CaseError(
            case.file,
            where,
            f"checking that {case.exact!r} fits this case did not end within {EXACT_CHECK_S:g} s "
            "(the guard against a check that never returns)",
        ) from None
    except Exception as err:  # it says why it does not fit by raising
        raise CaseError(case.file, where, f"{case.exact!r} does not fit this case: {err}") from None
    if len(getattr(start, "t", [])) == 0:
        return start  # known at some times only, not at the start
    shape: tuple[int, ...]
    match case.scene:
        case OdeSpec() as ode:
            x0, shape, what = ode.y0[None, :], (1, ode.dim), "states"
            legacy = getattr(start, "y", None) is None  # x as (T, 1, dim): deprecated, still read
            x = np.asarray(getattr(start, "x" if legacy else "y", None))
            if legacy and x.ndim == 3 and x.shape[1] == 1:
                x = ode_states(start)
        case ParticleModel() as model:
            x0, shape, what = model.x0[None], (1, model.n, 3), "positions"
            x = np.asarray(getattr(start, "x", None))
    if x.shape != shape:
        raise CaseError(
            case.file, where, f"{case.exact!r} gives {what} of shape {x.shape}; this case's are {shape}"
        )
    if not np.allclose(x, x0, rtol=1e-9, atol=1e-12):
        raise CaseError(
            case.file,
            where,
            f"{case.exact!r} does not start where the case starts "
            f"(largest difference {np.max(np.abs(x - x0)):.3g})",
        )
    return start


def _read_gates(f: Fields) -> list[Gate]:
    gates, ids = [], set()
    for i, sub in enumerate(f.subs("gates")):
        g = read_gate(sub, f"gates[{i}]")
        if g.id is not None and g.id in ids:
            raise sub.error("id", f"another gate of this file has the id {g.id!r}")
        ids.add(g.id)
        gates.append(g)
    return gates


GATE_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,79}")
"""What a gate's ``id`` may be: a short name that reads the same in a URL, a JUnit
report and a shell."""


def read_gate(g: Fields, where: str) -> Gate:
    """One ``[[gates]]`` table (of a case file or a gates file), checked field by field.

    ``engine`` (default ``reference``) and ``method`` may be ``*``: every engine that
    ran, every method of it. ``id`` (optional, letters, digits, ``.``, ``_``, ``-``): the
    gate's own name in every output (else one is made from what it checks, see
    :func:`truestep.ci.gates.gate_id`). Kinds and their numbers:

    - ``order``: ``expect``, ``tol`` (fitted order within ``tol`` of ``expect``);
    - ``error``, ``energy_drift``: ``dt``, ``max``;
    - ``status``: ``dt``, ``expect`` (``ok`` or ``unstable``);
    - ``property``: ``name``, ``dt``, ``min`` and/or ``max``;
    - ``stability-limit``: ``rel_tol`` (within it of the exact limit) and/or ``min``
      (s, the least acceptable limit, for scenes without an exact one);
    - ``restitution``: ``tol`` (``|e_measured - e_set| <= tol`` on every bounce), with
      optional ``dt``, ``e_set``, ``bounce`` filters and ``quantity`` (``e_measured``,
      from velocities, or ``e_apex``, from apex heights);
    - ``no-worse-than``: ``than`` (``engine/method``), ``factor`` (default 1) and
      ``quantity`` (default ``error``), on every ``dt`` both ran (or only ``dt``);
    - ``speedup``: ``dt``, ``over`` (engines), ``min`` (times faster).
    """
    kind = GATE_KINDS[g.string("kind", choices=GATE_KINDS)]
    gate_id = g.string("id", None)
    if gate_id is not None and not GATE_ID.fullmatch(gate_id):
        raise g.error("id", f"expected letters, digits, '.', '_' or '-' (at most 80), got {short(gate_id)}")
    engine = g.string("engine", "reference")
    method = g.string("method")
    dt = g.number("dt", None, positive=True)
    params: dict[str, object] = {}
    if kind.words and kind.fields is not None:
        kind.fields(g, params)
    for key in list(g.table):
        if key in GATE_NUMBERS and key not in params:
            params[key] = g.number(key)
    if kind.fields is not None and not kind.words:
        kind.fields(g, params)
    _require(g, kind, params, dt)
    g.done()
    return Gate(kind.name, engine, method, dt, params, where, file=g.file, id=gate_id)


def _require(g: Fields, kind: GateKind, params: dict, dt: float | None) -> None:
    """What ``kind`` needs of a gate's numbers and step (:mod:`truestep.cases.gate_kinds`)."""
    for key in kind.needs:
        if key not in params:
            raise g.error(key, f"a {kind.name} gate needs {key}")
    if kind.needs_dt and dt is None:
        raise g.error("dt", f"a {kind.name} gate needs the dt (or tolerance) of the row it reads")
    if kind.one_of is not None and not any(key in params for key in kind.one_of[0]):
        raise g.error(kind.one_of[0][0], kind.one_of[1])


def load_gates_file(path: str | Path) -> list[tuple[list[str], Gate]]:
    """The gates of a user's gates file: ``(case patterns, gate)`` pairs.

    A gates file is TOML with ``[[gates]]`` tables like a case file's, each naming the
    cases it applies to by ``cases`` (a name, a shell glob, or a list of them; default
    every case), and optionally a ``[baseline]`` table of tolerances (see
    :func:`load_baseline_tolerances`).
    """
    f = _read_toml(Path(path))
    out = []
    for i, g in enumerate(f.subs("gates")):
        raw = g.raw("cases", "*")
        patterns = [raw] if isinstance(raw, str) else raw
        if (
            not isinstance(patterns, list)
            or not patterns
            or not all(isinstance(p, str) and p.strip() for p in patterns)
        ):
            raise g.error("cases", f"expected a case name, glob, or a list of them, got {raw!r}")
        out.append(([p.strip() for p in patterns], read_gate(g, f"gates[{i}]")))
    f.raw("baseline", None)
    f.done()
    return out


def load_baseline_tolerances(path: str | Path) -> dict[str, float]:
    """The ``[baseline]`` table of a gates file: quantity -> tolerance (see
    :mod:`truestep.ci.baseline`); empty when the file has none."""
    f = _read_toml(Path(path))
    if not f.has("baseline"):
        return {}
    b = f.sub("baseline")
    return {k: b.number(k, nonnegative=True) for k in list(b.table)}


def _read_toml(path: Path) -> Fields:
    """The TOML table of a file: at most :data:`MAX_FILE_BYTES`, UTF-8, nested at most
    :data:`MAX_NESTING` deep; anything else is one :class:`CaseError`."""
    file = str(path)
    try:
        raw = read_regular(path, MAX_FILE_BYTES)
    except FileRefused as err:
        raise CaseError(file, "<file>", err.reason) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        line = raw[: err.start].count(b"\n") + 1
        raise CaseError(file, "<toml>", f"not UTF-8: byte 0x{raw[err.start]:02x} at line {line}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise CaseError(file, "<toml>", str(err)) from None
    except RecursionError:
        raise CaseError(file, "<toml>", f"nested too deeply (at most {MAX_NESTING} levels)") from None
    except ValueError as err:  # an integer beyond Python's digit limit, and the like
        raise CaseError(file, "<toml>", f"a value cannot be read: {str(err)[:80]}") from None
    depth = _depth(data)
    if depth > MAX_NESTING:
        raise CaseError(file, "<toml>", f"nested {depth} levels deep (at most {MAX_NESTING})")
    return Fields(file, data)


def _depth(value: object) -> int:
    """How deeply tables and arrays nest in ``value`` (iteratively: no recursion limit)."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        v, d = stack.pop()
        deepest = max(deepest, d)
        if deepest > MAX_NESTING:
            return deepest
        if isinstance(v, dict):
            stack.extend((x, d + 1) for x in v.values())
        elif isinstance(v, list):
            stack.extend((x, d + 1) for x in v)
    return deepest
