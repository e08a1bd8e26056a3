"""Generators of hostile case files and result tables, for the fuzz tests and the campaign.

Two layers over one implementation:

* plain generators driven by a :class:`random.Random` (:func:`case_mutant`,
  :func:`table_mutant`): ``tools/campaigns/fuzz_campaign.py`` calls them with ``Random(seed, i)``
  so a campaign is the same file for file on every checkout it runs against;
* hypothesis strategies (:func:`case_mutants`, :func:`table_mutants`) that draw a seed
  and run the same generators on ``Random(seed)``: hypothesis replays a failure (its
  database keeps the seed) but cannot shrink it, so every generated file says how it
  was made (``how``). (A hypothesis-controlled ``st.randoms()`` would shrink, but it
  leans so hard towards its first choices that two thirds of the examples came out of
  one branch.)

Case files come from three sources: the shipped ``cases/*.toml`` parsed with ``tomllib``,
mutated structurally (deleted fields, wrong types, NaN / inf / huge / negative numbers,
wrong shapes, dangling indices, unknown keys, markup in text, transplanted tables) and
written back with the small TOML writer :func:`to_toml`; byte-level damage of such a
text (truncation, invalid UTF-8, deep nesting, integers of thousands of digits, NUL
bytes, flipped bytes); and a schema taken from the shipped files (:class:`Schema`: every
table path, its keys and the values seen there) from which plausible-but-random cases
are assembled. Tables are the shipped ``reports/*.csv`` mutated (dropped columns, ragged
rows, non-numeric cells, numeric statuses, empty, header-only, NUL bytes, binary).

Nothing here imports truestep: the module runs against any checkout's files.
"""

from __future__ import annotations

import datetime as _dt
import math
import random
import re
import tomllib
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hypothesis import strategies as st

ROOT = Path(__file__).resolve().parents[2]
"""The checkout this file belongs to (its ``cases/`` and ``reports/`` are the defaults)."""

TABLE_NAMES = ("results", "stability", "restitution")
"""The tables ``truestep gate`` reads (``scaling.csv`` is not one of them)."""

# ---------------------------------------------------------------------------------------
# TOML writer
# ---------------------------------------------------------------------------------------

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE.match(k) else _string(k)


_PLAIN = re.compile(r'^[^"\\\x00-\x1f\x7f\ud800-\udfff]*$')


def _string(s: str) -> str:
    if _PLAIN.match(s):
        return f'"{s}"'
    out = ['"']
    for ch in s:
        code = ord(ch)
        if ch == '"':
            out.append('\\"')
        elif ch == "\\":
            out.append("\\\\")
        elif ch == "\n":
            out.append("\\n")
        elif ch == "\t":
            out.append("\\t")
        elif code < 0x20 or code == 0x7F:
            out.append(f"\\u{code:04x}")
        elif 0xD800 <= code <= 0xDFFF:  # a lone surrogate cannot be written as UTF-8
            out.append("\\ufffd")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def _float(x: float) -> str:
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    text = repr(x)
    return text if any(c in text for c in ".en") else text + ".0"


