"""The pytest plugin (entry point ``pytest11``): truestep's gates as tests of your suite.

Mark a test and take the ``truestep_gate`` fixture; the test is repeated once per gate
(and per engine and method a ``*`` stands for), with the gate as its id, and fails with
the gate's measured and required values::

    import pytest

    @pytest.mark.truestep(engines="mine", cases="harmonic-oscillator,cases",
                          gates="truestep-gates.toml")
    def test_physics(truestep_gate):
        truestep_gate.check()

Marker arguments: ``engines`` and ``cases`` as ``truestep run`` takes them (relative
paths are read from the test file's directory first), ``gates`` (a gates file or a
list of them, same), ``quick`` (default false), ``case_gates`` (also check the gates
written in the case files; default true), ``results`` (a run's ``results.csv``, with its
other tables beside it: the gates read it instead of running the cases again, as a CI
that has just run ``truestep run`` wants), ``declared_orders`` (also gate every fixed-step
method's declared order, or exactness, on every smooth case with an exact solution, as
``truestep gate --declared-orders`` does; default false) and ``baseline`` (a baseline's folder,
``truestep baseline save``: one more test per table, ``baseline/results``,
``baseline/orders``, ``baseline/stability``, ``baseline/restitution``, failing with every
row of the marker's cases and engines that got worse or vanished), ``identical`` (with
``baseline``: one more test, ``baseline/identical``, failing with every non-timing cell of
the marker's cases and engines that is not the baseline's bit for bit, as
``truestep gate --identical``; skipped, with the reason, where the two runs had other
package versions or floating-point environments) and ``require_identical`` (the same, but
failing where the runs cannot be compared bit for bit, as ``--require-identical``). The cases run once
per session for each distinct marker; a gate the run cannot evaluate (its engine did not
run the case) is a skipped test, and a marker whose gates name nothing fails.

The ``truestep_run`` fixture runs a selection directly: ``truestep_run(cases, engines,
quick=True)`` returns :class:`truestep.api.Tables`.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

MARKER = "truestep"
_RUNS: dict[tuple, Any] = {}


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        f"{MARKER}(engines, cases, gates=None, quick=False, case_gates=True, results=None, "
        "baseline=None, declared_orders=False, identical=False, require_identical=False): run "
        "truestep cases on these engines (or read results=), and compare with baseline=; the "
        "test takes `truestep_gate`, once per gate and baseline table",
    )


@dataclass(frozen=True)
class Selection:
    """What one marker asks for: the run (engines, cases, quick) and the gates files."""

    engines: tuple[str, ...]
    cases: tuple[str, ...]
    gates: tuple[str, ...]
    quick: bool
    case_gates: bool
    results: str | None = None
    baseline: str | None = None
    declared_orders: bool = False
    identical: bool = False
    require_identical: bool = False


def _paths(value: Any, base: Path) -> tuple[str, ...]:
    """Each item of a marker's ``cases=`` or ``gates=``: a path beside the test file where
    one exists there, else as given (a case name, a glob; the loader says what is wrong
    with it, as for the command line)."""
    items = [] if value is None else value.split(",") if isinstance(value, str) else list(value)
    out = []
    for item in (str(i).strip() for i in items if str(i).strip()):
        near = base / item
        out.append(str(near) if _exists(near) else item)
    return tuple(out)


def _exists(path: Path) -> bool:
    """Whether ``path`` exists; ``False`` for a name the system cannot look up (too long,
    a NUL byte)."""
    try:
        return path.exists()
    except (OSError, ValueError):
        return False


def _selection(mark: pytest.Mark, test_file: Path) -> Selection:
    kw = dict(mark.kwargs)
    unknown = set(kw) - {
        "engines",
        "cases",
        "gates",
        "quick",
        "case_gates",
        "results",
        "baseline",
        "declared_orders",
        "identical",
        "require_identical",
    }
    if unknown:
        raise pytest.UsageError(f"@pytest.mark.{MARKER}: unknown argument {sorted(unknown)[0]!r}")
    if "engines" not in kw or "cases" not in kw:
        raise pytest.UsageError(f"@pytest.mark.{MARKER} needs engines= and cases=")
    if (kw.get("identical") or kw.get("require_identical")) and kw.get("baseline") is None:
        raise pytest.UsageError(
            f"@pytest.mark.{MARKER}: identical= and require_identical= compare with a baseline: add baseline="
        )
    base = test_file.parent
    return Selection(
        engines=tuple(
            e.strip()
            for e in (kw["engines"].split(",") if isinstance(kw["engines"], str) else kw["engines"])
            if e.strip()
        ),
        cases=_paths(kw["cases"], base),
        gates=_paths(kw.get("gates"), base),
        quick=bool(kw.get("quick", False)),
        case_gates=bool(kw.get("case_gates", True)),
        results=_one_path(kw.get("results"), base, "results"),
        baseline=_one_path(kw.get("baseline"), base, "baseline"),
        declared_orders=bool(kw.get("declared_orders", False)),
        identical=bool(kw.get("identical", False)),
        require_identical=bool(kw.get("require_identical", False)),
    )


def _one_path(value: Any, base: Path, name: str) -> str | None:
    """A marker's file or folder argument: relative to the test file's directory, else as
    given; one that does not exist is a usage error (a CI must not pass by reading nothing)."""
    if value is None:
        return None
    path = Path(str(value))
    for candidate in (base / path, path):
        if _exists(candidate):
            return str(candidate)
    raise pytest.UsageError(f"@pytest.mark.{MARKER}: {name}={str(value)!r}: no such file or folder")


@dataclass
class GateCheck:
    """One gate on one engine and method, checked against the marker's (cached) run."""

    selection: Selection
    case: Any
    gate: Any
    copy: int = 1
    """Which gate of this id it is, in file order (a second one's id ends ``#2``)."""

    @property
    def id(self) -> str:
        """The gate's id, as every CI output names it (:func:`truestep.ci.gates.gate_id`)."""
        from truestep.ci.gates import gate_id

        base = gate_id(self.case.name, self.gate)
        return base if self.copy == 1 else f"{base}#{self.copy}"

    def result(self):
        """The :class:`~truestep.ci.gates.GateResult` (runs the selection on first use)."""
        from truestep.ci.gates import check_gate

        tables = _tables(self.selection)
        return check_gate(self.case, self.gate, tables.results, tables.stability, tables.restitution)

    def check(self) -> None:
        """Fail the test (with the gate's measured and required values) unless it holds;
        skip it when the run could not evaluate it."""
        from truestep.runtime.visible import visible

        r = self.result()
        if not r.evaluated:
            pytest.skip(visible(f"not evaluated: {r.line()}"))
        if not r.passed:
            pytest.fail(visible(r.line()), pytrace=False)


