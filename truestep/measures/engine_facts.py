"""What a run records about its engines, and what a verdict on its tables reads back.

A run writes, in its ``run.json``, each engine's ``precision`` and each method's declared
facts (``method_facts``: a reference method's name where the adapter names one, else the
facts' values); the peers and glossary notes its report shows (``peers``,
``method_notes``). Judging those tables later (``truestep gate``, the pytest plugin's
``results=``) takes them back (:func:`take`), so that a verdict reads the facts the run was
made with, also on a machine where that engine is not installed: a float32 engine's
orders are fitted above its round-off floor, its declared-order gates are made
(``--declared-orders``), and a run unstable where its facts say it is stable still fails.

A recorded name resolves to the reference method's whole facts (its stability region
too); recorded values carry the stability interval but not the step matrix, so the limit
on a damped mode stays unknown where only values were recorded.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable

from truestep.reference_impl.solvers import MethodFacts
from truestep.reference_impl.solvers.facts import NAMED, Stability

RECORDED_FACTS: dict[str, dict[str, MethodFacts | None]] = {}
"""Engine -> method -> the facts its run recorded (``None``: it declared none), set by
:func:`take` where a run's tables are judged."""


def _number(x: float) -> float | str:
    """A float for JSON: ``inf`` as the string ``"inf"`` (JSON has no infinity)."""
    return "inf" if math.isinf(x) else float(x)


FIELDS = ("order", "evaluations_per_step", "symplectic", "velocity_order", "exact_constant_acceleration")
"""The facts recorded as values (the stability region is recorded apart)."""


def _facts_record(spec: object, facts: MethodFacts | None) -> dict | None:
    """One method's facts as ``run.json`` keeps them: ``{"like": name}`` where they are a
    reference method's (named by the adapter, or the very record), with the values that
    differ where they are that method's changed (``MethodFacts.like(name, ...)``: the same
    stability region); else the values; ``None`` without facts."""
    if facts is None:
        return None
    if isinstance(spec, str):
        return {"like": spec}
    for name, ref in NAMED.items():
        if facts is ref or (facts.stability is not None and facts.stability is ref.stability):
            return {
                "like": name,
                **{f: getattr(facts, f) for f in FIELDS if getattr(facts, f) != getattr(ref, f)},
            }
    s = facts.stability
    return {
        **{f: getattr(facts, f) for f in FIELDS},
        "stability": None
        if s is None
        else {"imaginary": _number(s.imaginary), "real": _number(s.real), "a_stable": s.a_stable},
    }


def record(engines: Iterable[str]) -> dict:
    """``run.json``'s facts of ``engines`` (installed here: the run just used them):
    ``method_facts``, ``peers`` and ``method_notes``, each engine -> method -> value."""
    from truestep.adapters import EngineNotInstalled, UnknownEngine, get_adapter
    from truestep.adapters.base import facts_of

    facts: dict[str, dict] = {}
    peers: dict[str, dict] = {}
    notes: dict[str, dict] = {}
    for engine in engines:
        try:
            adapter = get_adapter(engine)
        except (EngineNotInstalled, UnknownEngine):
            continue
        declared = {
            **(getattr(adapter, "schemes", None) or {}),
            **(getattr(adapter, "method_facts", None) or {}),
        }
        with warnings.catch_warnings():  # a plugin's old ``schemes`` was warned about in its run
            warnings.simplefilter("ignore", DeprecationWarning)
            facts[engine] = {m: _facts_record(declared.get(m), facts_of(adapter, m)) for m in adapter.methods}
        peers[engine] = {str(k): str(v) for k, v in (getattr(adapter, "peers", None) or {}).items()}
        notes[engine] = {str(k): str(v) for k, v in (getattr(adapter, "method_notes", None) or {}).items()}
    return {"method_facts": facts, "peers": peers, "method_notes": notes}


def _facts_from(value: object) -> MethodFacts | None:
    """The facts a ``run.json`` entry records, or ``None`` (none declared, or unreadable)."""
    from truestep.adapters.base import resolve_facts

    if not isinstance(value, dict):
        return None
    try:
        if "like" in value:
            changes = {k: v for k, v in value.items() if k in FIELDS}
            return (
                MethodFacts.like(str(value["like"]), **changes)
                if changes
                else resolve_facts(str(value["like"]))
            )
        s = value.get("stability")
        stability = (
            None
            if not isinstance(s, dict)
            else Stability(float(s["imaginary"]), float(s["real"]), a_stable=bool(s["a_stable"]))
        )
        return MethodFacts(
            order=value["order"],
            evaluations_per_step=value.get("evaluations_per_step"),
            symplectic=bool(value["symplectic"]),
            stability=stability,
            velocity_order=value.get("velocity_order"),
            exact_constant_acceleration=value.get("exact_constant_acceleration"),
        )
    except (KeyError, TypeError, ValueError):
        return None


def take(run_record: dict | None) -> None:
    """Take what a run recorded about its engines (its ``run.json``), over what the
    adapters installed here say: precision and method facts."""
    from truestep.measures.metrics import recorded_precision

    recorded_precision(run_record)
    for engine, methods in ((run_record or {}).get("method_facts") or {}).items():
        if isinstance(methods, dict):
            RECORDED_FACTS[str(engine)] = {str(m): _facts_from(v) for m, v in methods.items()}


def recorded_facts(engine: str, method: str) -> tuple[bool, MethodFacts | None]:
    """``(known, facts)``: whether the judged run recorded ``engine``'s ``method``, and the
    facts it recorded (``None``: it declared none)."""
    methods = RECORDED_FACTS.get(engine)
    if methods is None or method not in methods:
        return False, None
    return True, methods[method]