def _value(v: Any) -> str:
    """One TOML value, inline (tables as inline tables)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v) if v.bit_length() < 13000 else _big_int_text(v)
    if isinstance(v, float):
        return _float(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, _dt.datetime | _dt.date | _dt.time):
        return v.isoformat()
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(str(k))} = {_value(x)}" for k, x in v.items()) + "}"
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return _string(repr(v))


def _big_int_text(v: int) -> str:
    # str() of a huge int trips Python's 4300-digit limit; hex has none.
    return ("-" if v < 0 else "") + hex(abs(v))


def _is_table_array(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def to_toml(data: dict[str, Any]) -> str:
    """``data`` as TOML text that ``tomllib.loads`` reads back equal (NaN aside).

    Scalars and arrays first, then sub-tables (``[a.b]``) and arrays of tables
    (``[[a.b]]``); keys that are not bare words are quoted.
    """
    lines: list[str] = []

    def emit(table: dict[str, Any], prefix: str) -> None:
        subs = []
        for k, v in table.items():
            if isinstance(v, dict) or _is_table_array(v):
                subs.append((k, v))
            else:
                lines.append(f"{_key(str(k))} = {_value(v)}")
        for k, v in subs:
            name = f"{prefix}.{_key(str(k))}" if prefix else _key(str(k))
            if isinstance(v, dict):
                lines.append(f"\n[{name}]")
                emit(v, name)
            else:
                for item in v:
                    lines.append(f"\n[[{name}]]")
                    emit(item, name)

    emit(data, "")
    return "\n".join(lines).lstrip("\n") + "\n"


# ---------------------------------------------------------------------------------------
# Hostile values
# ---------------------------------------------------------------------------------------

MARKUP = [
    "![x](/etc/hostname)",
    "<script>alert(1)</script>",
    "<img src=x onerror=alert(1)>",
    "[link](javascript:alert(1))",
    "| a | b |\n|---|---|",
    "```\ncode\n```",
    "{{ template }} ${HOME} %s %(x)s",
    "\x1b[31mred\x1b[0m",
    "line\nbreak\r\nand\u2028separator",
    "x" * 5000,
    "\u202eevil",
    "",
]
"""Text that a report or a terminal could mistake for markup or control."""


def huge_int(rng: random.Random) -> int:
    """Integers past int64, past 4300 decimal digits (Python's str/int limit) or past float range."""
    return rng.choice([2**63, -(2**63) - 1, 10**30, 2**1100, -(2**1100), 10**4400, 10**5000])


def nasty_number(rng: random.Random) -> int | float:
    """A number a field should refuse, or one at the edge of what it may take."""
    return rng.choice(
        [
            math.nan,
            math.inf,
            -math.inf,
            0,
            0.0,
            -0.0,
            -1,
            -1.0,
            1e-300,
            -1e-300,
            5e-324,
            1e300,
            -1e300,
            1.7976931348623157e308,
            1e12,
            10**9,
            10**12,
            10**15,
            10**16,
            2**31,
            2**53 + 1,
            3.5,
            0.5,
            1,
            2,
            100000,
            -100000,
            huge_int(rng),
        ]
    )


def nasty_value(rng: random.Random, depth: int = 0) -> Any:
    """Any TOML value of a wrong or extreme kind: numbers, strings, booleans, dates,
    arrays of wrong shape or type, tables."""
    kind = rng.randrange(11 if depth < 2 else 6)
    if kind <= 2:
        return nasty_number(rng)
    if kind == 3:
        return rng.choice([*MARKUP, "a", "1.0", "nan", "reference", "euler", "*"])
    if kind == 4:
        return rng.choice([True, False])
    if kind == 5:
        return rng.choice([_dt.datetime(1979, 5, 27, 7, 32), _dt.date(2000, 1, 1), _dt.time(12, 0)])
    if kind == 6:
        return []
    if kind == 7:
        return rng.choice(
            [
                ["a", "b", "c"],
                [1, "a"],
                [[1, 2], [3]],
                [[[]]],
                [math.nan] * 3,
                [1e300, -1e300, 0.0],
                [0, 0],
                [-1, 10**9],
                [[0, 0, 0]] * 3,
                [{}],
            ]
        )
    if kind == 8:
        return {}
    if kind == 9:
        return {"x": nasty_value(rng, depth + 1)}
    return [nasty_value(rng, depth + 1) for _ in range(rng.randint(1, 4))]


# ---------------------------------------------------------------------------------------
# Structural mutation of a parsed case
# ---------------------------------------------------------------------------------------

Path_ = tuple[Any, ...]


def _paths(node: Any, prefix: Path_ = ()) -> list[Path_]:
    """Every location in a parsed TOML tree (keys of tables, indices of arrays)."""
    out: list[Path_] = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append((*prefix, k))
            out.extend(_paths(v, (*prefix, k)))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.append((*prefix, i))
            out.extend(_paths(v, (*prefix, i)))
    return out


def _get(node: Any, path: Path_) -> Any:
    for p in path:
        node = node[p]
    return node


def _tables(node: Any, prefix: Path_ = ()) -> list[Path_]:
    """Locations of every table (the top one is ``()``)."""
    out: list[Path_] = []
    if isinstance(node, dict):
        out.append(prefix)
        for k, v in node.items():
            out.extend(_tables(v, (*prefix, k)))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.extend(_tables(v, (*prefix, i)))
    return out


def _deepcopy(node: Any) -> Any:
    if isinstance(node, dict):
        return {k: _deepcopy(v) for k, v in node.items()}
    if isinstance(node, list):
        return [_deepcopy(v) for v in node]
    return node


def _label(path: Path_) -> str:
    text = ""
    for p in path:
        text += f"[{p}]" if isinstance(p, int) else (f".{p}" if text else str(p))
    return text or "<top>"


def _numbers(data: Any) -> list[Path_]:
    return [
        p
        for p in _paths(data)
        if isinstance(_get(data, p), int | float) and not isinstance(_get(data, p), bool)
    ]


def _mut_delete(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    paths = _paths(data)
    if not paths:
        return "nothing to delete"
    path = rng.choice(paths)
    del _get(data, path[:-1])[path[-1]]
    return f"deleted {_label(path)}"


def _mut_replace(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    paths = _paths(data)
    if not paths:
        return "nothing to replace"
    path = rng.choice(paths)
    value = nasty_value(rng)
    _get(data, path[:-1])[path[-1]] = value
    return f"{_label(path)} = {_value(value)[:60]}"


def _mut_number(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    paths = _numbers(data)
    if not paths:
        return _mut_replace(rng, data, others)
    path = rng.choice(paths)
    old = _get(data, path)
    if isinstance(old, int) and rng.random() < 0.5:
        new: int | float = rng.choice(
            [old + 1, old + 1000, -old - 1, -1, old * 10**6, 10**9, 10**12, huge_int(rng)]
        )
    elif rng.random() < 0.5:
        new = rng.choice([math.nan, math.inf, -math.inf, 0.0, -0.0])
    else:
        factor = rng.choice([-1.0, 0.0, 1e-300, 1e-12, 1e-9, 1e6, 1e9, 1e12, 1e300])
        try:
            new = float(old) * factor
        except OverflowError:
            new = math.inf
    _get(data, path[:-1])[path[-1]] = new
    return f"{_label(path)}: {_value(old)[:30]} -> {_value(new)[:40]}"


def _mut_unknown_key(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    where = rng.choice(_tables(data))
    table = _get(data, where)
    key = rng.choice(
        ["unknown", "dtt", "Duration", "strenght", "exta", "__class__", "", " ", "a.b", "ключ", "x" * 300]
    )
    table[key] = nasty_value(rng)
    return f"unknown key {_label((*where, key))[:80]}"


def _mut_shape(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    paths = _paths(data)
    if not paths:
        return "nothing to reshape"
    path = rng.choice(paths)
    parent, key = _get(data, path[:-1]), path[-1]
    old = parent[key]
    how = rng.randrange(6)
    if how == 0:
        parent[key] = [old]
        what = "wrapped in an array"
    elif how == 1 and isinstance(old, list) and old:
        parent[key] = old[0]
        what = "unwrapped"
    elif how == 2 and isinstance(old, list) and old:
        parent[key] = old[:-1]
        what = "last element dropped"
    elif how == 3 and isinstance(old, list):
        parent[key] = [*old, old[-1] if old else 0]
        what = "an element added"
    elif how == 4 and isinstance(old, list) and old:
        parent[key] = old * rng.choice([2, 100, 1000])
        what = "repeated"
    else:
        parent[key] = [] if rng.random() < 0.5 else [[], []]
        what = "emptied"
    return f"{_label(path)} {what}"


def _mut_type(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    paths = _paths(data)
    if not paths:
        return "nothing to retype"
    path = rng.choice(paths)
    parent, key = _get(data, path[:-1]), path[-1]
    old = parent[key]
    if isinstance(old, str):
        new: Any = rng.choice([1, 1.5, True, [old], {"value": old}])
    elif isinstance(old, bool):
        new = rng.choice(["true", 1, 0])
    elif isinstance(old, int | float):
        new = rng.choice([str(old), [old], True, {"value": old}])
    elif isinstance(old, list):
        new = rng.choice([["a"] * max(1, len(old)), "[1, 2, 3]", 3, {"0": old}])
    elif isinstance(old, dict):
        new = rng.choice([[old], "table", 1, [old, old]])
    else:
        new = str(old)
    parent[key] = new
    return f"{_label(path)} retyped to {type(new).__name__} {_value(new)[:40]}"


def _mut_index(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    ints = [p for p in _paths(data) if type(_get(data, p)) is int]
    if not ints:
        return _mut_number(rng, data, others)
    path = rng.choice(ints)
    new = rng.choice([-1, -2, 5, 99, 10**6, 2**63, 10**12])
    _get(data, path[:-1])[path[-1]] = new
    return f"{_label(path)} index -> {new}"


def _mut_text(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    paths = [p for p in _paths(data) if isinstance(_get(data, p), str)]
    if not paths:
        paths = [("title",)]
    path = rng.choice(paths)
    new = rng.choice(MARKUP)
    _get(data, path[:-1])[path[-1]] = new
    return f"{_label(path)} = {_value(new)[:60]}"


def _mut_transplant(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    if not others:
        return _mut_replace(rng, data, others)
    other = rng.choice(others)
    where = rng.choice([p for p in _tables(other) if p] or [()])
    if not where:
        return "no table to transplant"
    value = _deepcopy(_get(other, where))
    target = rng.choice(_tables(data))
    key = where[-1] if isinstance(where[-1], str) else rng.choice(["scene", "reference", "run", "ode"])
    table = _get(data, target)
    table[key] = value
    return f"{_label((*target, key))} <- another case's {_label(where)}"


def _mut_extreme_run(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    run = data.setdefault("run", {})
    if not isinstance(run, dict):
        return "[run] is not a table"
    choice = rng.randrange(8)
    if choice == 0:
        run["duration"] = rng.choice([1e9, 1e300, 3.15e7])
        return f"run.duration = {run['duration']}"
    if choice == 1:
        key = rng.choice(["dt", "quick_dt", "tolerances", "quick_tolerances"])
        run[key] = rng.choice([[1e-12], [1e-300], [math.nan], [math.inf], [], [5e-324, 1e-3]])
        return f"run.{key} = {_value(run[key])}"
    if choice == 2:
        run["timeout"] = rng.choice([1e300, math.inf, math.nan, 0.0, -1.0, 1e-9])
        return f"run.timeout = {run['timeout']}"
    if choice == 3:
        run["max_records"] = rng.choice([10**9, 10**12, 1, 0, -5, 2**63])
        return f"run.max_records = {run['max_records']}"
    if choice == 4:
        ref = data.setdefault("reference", {})
        if isinstance(ref, dict):
            ref[rng.choice(["rtol", "atol", "scale", "dt"])] = rng.choice([1e-300, 0.0, math.nan, 1e300])
        return "reference tolerance extreme"
    if choice == 5:
        stab = data.setdefault("stability", {"horizon": 1.0, "dt_lo": 1e-3, "dt_hi": 0.1})
        if isinstance(stab, dict):
            key = rng.choice(["horizon", "dt_lo", "dt_hi", "max_runs", "min_steps", "budget_s"])
            stab[key] = rng.choice([1e9, 1e-300, 10**9, math.inf, 0, 2**63])
            return f"stability.{key} = {_value(stab[key])}"
        return "stability not a table"
    if choice == 6:
        run["quick_dt"] = [1e-9]
        run["duration"] = 1.0
        return "run.quick_dt = [1e-9] over 1 s (1e9 steps)"
    run["dt"] = [1e-8]
    run["quick_dt"] = [1e-8]
    return "run.dt = quick_dt = [1e-8] (duration / dt above 1e8)"


def _mut_scene(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    """Targeted damage where the scene models are: meshes, emitters, planes, fields, springs."""
    scene = data.get("scene")
    if not isinstance(scene, dict):
        return _mut_replace(rng, data, others)
    choice = rng.randrange(9)
    if choice == 0:
        scene.setdefault("planes", [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0]}])
        planes = scene["planes"]
        if isinstance(planes, list) and planes and isinstance(planes[0], dict):
            planes[0]["normal"] = rng.choice(
                [[0.0, 0.0, 0.0], [math.nan, 1.0, 0.0], [1e-320, 0.0, 0.0], [0.0, 1.0], [1.0, 0.0, 0.0, 0.0]]
            )
            return f"scene.planes[0].normal = {_value(planes[0]['normal'])}"
    if choice == 1:
        emitter = {
            "shape": "cube",
            "center": [0.0, 0.0, 0.0],
            "size": 0.1,
            "rate_n": 1e9,
            "rate_r": 0.0,
            "speed": 1.0,
            "lifetime": 10**6,
            "frame_dt": 0.01,
            "capacity": rng.choice([10**9, 10**12, 2**62, 0, -1]),
            "particle_mass": 0.01,
        }
        scene.setdefault("emitters", []).append(emitter) if isinstance(
            scene.get("emitters", []), list
        ) else None
        return f"scene.emitters += capacity {emitter['capacity']}, rate_n 1e9"
    if choice == 2:
        scene["fields"] = [
            rng.choice(
                [
                    {"kind": "vortex", "center": ["a", "b", "c"]},
                    {"kind": "radial", "center": [0.0, 0.0, 0.0]},
                    {"kind": "drag"},
                    {"kind": "gravity", "strength": "strong"},
                    {"kind": "unknown-field", "strength": 1.0},
                ]
            )
        ]
        return f"scene.fields = {_value(scene['fields'])[:80]}"
    if choice == 3:
        springs = scene.get("springs")
        if isinstance(springs, list) and springs and isinstance(springs[0], dict):
            springs[0]["pairs"] = rng.choice(
                [[[0, 10**6]], [[-1, 0]], [[0, 0]], [[0]], [[0, 1, 2]], [[0.5, 1]], [["a", "b"]]]
            )
            return f"scene.springs[0].pairs = {_value(springs[0]['pairs'])}"
    if choice == 4:
        anchors = scene.get("anchors")
        if isinstance(anchors, list) and anchors and isinstance(anchors[0], dict):
            anchors[0]["particle"] = rng.choice([10**6, -1, 2**63, 1.5])
            return f"scene.anchors[0].particle = {anchors[0]['particle']}"
    if choice == 5:
        for k, v in list(scene.items()):
            if isinstance(v, list) and v and isinstance(v[0], dict) and "impulse" in str(k):
                v[0]["particle"] = 10**6
                return f"scene.{k}[0].particle = 1000000"
        scene["impulses"] = [{"particle": 10**6, "time": 0.1, "impulse": [1.0, 0.0, 0.0]}]
        return "scene.impulses particle 1000000"
    if choice == 6:
        for k, v in scene.items():
            if isinstance(v, list) and v and isinstance(v[0], dict):
                for kk in v[0]:
                    if kk in {
                        "nx",
                        "ny",
                        "nz",
                        "n",
                        "count",
                        "segments",
                        "rows",
                        "cols",
                        "blocks",
                        "strands",
                        "per_strand",
                        "resolution",
                        "capacity",
                    }:
                        v[0][kk] = rng.choice([10**5, 10**7, 10**9, 10**15])
                        return f"scene.{k}[0].{kk} = {v[0][kk]}"
        scene["particles"] = [{"position": [[0.0, 0.0, 0.0]] * 2, "mass": 1.0, "count": 10**9}]
        return "scene.particles count 1e9"
    if choice == 7:
        for v in scene.values():
            if isinstance(v, list) and v and isinstance(v[0], dict):
                victim = rng.choice(list(v[0]) or ["x"])
                v[0].pop(victim, None)
                return f"scene element lost {victim}"
    particles = scene.get("particles")
    if isinstance(particles, list) and particles and isinstance(particles[0], dict):
        p = particles[0]
        key = rng.choice(["position", "velocity", "mass"])
        p[key] = rng.choice([[[math.nan, 0.0, 0.0]], [[0.0, 0.0]], [[1e300, 1e300, 1e300]], -1.0, 0.0, []])
        return f"scene.particles[0].{key} = {_value(p[key])}"
    return _mut_replace(rng, data, others)


def _mut_ode(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    ode = data.get("ode")
    if not isinstance(ode, dict):
        return _mut_scene(rng, data, others)
    choice = rng.randrange(4)
    if choice == 0:
        ode[rng.choice(["mu", "omega", "bogus", "k", "gm"])] = nasty_value(rng)
        return "ode: unknown or wrong parameter"
    if choice == 1:
        key = rng.choice(list(ode) or ["system"])
        ode[key] = rng.choice(["kepler", "arenstorf", "circle-field", "no-such-system", 1, []])
        return f"ode.{key} = {_value(ode[key])}"
    if choice == 2:
        for k, v in ode.items():
            if isinstance(v, list):
                ode[k] = [*v, 0.0] if rng.random() < 0.5 else v[:-1]
                return f"ode.{k} length changed"
    ref = data.setdefault("reference", {})
    if isinstance(ref, dict):
        ref["exact"] = rng.choice(
            ["linear", "kepler", "free-fall", "reference-run", "projectile", "no-such", "circle", ""]
        )
        return f"reference.exact = {ref['exact']!r}"
    return "reference not a table"


def _mut_gates(rng: random.Random, data: dict, others: Sequence[dict]) -> str:
    gates = data.get("gates")
    gate = {
        "kind": rng.choice(
            [
                "order",
                "error",
                "energy_drift",
                "status",
                "property",
                "stability-limit",
                "speedup",
                "restitution",
                "no-worse-than",
                "bogus",
            ]
        )
    }
    for k in rng.sample(
        [
            "method",
            "engine",
            "dt",
            "expect",
            "tol",
            "max",
            "min",
            "rel_tol",
            "factor",
            "bounce",
            "e_set",
            "name",
            "bounces",
            "against",
        ],
        rng.randint(0, 5),
    ):
        gate[k] = (
            nasty_value(rng)
            if rng.random() < 0.5
            else rng.choice(["rk4", "euler", "reference", 1e-3, 2, [], "nope"])
        )
    if isinstance(gates, list):
        gates.append(gate)
    else:
        data["gates"] = [gate]
    return f"gates += {_value(gate)[:100]}"


MUTATIONS: dict[str, Callable[[random.Random, dict, Sequence[dict]], str]] = {
    "delete": _mut_delete,
    "replace": _mut_replace,
    "number": _mut_number,
    "unknown-key": _mut_unknown_key,
    "shape": _mut_shape,
    "type": _mut_type,
    "index": _mut_index,
    "text": _mut_text,
    "transplant": _mut_transplant,
    "extreme-run": _mut_extreme_run,
    "scene": _mut_scene,
    "ode": _mut_ode,
    "gates": _mut_gates,
}
"""Structural mutations of a parsed case: each edits the dict in place and says what it did."""


# ---------------------------------------------------------------------------------------
# Byte-level damage
# ---------------------------------------------------------------------------------------


def _nest(depth: int, inline: bool) -> str:
    return "{a = " * depth + "1" + "}" * depth if inline else "[" * depth + "]" * depth


def byte_mutation(rng: random.Random, text: bytes) -> tuple[bytes, str]:
    """Damage at the byte level that the TOML parser itself must survive."""
    choice = rng.randrange(13)
    if choice == 0:
        cut = rng.randrange(len(text) + 1) if text else 0
        return text[:cut], f"truncated at byte {cut} of {len(text)}"
    if choice == 1:
        bad = rng.choice([b"\xff", b"\xfe\xff", b"\xc3\x28", b"\xed\xa0\x80", b"\x80", b"\xf8\x88\x80\x80"])
        at = rng.randrange(len(text) + 1)
        return text[:at] + bad + text[at:], f"invalid UTF-8 {bad!r} at byte {at}"
    if choice == 2:
        depth = rng.choice([50, 500, 1000, 3000, 10000, 100000])
        inline = rng.random() < 0.3
        return (
            text + f"\ndeep = {_nest(depth, inline)}\n".encode(),
            f"deep nesting {depth} ({'inline tables' if inline else 'arrays'})",
        )
    if choice == 3:
        digits = rng.choice([400, 4301, 5000, 20000])
        number = "9" * digits
        key = rng.choice(["seed", "max_records", "duration", "huge"])
        return _replace_or_append(text, key, number), f"{key} = an integer of {digits} digits"
    if choice == 4:
        key = rng.choice(["duration", "dt", "huge"])
        number = rng.choice(["1e400", "-1e400", "1e-400", "0x" + "f" * 400, "nan", "+inf", "-nan"])
        return _replace_or_append(text, key, number), f"{key} = {number}"
    if choice == 5:
        at = rng.randrange(len(text) + 1)
        return text[:at] + b"\0" + text[at:], f"NUL byte at {at}"
    if choice == 6:
        data = bytearray(text)
        for _ in range(rng.randint(1, 8)):
            if data:
                data[rng.randrange(len(data))] = rng.randrange(256)
        return bytes(data), "flipped bytes"
    if choice == 7:
        return b"\xef\xbb\xbf" + text.replace(b"\n", b"\r\n"), "BOM and CRLF"
    if choice == 8:
        return rng.choice([b"", b" ", b"\n\n", b"#", b"[", b"=", b"a="]), "nearly empty"
    if choice == 9:
        return bytes(rng.randrange(256) for _ in range(rng.randint(1, 512))), "binary garbage"
    if choice == 10:
        lines = text.splitlines(keepends=True)
        if lines:
            line = rng.choice(lines)
            return text + b"\n" + line, "a line repeated (duplicate key)"
        return text, "nothing to duplicate"
    if choice == 11:
        size = rng.choice([10**5, 10**6])
        return text + b"\n[run2]\n" + b"".join(
            b"k%d = %d\n" % (i, i) for i in range(size // 10)
        ), f"{size // 10} extra keys"
    return text + b"\n" + rng.choice(
        [
            b"[[gates]]\n" * 2000,
            b'title = """' + b"x" * 100000 + b'"""',
            b"[a.b.c.d.e.f.g.h.i.j.k.l.m.n.o.p]\nx = 1",
            b'"\\ud800" = 1',
        ]
    ), "appended oddities"


def _replace_or_append(text: bytes, key: str, number: str) -> bytes:
    pattern = re.compile(rb"(?m)^(" + re.escape(key.encode()) + rb"\s*=\s*)[^\n]*$")
    if pattern.search(text):
        return pattern.sub(lambda m: m.group(1) + number.encode(), text, count=1)
    return text + f"\n{key} = {number}\n".encode()


# ---------------------------------------------------------------------------------------
# The schema of the shipped cases
# ---------------------------------------------------------------------------------------


def _shape(path: Path_) -> str:
    """A location with array indices erased: ``scene.planes[].normal``."""
    return ".".join("[]" if isinstance(p, int) else str(p) for p in path)


@dataclass
class Schema:
    """What the shipped case files hold: per table location (indices erased), the keys
    seen there, and per key location the values seen there."""

    keys: dict[str, set[str]] = field(default_factory=dict)
    values: dict[str, list[Any]] = field(default_factory=dict)
    arrays_of_tables: set[str] = field(default_factory=set)

    @classmethod
    def of(cls, cases: Iterable[dict]) -> Schema:
        schema = cls()
        for data in cases:
            schema._add(data, ())
        return schema

    def _add(self, node: Any, path: Path_) -> None:
        where = _shape(path)
        if isinstance(node, dict):
            keys = self.keys.setdefault(where, set())
            for k, v in node.items():
                keys.add(k)
                self._add(v, (*path, k))
        elif _is_table_array(node):
            self.arrays_of_tables.add(where)
            for i, v in enumerate(node):
                self._add(v, (*path, i))
        else:
            self.values.setdefault(where, []).append(node)

    def generate(self, rng: random.Random, where: str = "", depth: int = 0) -> dict[str, Any]:
        """A table for ``where``: a random subset of the keys seen there, each filled with
        a value seen at that key (in any case), sometimes a hostile one, sometimes
        nothing. Plausible to the eye, random in combination."""
        out: dict[str, Any] = {}
        keys = sorted(self.keys.get(where, set()))
        for k in keys:
            if where == "" and k == "kind":
                continue
            if rng.random() < 0.35:
                continue
            sub = f"{where}.{k}" if where else k
            if sub in self.arrays_of_tables and depth < 4:
                elem = f"{sub}.[]"
                out[k] = [self.generate(rng, elem, depth + 1) for _ in range(rng.randint(0, 3))]
            elif sub in self.keys and depth < 4:
                out[k] = self.generate(rng, sub, depth + 1)
            elif sub in self.values:
                out[k] = _deepcopy(rng.choice(self.values[sub])) if rng.random() < 0.93 else nasty_value(rng)
        if where == "":
            out = {"kind": rng.choice(["ode", "particles", "particles", "ode", "rigid"]), **out}
        return out


# ---------------------------------------------------------------------------------------
# Case mutants
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CaseMutant:
    """A generated case file: ``name`` (its file stem, usually the base case's), the bytes
    to write, and how it was made."""

    name: str
    data: bytes
    how: str

    def write(self, directory: Path) -> Path:
        """Write as ``directory/<name>.toml`` (the directory is created)."""
        directory.mkdir(parents=True, exist_ok=True)
        path = directory / f"{self.name}.toml"
        path.write_bytes(self.data)
        return path


@dataclass(frozen=True)
class CaseBase:
    """A shipped case file: its name, text and parsed table."""

    name: str
    text: bytes
    data: dict[str, Any]


def load_bases(root: Path = ROOT) -> list[CaseBase]:
    """The case files shipped in ``root/cases`` (not the figures' cases under
    ``cases/figures/``: they are not part of a quick run), parsed."""
    files = sorted((root / "cases").glob("*.toml"))
    out = []
    for f in files:
        raw = f.read_bytes()
        out.append(CaseBase(f.stem, raw, tomllib.loads(raw.decode("utf-8"))))
    if not out:
        raise FileNotFoundError(f"no case files under {root / 'cases'}")
    return out


def case_mutant(rng: random.Random, bases: Sequence[CaseBase], schema: Schema | None = None) -> CaseMutant:
    """One generated case file: 60% structural mutations of a shipped case (1 to 3 of
    :data:`MUTATIONS`), 15% the same then damaged at the byte level, 10% byte damage of
    the shipped text itself, 15% assembled from the :class:`Schema` (and sometimes
    mutated once more)."""
    base = rng.choice(bases)
    others = [b.data for b in bases if b is not base]
    roll = rng.random()
    if roll < 0.15:
        schema = schema or Schema.of(b.data for b in bases)
        data = schema.generate(rng)
        how = ["schema"]
        if rng.random() < 0.3:
            name = rng.choice(list(MUTATIONS))
            how.append(f"{name}: {MUTATIONS[name](rng, data, others)}")
        name = base.name if rng.random() < 0.7 else "fuzz-schema"
        return CaseMutant(name, to_toml(data).encode("utf-8", "replace"), "; ".join(how))
    if roll < 0.25:
        data, how = byte_mutation(rng, base.text)
        return CaseMutant(base.name, data, f"{base.name}: bytes: {how}")
    data = _deepcopy(base.data)
    how = [base.name]
    for _ in range(rng.choice([1, 1, 1, 2, 2, 3])):
        name = rng.choice(list(MUTATIONS))
        how.append(f"{name}: {MUTATIONS[name](rng, data, others)}")
    text = to_toml(data).encode("utf-8", "replace")
    if roll < 0.40:
        text, damage = byte_mutation(rng, text)
        how.append(f"bytes: {damage}")
    stem = base.name
    if rng.random() < 0.01:
        stem = rng.choice(["Bad Name", "UPPER", "dots.in.name", "ü-case", "-"])
        how.append(f"file name {stem!r}")
    return CaseMutant(stem, text, "; ".join(how))


# ---------------------------------------------------------------------------------------
# Table mutants
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TableMutant:
    """A damaged table: which of :data:`TABLE_NAMES` it replaces, its bytes, how made."""

    table: str
    data: bytes
    how: str


def load_tables(root: Path = ROOT) -> dict[str, bytes]:
    """The shipped ``reports/{results,stability,restitution}.csv`` of ``root``."""
    out = {}
    for name in TABLE_NAMES:
        path = root / "reports" / f"{name}.csv"
        if path.is_file():
            out[name] = path.read_bytes()
    if "results" not in out:
        raise FileNotFoundError(f"no reports/results.csv under {root}")
    return out


STATUS_VALUES = ["0", "1", "1.5", "OK", "okay", "", "nan", "crashed ", "🙂", "ok;rm -rf /"]
CELL_VALUES = [
    "abc",
    "1e999",
    "nan",
    "inf",
    "-",
    "1,2",
    '"',
    "NaN",
    "0x10",
    "1_000",
    "TRUE",
    " ",
    "\t",
    "1e-400",
    "9" * 5000,
    "<script>",
    "=cmd|' /C calc'!A0",
]


def _csv_rows(text: str) -> list[list[str]]:
    import csv

    return [row for row in csv.reader(text.splitlines())]


def _csv_text(rows: list[list[str]]) -> str:
    import csv
    import io

    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerows(rows)
    return buf.getvalue()


def table_mutant(rng: random.Random, tables: dict[str, bytes]) -> TableMutant:
    """One of the shipped tables, damaged in one of many ways (each chosen to be garbage,
    not a plausible table)."""
    name = rng.choice(sorted(tables))
    raw = tables[name]
    rows = _csv_rows(raw.decode("utf-8", "replace"))
    header, body = (rows[0], rows[1:]) if rows else ([], [])
    choice = rng.randrange(14)

    def done(data: bytes | str, how: str) -> TableMutant:
        return TableMutant(
            name,
            data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data,
            f"{name}.csv: {how}",
        )

    if choice == 0 and header:
        needed = [
            c
            for c in header
            if c
            in {
                "case",
                "engine",
                "method",
                "dt",
                "status",
                "error",
                "dt_limit",
                "dt_limit_exact",
                "e_set",
                "bounce",
                "e_measured",
            }
        ]
        col = rng.choice(needed or header)
        k = header.index(col)
        kept = [[c for i, c in enumerate(r) if i != k] for r in rows]
        return done(_csv_text(kept), f"column {col} dropped")
    if choice == 1 and body:
        r = rng.randrange(len(body))
        row = body[r]
        body[r] = row[: -rng.randint(1, max(1, len(row) - 1))] if rng.random() < 0.5 else [*row, "extra", "x"]
        return done(_csv_text([header, *body]), f"row {r + 2} ragged")
    if choice == 2 and body:
        numeric = [
            i
            for i, c in enumerate(header)
            if c
            in {
                "dt",
                "error",
                "energy_drift",
                "nfev",
                "steps",
                "wall_s",
                "dt_limit",
                "dt_limit_exact",
                "runs",
                "e_set",
                "bounce",
                "e_measured",
                "v_in",
            }
        ]
        if numeric:
            col = rng.choice(numeric)
            r = rng.randrange(len(body))
            value = rng.choice(CELL_VALUES[:2] + CELL_VALUES[4:])
            if col < len(body[r]):
                body[r][col] = value
            return done(_csv_text([header, *body]), f"{header[col]} row {r + 2} = {value[:20]!r}")
    if choice == 3 and "status" in header and body:
        k = header.index("status")
        value = rng.choice(STATUS_VALUES)
        every = rng.random() < 0.5
        for r in body if every else [rng.choice(body)]:
            if k < len(r):
                r[k] = value
        return done(_csv_text([header, *body]), f"status = {value!r} in {'every row' if every else 'a row'}")
    if choice == 4:
        return done(b"", "empty")
    if choice == 5:
        return done(_csv_text([header]), "header only")
    if choice == 6:
        at = rng.randrange(len(raw) + 1)
        return done(raw[:at] + b"\0" + raw[at:], f"NUL byte at {at}")
    if choice == 7:
        return done(bytes(rng.randrange(256) for _ in range(rng.randint(1, 4096))), "binary")
    if choice == 8:
        at = rng.randrange(len(raw) + 1)
        return done(raw[:at] + b"\xff\xfe" + raw[at:], f"invalid UTF-8 at {at}")
    if choice == 9 and header:
        text_cols = [i for i, c in enumerate(header) if c in {"case", "engine", "method"}]
        if text_cols and body:
            col = rng.choice(text_cols)
            for r in body:
                if col < len(r):
                    r[col] = str(rng.randint(0, 9))
            return done(_csv_text([header, *body]), f"column {header[col]} all numbers")
    if choice == 10:
        return done(_csv_text([list(reversed(header)), *body]), "header reversed (columns swapped)")
    if choice == 11:
        return done(raw[: rng.randrange(len(raw) + 1)] + b'"', "truncated, unclosed quote")
    if choice == 12 and header:
        return done(_csv_text([[f"{c}?" for c in header], *body]), "every header name changed")
    return done(
        _csv_text([header, *[[rng.choice(CELL_VALUES) for _ in header] for _ in range(3)]]),
        "rows of junk cells",
    )


# ---------------------------------------------------------------------------------------
# Hypothesis strategies
# ---------------------------------------------------------------------------------------

_CACHE: dict[Path, tuple[list[CaseBase], Schema, dict[str, bytes]]] = {}


def _shipped(root: Path = ROOT) -> tuple[list[CaseBase], Schema, dict[str, bytes]]:
    if root not in _CACHE:
        bases = load_bases(root)
        _CACHE[root] = (bases, Schema.of(b.data for b in bases), load_tables(root))
    return _CACHE[root]


def _seeds() -> st.SearchStrategy[int]:
    return st.integers(min_value=0, max_value=2**63 - 1)


def case_mutants(root: Path = ROOT) -> st.SearchStrategy[CaseMutant]:
    """Generated case files (:func:`case_mutant`) from ``root``'s shipped cases."""
    bases, schema, _ = _shipped(root)
    return _seeds().map(lambda seed: case_mutant(random.Random(seed), bases, schema))


def case_bytes(root: Path = ROOT) -> st.SearchStrategy[bytes]:
    """Just the bytes of :func:`case_mutants`."""
    return case_mutants(root).map(lambda m: m.data)


def schema_cases(root: Path = ROOT) -> st.SearchStrategy[dict[str, Any]]:
    """Plausible-but-random case tables assembled from the shipped cases' schema."""
    _, schema, _ = _shipped(root)
    return _seeds().map(lambda seed: schema.generate(random.Random(seed)))


def table_mutants(root: Path = ROOT) -> st.SearchStrategy[TableMutant]:
    """Damaged results / stability / restitution tables (:func:`table_mutant`)."""
    _, _, tables = _shipped(root)
    return _seeds().map(lambda seed: table_mutant(random.Random(seed), tables))