@functools.cache
def _gates(sel: Selection) -> tuple[list, list]:
    """The selection's cases and its (case, gate) pairs: the cases' own gates (unless
    ``case_gates`` is false), then the gates files' on every case they name."""
    from truestep.cases.loader import load_cases, load_gates_file
    from truestep.ci.gates import gates_to_check

    cases = load_cases(list(sel.cases))
    own = cases if sel.case_gates else [dataclasses.replace(c, gates=[]) for c in cases]
    extra = [item for f in sel.gates for item in load_gates_file(f)]
    if sel.declared_orders:
        from truestep.api import select_engines
        from truestep.measures.declared import declared_order_pairs

        extra += declared_order_pairs(cases, select_engines(list(sel.engines)), quick=sel.quick)
    return cases, gates_to_check(own, extra)


def _plan(sel: Selection) -> list[GateCheck | BaselineCheck]:
    """Every gate of the selection, ``*`` expanded to the engine/method pairs that can
    model the case (what the run will simulate), then each baseline table to compare."""
    from truestep.adapters import PluginFailed, get_adapter, plugin_answer
    from truestep.api import select_engines

    def models(engine: str, adapter, case, method: str) -> bool:
        """Whether the adapter runs ``case`` with ``method`` (one that cannot say: it is
        checked, and its run's row says why)."""
        try:
            return not hasattr(case, "model") or not plugin_answer(
                engine, "missing()", adapter.missing, case, method
            )
        except PluginFailed:
            return True

    engines = select_engines(list(sel.engines))
    checks: list[GateCheck] = []
    for case, g in _gates(sel)[1]:
        for engine in engines if g.engine == "*" else [g.engine]:
            if engine not in engines:
                checks.append(GateCheck(sel, case, g))  # not run: the check says so (skip)
                continue
            adapter = get_adapter(engine)
            methods = (
                [m for m in adapter.methods if models(engine, adapter, case, m)]
                if g.method == "*"
                else [g.method]
            )
            checks += [GateCheck(sel, case, dataclasses.replace(g, engine=engine, method=m)) for m in methods]
    seen: dict[str, int] = {}
    for c in checks:
        seen[c.id] = seen.get(c.id, 0) + 1
        c.copy = seen[c.id]
    tables = [t for t in BASELINE_TABLES if sel.baseline is not None]
    if sel.identical or sel.require_identical:
        tables.append(IDENTICAL)
    return [*checks, *(BaselineCheck(sel, t) for t in tables)]


