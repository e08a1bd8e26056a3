"""Load and validate case files (TOML) into :class:`~truestep.cases.case.Case` objects."""

from __future__ import annotations

import fnmatch
import tomllib
from pathlib import Path

from truestep.cases.case import Case, Gate, OdeSpec, StabilitySpec
from truestep.cases.errors import CaseError
from truestep.cases.fields import Fields
from truestep.cases.scene import read_scene

CASE_DIR = Path(__file__).resolve().parent
ODE_SYSTEMS = {"circle-field": 2, "kepler": 4, "arenstorf": 4}
GATE_KINDS = {"order", "error", "energy_drift", "status", "property", "stability-limit", "speedup"}
GATE_NUMBERS = {"expect", "tol", "max", "min", "rel_tol"}


def case_files(pattern: str = "*") -> list[Path]:
    """Case files under ``cases/`` whose name (without ``.toml``) matches ``pattern``.

    ``pattern`` is a shell glob, or several separated by commas.
    """
    globs = [p.strip() for p in pattern.split(",") if p.strip()] or ["*"]
    files = sorted(CASE_DIR.glob("*.toml"))
    return [p for p in files if any(fnmatch.fnmatch(p.stem, g) for g in globs)]


def load_cases(pattern: str = "*") -> list[Case]:
    """Load every case matching ``pattern``; raises :class:`CaseError` on the first bad one."""
    return [load_case(p) for p in case_files(pattern)]


def load_case(path: str | Path) -> Case:
    """Load one case file, validating every field."""
    path = Path(path)
    file = str(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise CaseError(file, "<file>", "no such file") from None
    except tomllib.TOMLDecodeError as err:
        raise CaseError(file, "<toml>", str(err)) from None
    f = Fields(file, data)
    name = path.stem
    if name != name.lower() or not all(c.isalnum() or c == "-" for c in name):
        raise CaseError(file, "<name>", "case names are lower-case words joined by dashes")

    kind = f.string("kind", choices={"ode", "particles"})
    run = f.sub("run")
    duration = run.number("duration", positive=True)
    dts = run.numbers("dt", positive=True)
    quick_dts = run.numbers("quick_dt", dts[:2], positive=True)
    tolerances = run.numbers("tolerances", [1e-4, 1e-6, 1e-8], positive=True)
    quick_tolerances = run.numbers("quick_tolerances", tolerances[:2], positive=True)
    for where, values in (("dt", dts), ("quick_dt", quick_dts)):
        if max(values) > duration:
            raise run.error(where, f"a step of {max(values):g} s exceeds the duration {duration:g} s")
    max_records = run.integer("max_records", 2000, minimum=2)
    timeout_s = run.number("timeout", 120.0, positive=True)
    in_quick = run.boolean("quick", True)
    skip = []
    for s in run.subs("skip"):
        skip.append((s.string("engine"), s.string("method", "*"), s.string("reason")))
        s.done()
    run.done()

    ode = model = None
    if kind == "ode":
        o = f.sub("ode")
        system = o.string("system", choices=set(ODE_SYSTEMS))
        y0 = o.array("y0", shape=(ODE_SYSTEMS[system],))
        params = {k: o.number(k) for k in o.table if k not in ("system", "y0")}
        o.done()
        ode = OdeSpec(system, y0, params)
        if f.has("scene"):
            raise f.error("scene", "an ode case has no scene (kind = \"ode\")")
    else:
        model = read_scene(f.sub("scene"))
        if model.n == 0:
            raise f.error("scene", "the scene has no particles")

    ref = f.sub("reference", {})
    exact = ref.string("exact", None)
    error_norm = ref.string("error", "final", choices={"final", "max"})
    error_scale = ref.number("scale", 1.0, positive=True)
    conservative = ref.boolean("conservative", False)
    exact_params = {k: ref.raw(k) for k in ref.table if k not in {"exact", "error", "scale", "conservative"}}
    ref.done()
    if exact is not None:
        from truestep.cases.exact import EXACT

        if exact not in EXACT:
            raise ref.error("exact", f"no exact solution named {exact!r}; known: {', '.join(sorted(EXACT))}")

    stability = None
    if f.has("stability"):
        s = f.sub("stability")
        stability = StabilitySpec(
            horizon=s.number("horizon", positive=True),
            dt_lo=s.number("dt_lo", positive=True),
            dt_hi=s.number("dt_hi", positive=True),
            max_runs=s.integer("max_runs", 30, minimum=3),
            rel_tol=s.number("rel_tol", 1e-3, positive=True),
            quick=s.boolean("quick", False),
            min_steps=s.integer("min_steps", 5000, minimum=10),
            budget_s=s.number("budget_s", 10.0, positive=True),
        )
        if stability.dt_lo >= stability.dt_hi:
            raise s.error("dt_hi", f"must exceed dt_lo ({stability.dt_lo:g})")
        s.done()

    case = Case(
        name=name,
        file=file,
        title=f.string("title", name),
        description=f.string("description", ""),
        kind=kind,
        duration=duration,
        dts=sorted(dts, reverse=True),
        quick_dts=sorted(quick_dts, reverse=True),
        tolerances=sorted(tolerances, reverse=True),
        quick_tolerances=sorted(quick_tolerances, reverse=True),
        model=model,
        ode=ode,
        exact=exact,
        exact_params=exact_params,
        error_norm=error_norm,
        error_scale=error_scale,
        conservative=conservative,
        max_records=max_records,
        gates=_read_gates(f),
        stability=stability,
        properties=f.strings("properties", []),
        skip=skip,
        hard=f.string("hard", None),
        tags=f.strings("tags", []),
        timeout_s=timeout_s,
        in_quick=in_quick,
    )
    f.done()
    return case


def _read_gates(f: Fields) -> list[Gate]:
    gates = []
    for i, g in enumerate(f.subs("gates")):
        kind = g.string("kind", choices=GATE_KINDS)
        engine = g.string("engine", "reference")
        method = g.string("method")
        dt = g.number("dt", None, positive=True)
        params: dict[str, object] = {}
        if kind == "status":
            params["expect"] = g.string("expect", choices={"ok", "unstable"})
        for key in list(g.table):
            if key in GATE_NUMBERS and key not in params:
                params[key] = g.number(key)
        if kind == "property":
            params["name"] = g.string("name")
        if kind == "speedup":
            params["over"] = g.strings("over")
        _require(g, kind, params, dt)
        g.done()
        gates.append(Gate(kind, engine, method, dt, params, f"gates[{i}]"))
    return gates


def _require(g: Fields, kind: str, params: dict, dt: float | None) -> None:
    need = {
        "order": ("expect", "tol"),
        "error": ("max",),
        "energy_drift": ("max",),
        "stability-limit": ("rel_tol",),
        "speedup": ("min",),
    }.get(kind, ())
    for key in need:
        if key not in params:
            raise g.error(key, f"a {kind} gate needs {key}")
    if kind in ("error", "energy_drift", "status", "property", "speedup") and dt is None:
        raise g.error("dt", f"a {kind} gate needs the dt (or tolerance) of the row it reads")
    if kind == "property" and "min" not in params and "max" not in params:
        raise g.error("max", "a property gate needs min, max or both")

