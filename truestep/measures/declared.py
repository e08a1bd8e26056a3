"""Gates from what the methods declare: every method's measured order against its facts.

Each engine declares the facts of its methods (:func:`truestep.adapters.base.facts_of`,
:class:`~truestep.reference_impl.solvers.MethodFacts`). :func:`declared_order_gates`
turns the declared orders into ``order`` gates on every smooth case with an exact
solution, for every fixed-step method of every engine that ran, so that a method
whose convergence does not match what its adapter says fails a gate.

Which order is declared for a case follows from the facts and the scene alone:

- forces that depend on velocity (dampers, drag, wind, Coriolis terms) give the
  method's ``velocity_order`` (velocity Verlet and leapfrog drop to 1), found by
  probing the case's acceleration (:func:`velocity_dependent`);
- a constant acceleration (uniform gravity alone) is integrated exactly by a method
  that declares it (every method of order 2 or more, and the lecture's update): its
  error is round-off, which has no order: its gate asks for exactness instead, every
  run's error below the round-off floor (:func:`constant_acceleration`).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import pandas as pd

from truestep.adapters import PluginFailed, engine_status, get_adapter, plugin_answer, registered
from truestep.adapters.base import duplicate_of, facts_of
from truestep.adapters.reference import build_system
from truestep.cases.case import Case, Gate
from truestep.measures import engine_facts
from truestep.measures.engine_facts import recorded_facts
from truestep.reference_impl.solvers import MethodFacts
from truestep.reference_impl.system import SecondOrderSystem

DECLARED_ORDER_TOL = 0.25
"""How far a fitted order may lie below the declared one (a declared order is the least a
method delivers; over a finite sweep it may deliver more, as symplectic Euler does on a
chain whose second-order error term outweighs its first-order one down to 1e-4 s). A
wrong declaration, or a change that loses an order, moves the fit by a whole unit, so the
tolerance must stay well below one half; a quarter leaves room for the next term of the
error, which moves a fit on a sweep that is not yet asymptotic by a fraction of a unit
(the case files' own order gates allow 0.1 to 0.25 for it)."""
DECLARED_WHERE = "declared"
"""The ``where`` of a declared-order gate, as its id shows it."""
DECLARED_FILE = "<declared order>"
"""The ``file`` (source) of a declared-order gate."""
NON_SMOOTH = frozenset({"planes", "emitters", "impulses"})
"""Scene features that make a run non-smooth (contact events, births, force jumps): any
method is then first order at best, and the declared order says nothing."""
PROBE_STEP = 1e-3
"""Relative size of the velocity (and position) change that probes the acceleration."""
PROBE_TOL = 1e-9
"""A change of the acceleration above this, relative to its size, is a dependence: a
force that does not read the probed quantity changes by exactly nothing, one that does
by about :data:`PROBE_STEP` of its own size."""


def smooth_with_exact(case: Case) -> bool:
    """Whether ``case`` has an exact solution and a smooth scene (no planes, emitters or
    impulses), the cases on which a method shows its declared order."""
    return case.exact is not None and not (case.features & NON_SMOOTH)


def _probe(case: Case) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, SecondOrderSystem] | None:
    system = build_system(case)
    if not isinstance(system, SecondOrderSystem):
        return None
    x = system.get_state()
    q, v = x[: system.half], x[system.half :]
    pattern = 1.0 + (np.sqrt(2.0) * np.arange(system.half)) % 1.0  # all distinct, none 0
    return q, v, pattern, system.get_time(), system


def _changes(a0: np.ndarray, a1: np.ndarray) -> bool:
    size = max(np.max(np.abs(a0), initial=0.0), np.max(np.abs(a1), initial=0.0))
    return bool(np.max(np.abs(a1 - a0), initial=0.0) > PROBE_TOL * size)


def velocity_dependent(case: Case) -> bool:
    """Whether the case's acceleration depends on velocity, probed at its start.

    The reference system of the case (:func:`truestep.adapters.reference.build_system`)
    is asked for ``a(q, v, t)`` and ``a(q, v + dv, t)`` with ``dv`` of relative size
    :data:`PROBE_STEP`: every velocity force here (dampers, drag, wind, Coriolis) is
    linear in the velocity, so any such term shows. A first-order ODE has no velocity.
    """
    probe = _probe(case)
    if probe is None:
        return False
    q, v, pattern, t, system = probe
    dv = PROBE_STEP * (1.0 + np.max(np.abs(v), initial=0.0)) * pattern
    return _changes(system.acceleration(q, v, t), system.acceleration(q, v + dv, t))


