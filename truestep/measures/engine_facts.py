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
too). Recorded values carry the stability interval but not the step matrix (a function):
for those methods the run also records the exact largest stable step on each of its
linear cases (``stability_limits``, from the whole facts, step matrix included), which a
verdict on its tables reads (:func:`recorded_limit`) before it computes one from the
values (which knows no limit on a damped mode).
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
RECORDED_LIMITS: dict[tuple[str, str, str], float] = {}
"""(engine, method, case) -> the exact largest stable step (s) its run recorded
(``stability_limits``), set by :func:`take`."""
RECORDED_PEERS: dict[str, dict[str, str]] = {}
"""Engine -> method -> the reference method its run recorded as its scheme (``peers``),
set by :func:`take`."""
RECORDED_NOTES: dict[str, dict[str, str]] = {}
"""Engine -> method -> the glossary note its run recorded (``method_notes``), set by
:func:`take`."""


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


def _limits_record(facts: MethodFacts | None, recorded: dict | None, cases: Iterable) -> dict:
    """The exact largest stable step (s; ``"inf"``: every step) of facts recorded as
    values whose step matrix is not recorded, on each of ``cases`` where one is known
    (:func:`truestep.cases.exact.stability_limit`): case name -> limit."""
    from truestep.cases.exact import stability_limit

    s = None if facts is None else facts.stability
    if recorded is None or "like" in recorded or s is None or s.step_matrix is None:
        return {}
    out = {}
    for case in cases:
        limit = stability_limit(case, facts)
        if limit is not None and not math.isnan(limit):
            out[case.name] = _number(limit)
    return out


def record(engines: Iterable[str], cases: Iterable = ()) -> dict:
    """``run.json``'s facts of ``engines`` (installed here: the run just used them):
    ``method_facts``, ``peers`` and ``method_notes``, each engine -> method -> value;
    ``stability_limits`` (engine -> method -> case -> s) on ``cases`` for the methods whose
    step matrix the recorded values leave out (:func:`_limits_record`), and ``twins``
    (:func:`truestep.measures.twins.twins_of`), where there are any."""
    from truestep.adapters import EngineNotInstalled, UnknownEngine, get_adapter
    from truestep.adapters.base import facts_of
    from truestep.measures.twins import twins_of

    cases = list(cases)
    engines = list(engines)
    limits: dict[str, dict] = {}
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
            whole = {m: facts_of(adapter, m) for m in adapter.methods}
        facts[engine] = {m: _facts_record(declared.get(m), f) for m, f in whole.items()}
        mine = {m: _limits_record(f, facts[engine][m], cases) for m, f in whole.items()}
        if any(mine.values()):
            limits[engine] = {m: v for m, v in mine.items() if v}
        peers[engine] = {str(k): str(v) for k, v in (getattr(adapter, "peers", None) or {}).items()}
        notes[engine] = {str(k): str(v) for k, v in (getattr(adapter, "method_notes", None) or {}).items()}
    return {
        "method_facts": facts,
        "peers": peers,
        "method_notes": notes,
        **({"stability_limits": limits} if limits else {}),
        **({"twins": twins} if (twins := twins_of(engines, recorded=False)) else {}),
    }


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


def take(*run_records: dict | None) -> None:
    """Judge by what these runs recorded about their engines (their ``run.json``), over what
    the adapters installed here say: precision, method facts, stability limits, peers,
    glossary notes and twins, a later record winning where two name the same engine (a baseline's,
    then the judged run's).
    What an earlier call took is dropped first, so one judged run's facts never reach the
    next (two markers of one pytest session, two gates of one process); ``take()`` judges by
    the installed adapters alone."""
    from truestep.measures import metrics, twins

    RECORDED_FACTS.clear()
    RECORDED_LIMITS.clear()
    RECORDED_PEERS.clear()
    RECORDED_NOTES.clear()
    twins.RECORDED_TWINS.clear()
    metrics.RECORDED_PRECISION.clear()
    for run_record in run_records:
        _take_one(run_record)


def _take_one(run_record: dict | None) -> None:
    """One run's record over what :func:`take` holds already."""
    from truestep.measures.metrics import recorded_precision
    from truestep.measures.twins import RECORDED_TWINS

    recorded_precision(run_record)
    for engine, methods in ((run_record or {}).get("method_facts") or {}).items():
        if isinstance(methods, dict):
            RECORDED_FACTS[str(engine)] = {str(m): _facts_from(v) for m, v in methods.items()}
    pairs = (run_record or {}).get("twins")
    if isinstance(pairs, dict):
        RECORDED_TWINS.update({str(b): str(a) for b, a in pairs.items() if isinstance(a, str)})
    for key, into in (("peers", RECORDED_PEERS), ("method_notes", RECORDED_NOTES)):
        for engine, said in ((run_record or {}).get(key) or {}).items():
            if isinstance(said, dict):
                into[str(engine)] = {str(m): v for m, v in said.items() if isinstance(v, str)}
    for engine, methods in ((run_record or {}).get("stability_limits") or {}).items():
        for method, by_case in methods.items() if isinstance(methods, dict) else ():
            for case, value in by_case.items() if isinstance(by_case, dict) else ():
                try:
                    limit = float(value)
                except (TypeError, ValueError):
                    continue
                if limit >= 0:
                    RECORDED_LIMITS[(str(engine), str(method), str(case))] = limit


def recorded_facts(engine: str, method: str) -> tuple[bool, MethodFacts | None]:
    """``(known, facts)``: whether the judged run recorded ``engine``'s ``method``, and the
    facts it recorded (``None``: it declared none)."""
    methods = RECORDED_FACTS.get(engine)
    if methods is None or method not in methods:
        return False, None
    return True, methods[method]


def recorded_words(engine: str, key: str) -> dict[str, str] | None:
    """What the judged run recorded of ``engine``'s ``peers`` or ``method_notes``
    (``key``), method -> words, or ``None`` where it recorded nothing of that engine."""
    return {"peers": RECORDED_PEERS, "method_notes": RECORDED_NOTES}[key].get(engine)


def recorded_limit(engine: str, method: str, case: str) -> float | None:
    """The exact largest stable step (s) the judged run recorded for ``engine``'s
    ``method`` on ``case`` (``stability_limits``), or ``None``."""
    return RECORDED_LIMITS.get((engine, method, case))