BASELINE_TABLES = ("results", "orders", "stability", "restitution")
"""What a marker's ``baseline=`` compares, one test each (:func:`truestep.ci.baseline.compare`)."""
IDENTICAL = "identical"
"""The test of ``identical=`` and ``require_identical=``: every non-timing cell, bit for bit."""
SHOWN = 20
"""How many differing cells a failed ``baseline/identical`` lists (it counts them all)."""


@dataclass
class BaselineCheck:
    """One table of the marker's run compared with its ``baseline=``, in the marker's
    cases and engines: fails with every row that got worse or vanished."""

    selection: Selection
    table: str

    @property
    def id(self) -> str:
        return f"baseline/{self.table}"

    def check(self) -> None:
        if self.table == IDENTICAL:
            self._check_identical()
            return
        comparison = _comparison(self.selection)
        if self.table == "results" and not comparison.compared:
            pytest.fail(
                f"baseline {self.selection.baseline}: no row of the marker's cases and engines to compare",
                pytrace=False,
            )
        bad = [f for f in comparison.worse() if f.table == self.table]
        if bad:
            from truestep.runtime.visible import visible

            pytest.fail("\n".join(visible(f.line()) for f in bad), pytrace=False)

    def _check_identical(self) -> None:
        """Every non-timing cell of the marker's cases and engines equal to the baseline's
        (:func:`truestep.ci.baseline.identical`) where both runs' records promise it;
        else skipped (``identical``) or failed (``require_identical``) with the reason."""
        from truestep.ci.baseline import identical
        from truestep.ci.gate_report import not_bit_for_bit
        from truestep.reporting.run_record import read_run_record
        from truestep.runtime.visible import visible

        sel = self.selection
        old, new = read_run_record(Path(str(sel.baseline))), _record(sel)
        if old is None or new is None:
            where = sel.baseline if old is None else Path(str(sel.results)).parent
            why = [f"{where}/run.json is missing: cannot tell whether both runs had the same packages"]
        else:
            why = not_bit_for_bit(old, new)
        if why:
            line = visible(f"not comparable bit for bit ({'; '.join(why)[:300]})")
            if sel.require_identical:
                pytest.fail(f"require_identical: {line}", pytrace=False)
            pytest.skip(f"{line}; the other baseline tests compare with tolerances only")
        findings, cells = identical(*_narrowed(sel))
        if not cells:
            pytest.fail(
                f"baseline {sel.baseline}: no non-timing cell of the marker's cases and engines to compare",
                pytrace=False,
            )
        if findings:
            more = f"\n... and {len(findings) - SHOWN} more" if len(findings) > SHOWN else ""
            pytest.fail(
                f"{len(findings)} of {cells} non-timing cells differ from the baseline bit for bit:\n"
                + "\n".join(visible(f.line()) for f in findings[:SHOWN])
                + more,
                pytrace=False,
            )


def _record(sel: Selection) -> dict | None:
    """The marker's run's record as ``run.json`` keeps what decides its numbers: its
    ``results=`` folder's, or the run made here (its truestep version and
    :attr:`~truestep.api.Tables.numerics`)."""
    if sel.results is not None:
        from truestep.reporting.run_record import read_run_record

        return read_run_record(Path(sel.results).parent)
    from truestep import __version__

    return {"truestep": __version__, "numerics": _tables(sel).numerics}