def constant_acceleration(case: Case) -> bool:
    """Whether the case's acceleration is the same everywhere and always (uniform gravity
    alone): it changes neither with position, nor with velocity, nor between the start
    and the end of the run (probed like :func:`velocity_dependent`)."""
    probe = _probe(case)
    if probe is None:
        return False
    q, v, pattern, t, system = probe
    a0 = system.acceleration(q, v, t)
    dq = PROBE_STEP * (1.0 + np.max(np.abs(q), initial=0.0)) * pattern
    dv = PROBE_STEP * (1.0 + np.max(np.abs(v), initial=0.0)) * pattern
    return not any(
        _changes(a0, a)
        for a in (
            system.acceleration(q + dq, v, t),
            system.acceleration(q, v + dv, t),
            system.acceleration(q, v, t + case.duration),
        )
    )


def declared_order(facts: MethodFacts, case: Case) -> int | None:
    """The order ``facts`` declare on ``case``, or ``None`` when the method is exact on it
    (a constant acceleration that it integrates exactly: no order to measure)."""
    if facts.exact_when_acceleration_is_constant and constant_acceleration(case):
        return None
    return facts.order_for(velocity_forces=velocity_dependent(case))


def declared_order_gates(cases: Iterable[Case], engines: Iterable[str], *, quick: bool = False) -> list[Gate]:
    """``order`` gates with the declared order of every engine method on every smooth case
    that has an exact solution.

    For each case of ``cases`` with an exact solution and no planes, emitters or impulses
    (:func:`smooth_with_exact`) whose fixed-step sweep (the ``--quick`` one if ``quick``)
    has at least two steps, and for each engine of ``engines`` (the names the run used),
    every method the run simulates there (not adaptive: for those ``dt`` is a tolerance,
    and an order in the step cannot be fitted to it; not unsupported; not skipped by
    the case or as a duplicate) with declared facts (:func:`truestep.adapters.base.facts_of`)
    gets ``Gate(kind="order", engine, method, dt=None, params={"expect": p, "tol":
    DECLARED_ORDER_TOL}, where="declared", file="<declared order>")`` with ``p`` from
    :func:`declared_order`; a method exact on the case gets one whose ``params`` also hold
    ``exact = True`` (every run's error at round-off). Methods without declared facts get
    none.

    A gate does not name its case (a :class:`~truestep.cases.case.Gate` cannot), and the
    declared order differs between cases (Verlet: 2 on an orbit, 1 with a damper): check
    the gates of one case on that case, ``check_gates([case], results, extra=[(["*"], g)
    for g in declared_order_gates([case], engines)])``, or use
    :func:`declared_order_pairs`, which pairs every gate with its case's name.
    """
    return [g for _, g in declared_order_pairs(cases, engines, quick=quick)]


def declared_order_pairs(
    cases: Iterable[Case], engines: Iterable[str], *, quick: bool = False
) -> list[tuple[list[str], Gate]]:
    """:func:`declared_order_gates` as ``([case name], gate)`` pairs, the form
    :func:`truestep.ci.gates.check_gates` takes as ``extra``: each gate on its own case."""
    engines = list(engines)
    out: list[tuple[list[str], Gate]] = []
    for case in cases:
        if not smooth_with_exact(case) or len(case.sweep(adaptive=False, quick=quick)) < 2:
            continue
        for engine in engines:
            adapter = get_adapter(engine)
            for method in adapter.methods:
                try:  # an adapter whose answer raises has crashed rows here, and no gate
                    missing = plugin_answer(engine, "missing()", adapter.missing, case, method)
                    same = (
                        None
                        if missing
                        else plugin_answer(engine, "duplicate()", duplicate_of, adapter, case, method)
                    )
                except PluginFailed:
                    continue
                if (
                    method in adapter.adaptive_methods
                    or missing
                    or any(e == engine and m in (method, "*") for e, m, _ in case.skip)
                    or same is not None
                ):
                    continue
                known, facts = recorded_facts(engine, method)  # the judged run's facts win
                if not known:
                    facts = facts_of(adapter, method)
                gate = None if facts is None else _declared_gate(engine, method, facts, case)
                if gate is not None:
                    out.append(([case.name], gate))
    return out