def _narrowed(sel: Selection) -> tuple[dict, dict]:
    """The baseline's tables and the marker's run's, each narrowed to the marker's cases
    and engines (made once)."""
    from truestep.adapters import resolve_engine
    from truestep.ci.baseline import narrow, read_tables

    key = ("narrowed", *dataclasses.astuple(sel))
    if key not in _RUNS:
        tables = _tables(sel)
        current = {
            "results": tables.results,
            "stability": tables.stability,
            "restitution": tables.restitution,
        }
        current = {k: v if v is None or len(v.columns) else None for k, v in current.items()}
        names = {c.name for c in _gates(sel)[0]}
        engines = {resolve_engine(e) for e in sel.engines}
        before = narrow(read_tables(Path(str(sel.baseline))), cases=names, engines=engines)
        _RUNS[key] = (before, narrow(current, cases=names, engines=engines))
    return _RUNS[key]


def _comparison(sel: Selection):
    """The marker's run compared with its baseline, in its cases and engines (made once)."""
    from truestep.adapters import resolve_engine
    from truestep.ci.gate_report import compare_with

    key = ("baseline", *dataclasses.astuple(sel))
    if key not in _RUNS:
        before, current = _narrowed(sel)
        engines = {resolve_engine(e) for e in sel.engines}
        _RUNS[key] = compare_with(before, current, _gates(sel)[0], engines)
    return _RUNS[key]


@dataclass
class _Read:
    """A run's tables read from its folder (the marker's ``results=``)."""

    results: Any
    stability: Any
    restitution: Any


def _tables(sel: Selection):
    """The selection's run, made once per session (the stability searches and the
    restitution sweep only when a gate reads them), or read from ``results=``."""
    from truestep.api import run
    from truestep.cases.gate_kinds import GATE_KINDS
    from truestep.measures.engine_facts import take

    key = dataclasses.astuple(sel)
    if sel.results is not None:  # its run's facts, at every use: another marker may have taken others
        from truestep.reporting.run_record import read_run_record

        take(read_run_record(Path(sel.results).parent))
    else:  # a run made here: the installed adapters' facts
        take()
    if key not in _RUNS and sel.results is not None:
        from truestep.ci.baseline import read_tables

        read = read_tables(Path(sel.results).parent)
        _RUNS[key] = _Read(read["results"], read["stability"], read["restitution"])
    if key not in _RUNS:
        cases, todo = _gates(sel)
        analyses = any(GATE_KINDS[g.kind].reads in ("stability", "restitution") for _, g in todo)
        _RUNS[key] = run(
            cases, list(sel.engines), quick=sel.quick, analyses=analyses, progress=lambda _: None
        )
    return _RUNS[key]


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "truestep_gate" not in metafunc.fixturenames:
        return
    mark = metafunc.definition.get_closest_marker(MARKER)
    if mark is None:
        raise pytest.UsageError(
            f"{metafunc.definition.nodeid}: `truestep_gate` needs "
            f"@pytest.mark.{MARKER}(engines=..., cases=..., gates=...)"
        )
    from truestep.adapters import EngineNotInstalled, UnknownEngine
    from truestep.cases import CaseError, SelectionError

    try:
        sel = _selection(mark, Path(str(metafunc.definition.fspath)))
        checks = _plan(sel)
    except (CaseError, SelectionError, UnknownEngine, EngineNotInstalled) as err:
        raise pytest.UsageError(f"{metafunc.definition.nodeid}: truestep: {err}") from None
    if not checks:
        metafunc.parametrize("truestep_gate", [None], ids=["no-gate"], indirect=True)
        return
    metafunc.parametrize("truestep_gate", checks, ids=[c.id for c in checks], indirect=True)


@pytest.fixture
def truestep_gate(request: pytest.FixtureRequest) -> GateCheck | BaselineCheck:
    """One gate of the test's ``@pytest.mark.truestep`` selection (call ``.check()``)."""
    check = getattr(request, "param", None)
    if check is None:
        pytest.fail(
            "truestep: the marker's cases and gates name no gate to check: "
            "a gate that checked nothing has not passed",
            pytrace=False,
        )
    return check


@pytest.fixture(scope="session")
def truestep_run():
    """``truestep_run(cases, engines, quick=False, analyses=True)`` -> Tables (cached)."""

    def run_selection(cases, engines, *, quick: bool = False, analyses: bool = True):
        from truestep.api import run

        key = (str(cases), str(engines), quick, analyses)
        if key not in _RUNS:
            _RUNS[key] = run(cases, engines, quick=quick, analyses=analyses, progress=lambda _: None)
        return _RUNS[key]

    return run_selection