def recorded_order_pairs(
    cases: Iterable[Case], results: pd.DataFrame, engine: str, *, quick: bool = False
) -> list[tuple[list[str], Gate]]:
    """:func:`declared_order_pairs` for an engine not installed here, from the facts its run
    recorded (:mod:`truestep.measures.engine_facts`) and the rows it ran: a method that ran
    a case at fixed steps (a row neither unsupported nor skipped, which is how the run
    left out what the installed adapter's ``missing``, ``duplicate`` and the case's
    ``skip`` leave out) gets the case's gate."""
    out: list[tuple[list[str], Gate]] = []
    mine = results[(results["engine"].astype(str) == engine) & (results["dt_kind"] == "step")]
    ran = mine[~mine["status"].isin(("unsupported", "skipped"))]
    for case in cases:
        if not smooth_with_exact(case) or len(case.sweep(adaptive=False, quick=quick)) < 2:
            continue
        for method in dict.fromkeys(ran.loc[ran["case"] == case.name, "method"].astype(str)):
            _, facts = recorded_facts(engine, method)
            gate = None if facts is None else _declared_gate(engine, method, facts, case)
            if gate is not None:
                out.append(([case.name], gate))
    return out


def _declared_gate(engine: str, method: str, facts: MethodFacts, case: Case) -> Gate:
    """The declared-order gate of ``engine``'s ``method`` on ``case``: its declared order,
    or, where its facts make it exact on the case (a constant acceleration), exactness:
    every run's error at round-off (``params["exact"]``), not a silent skip."""
    order = declared_order(facts, case)
    if order is None:
        gate = _order_gate(engine, method, facts.order)
        gate.params["exact"] = True
        return gate
    return _order_gate(engine, method, order)


def _order_gate(engine: str, method: str, order: int) -> Gate:
    """The declared-order gate of ``engine``'s ``method`` at ``order``."""
    return Gate(
        kind="order",
        engine=engine,
        method=method,
        dt=None,
        params={"expect": float(order), "tol": DECLARED_ORDER_TOL},
        where=DECLARED_WHERE,
        file=DECLARED_FILE,
    )


def run_order_pairs(cases: Iterable[Case], results: pd.DataFrame) -> list[tuple[list[str], Gate]]:
    """The declared-order gates of the engines that ran (``results``), as
    :func:`declared_order_pairs`, case by case in the order of ``results``' engines: the
    pairs ``truestep gate --declared-orders`` checks and the report's orders table reads. From the facts
    their run recorded (``run.json``, :mod:`truestep.measures.engine_facts`) where it
    recorded them, so that a verdict does not depend on which engines this machine has
    (nor waits for their imports), else from the installed adapter's
    (:func:`unreadable_facts` names engines with neither)."""
    unreadable = unreadable_facts(results)
    readable = [e for e in dict.fromkeys(results["engine"].astype(str)) if e not in unreadable]
    pairs: list[tuple[list[str], Gate]] = []
    for case in cases:
        for engine in readable:
            if engine in engine_facts.RECORDED_FACTS:
                pairs += recorded_order_pairs([case], results, engine)
            else:
                pairs += declared_order_pairs([case], [engine])
    return pairs


def unreadable_facts(results: pd.DataFrame, *, recorded: bool = True) -> dict[str, str]:
    """The engines that ran (``results``) whose declared facts this process cannot read, each
    with why: not registered here (an adapter run by ``module:Class``, which ``--engines``
    can name again) or not installed; with ``recorded``, not those whose run recorded
    them (its ``run.json``, :mod:`truestep.measures.engine_facts`). ``--declared-orders``
    fails naming them: their order gates would otherwise be missing without a word."""
    out: dict[str, str] = {}
    for engine in dict.fromkeys(results["engine"].astype(str)):
        if recorded and engine in engine_facts.RECORDED_FACTS:
            continue
        if engine not in registered():
            out[engine] = (
                "it is not registered here: name its adapter with --engines module:Class, or "
                "install the package that registers it"
            )
        elif (status := engine_status(engine)) != "installed":
            out[engine] = status
    return out
