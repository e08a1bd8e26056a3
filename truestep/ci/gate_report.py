"""One ``truestep gate`` from start to end: a run's tables read, every verdict and the
baseline comparison made (:func:`gate`), and the :class:`GateReport` that says what they
found on the console, in JUnit, markdown and JSON, the same for the command line
(:mod:`truestep.commands.gate`) and the API (:func:`truestep.api.gate`).

What is checked: the gates of the cases the results cover (or ``cases``), the gates of
the ``gates`` files, with ``declared_orders`` every fixed-step method's declared order;
with a ``baseline``, the run compared with it row by row in the cases and engines the run
was asked for (``--identical``: also cell by cell), and every gate the baseline's tables
evaluate that this run cannot fails. ``engines`` chooses whose verdicts count; every row
stays for the gates to read (a ``no-worse-than`` gate's other run, the rows a
``time_against`` ratio divides by). Nothing checked is a failure, said in one line.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from truestep.cases.case import Case
from truestep.ci import outputs
from truestep.ci.baseline import Comparison
from truestep.ci.gates import GateResult
from truestep.runtime.visible import visible


class GateInputError(ValueError):
    """Input a gate cannot be run on (a missing or malformed table, a bad option value): one
    line naming the file or the option and the reason (``truestep gate`` exits 2)."""


@dataclass(frozen=True)
class GateRequest:
    """What to check, as ``truestep gate``'s options say it.

    results : the run's ``results.csv`` (its ``stability.csv``, ``restitution.csv`` and
        ``run.json`` are read from beside it)
    baseline : an earlier run's folder to compare with, row by row
    gates : gates files;  cases : a case selection (default: the cases of the results)
    engines : whose verdicts and baseline rows count (comma-separated names or
        ``module:Class``); ``None``: every engine
    declared_orders : also gate every method's declared order
    identical : with a baseline, every non-timing cell must equal the baseline's
    require_identical : ``identical``, and a baseline that cannot be compared bit for bit
        (other package versions or floating-point environment, or a ``run.json`` missing)
        fails the check instead of leaving the tolerances alone to decide
    tolerances : ``QUANTITY=X`` baseline tolerances;  time_against : ``ENGINE/METHOD``
    limits : ``KEY=VALUE`` cost limits the run was made under;  trust_limits : past their ceiling
    """

    results: Path
    baseline: Path | None = None
    gates: tuple[str, ...] = ()
    cases: str | None = None
    engines: str | None = None
    declared_orders: bool = False
    identical: bool = False
    require_identical: bool = False
    tolerances: tuple[str, ...] = ()
    time_against: str | None = None
    limits: tuple[str, ...] = ()
    trust_limits: bool = False


@dataclass
class GateReport:
    """What a gate found: every verdict (:class:`~truestep.ci.gates.GateResult`), the
    baseline comparison (``None`` without one), the ``reasons`` the whole check fails for
    (nothing checked, facts that cannot be read), and ``notes`` on how the comparison was
    made (``--identical``'s count of cells)."""

    verdicts: list[GateResult]
    comparison: Comparison | None = None
    reasons: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    identical: bool = False

    @property
    def passed(self) -> bool:
        """Every gate held, nothing got worse, and something was checked."""
        worse = self.comparison.worse() if self.comparison is not None else []
        return not self.failed and not self.reasons and not worse

    @property
    def held(self) -> list[GateResult]:
        return [v for v in self.verdicts if v.verdict == "pass"]

    @property
    def failed(self) -> list[GateResult]:
        return [v for v in self.verdicts if v.verdict == "fail"]

    @property
    def skipped(self) -> list[GateResult]:
        return [v for v in self.verdicts if v.verdict == "skip"]

    def summary(self) -> str:
        """The last line: the counts of verdicts and of baseline findings."""
        line = f"{len(self.held)} gates held, {len(self.failed)} failed, {len(self.skipped)} not evaluated"
        if self.comparison is None:
            return line
        n = {
            k: sum(f.change == k for f in self.comparison.findings)
            for k in ("worse", "better", "appeared", "vanished", "differs")
        }
        return line + (
            f"; baseline: {self.comparison.compared} rows compared, {n['worse']} worse, "
            f"{n['better']} better, {n['appeared']} appeared, {n['vanished']} vanished"
            + (f", {n['differs']} cells differ" if self.identical else "")
            + (
                f"; {self.comparison.timed} wall-time ratios to {self.comparison.time_against} compared"
                if self.comparison.time_against
                else ""
            )
        )

    def console(self, *, verbose: bool = False, quiet: bool = False) -> list[str]:
        """The lines ``truestep gate`` prints, each with hidden characters shown: the
        comparison's notes; every verdict and finding with ``verbose``, else failures,
        gates not evaluated (unless ``quiet``), what got worse or vanished and the first 20
        cells that differ; the reasons the check fails; the summary."""
        lines = list(self.notes)
        for v in self.verdicts:
            if verbose or v.verdict == "fail" or (v.verdict == "skip" and not quiet):
                lines.append(v.line())
        shown = 0
        for f in self.comparison.findings if self.comparison is not None else []:
            if verbose or f.change in ("worse", "vanished") or (f.change == "differs" and shown < 20):
                shown += f.change == "differs"
                lines.append(f.line())
        lines += [f"FAIL {r}" for r in self.reasons]
        return [visible(line) for line in [*lines, self.summary()]]

    def junit(self) -> str:
        return outputs.junit(self.verdicts, self.comparison, self.reasons)

    def markdown(self) -> str:
        return outputs.markdown(
            self.verdicts, self.comparison, self.reasons, passed=self.passed, notes=self.notes
        )

    def as_json(self) -> str:
        return outputs.as_json(
            self.verdicts, self.comparison, self.reasons, passed=self.passed, notes=self.notes
        )

    def write(
        self,
        *,
        junit: str | Path | None = None,
        markdown: str | Path | None = None,
        json: str | Path | None = None,
        step_summary: str | Path | None = None,
    ) -> None:
        """Write the outputs asked for (``step_summary``: the markdown appended, as to
        ``$GITHUB_STEP_SUMMARY``); one that cannot be written raises :class:`OSError`."""
        if junit:
            outputs.write(junit, self.junit())
        if markdown:
            outputs.write(markdown, self.markdown())
        if step_summary:
            outputs.write(step_summary, self.markdown(), append=True)
        if json:
            outputs.write(json, self.as_json())


def gate(request: GateRequest) -> GateReport:
    """Check ``request`` (see the module's docstring). Raises :class:`GateInputError` for
    tables or options that cannot be used, and the loader's errors
    (:class:`~truestep.cases.CaseError`) for case and gates files."""
    from truestep.measures.engine_facts import take
    from truestep.reporting.run_record import read_run_record

    tables = run_tables(request.results)
    engines = engine_names(request.engines)
    # the facts each run was made with, this run's last (they win)
    under = () if request.baseline is None else (read_run_record(request.baseline),)
    take(*under, read_run_record(request.results.parent))
    asked = {e.strip() for e in engines.split(",") if e.strip()} if engines else None
    cases, verdicts = _verdicts(request, tables)
    report = GateReport(verdicts, identical=request.identical or request.require_identical)
    baseline = _compare(request, tables, cases, engines, report)
    if baseline is not None:
        from truestep.ci.gates import lost_since

        report.verdicts = lost_since(report.verdicts, _verdicts_on(request, baseline, cases))
    if asked is not None:
        report.verdicts = [v for v in report.verdicts if v.gate.engine in asked or v.gate.engine == "*"]
    report.reasons += _reasons(request, report, tables["results"], asked)
    report.notes += unexercised(cases, tables["results"], asked)
    return report


def unexercised(cases: list[Case], results: pd.DataFrame, asked: set[str] | None = None) -> list[str]:
    """A line for each engine of another package than truestep (a user's solver) that
    declares capabilities no case it ran here has (a row run, whatever became of it):
    nothing in these verdicts checks those code paths (a solver whose pinned particles move
    passes every gate of a run without a pinned particle). truestep's own engines are left
    out: the full run exercises them."""
    from truestep.adapters import adapter_class, registered, truestep_target
    from truestep.tables.io import RAN

    lines = []
    features = {c.name: set(map(str, c.features)) for c in cases}
    for engine in dict.fromkeys(results["engine"].astype(str)):
        if (asked is not None and engine not in asked) or engine not in registered():
            continue
        if truestep_target(engine):  # known without importing its engine (seconds for some)
            continue
        try:
            cls = adapter_class(engine)
        except Exception:  # not installed here: its capabilities cannot be read
            continue
        if cls.__module__.split(".")[0] == "truestep":
            continue
        ran = results[(results["engine"].astype(str) == engine) & results["status"].isin(RAN)]
        used = set().union(*(features.get(c, set()) for c in ran["case"].astype(str).unique()))
        idle = sorted(set(map(str, getattr(cls, "capabilities", ()))) - used)
        if idle:
            lines.append(
                f"note: engine {engine} declares {', '.join(idle)}, which no case it ran here has: "
                "no verdict of this run checks those (add a case that needs them)"
            )
    return lines


def _reasons(
    request: GateRequest, report: GateReport, results: pd.DataFrame, asked: set[str] | None
) -> list[str]:
    """Why the whole check fails though no verdict does: it checked nothing, its baseline
    or timing comparison compared nothing, or declared orders cannot be read."""
    comparison = report.comparison
    reasons = []
    if not report.held and not report.failed and (comparison is None or not comparison.compared):
        reasons.append(
            "nothing was checked: no gate was evaluated"
            + ("" if comparison is None else " and no baseline row matched")
            + f" ({len(report.skipped)} gates name cases or engines this run left out)"
        )
    elif comparison is not None and not comparison.compared:
        reasons.append(
            "the baseline comparison compared nothing: no row of the baseline matches one of this run"
        )
    if request.declared_orders:
        from truestep.measures.declared import unreadable_facts

        for engine, why in unreadable_facts(results).items():
            if asked is None or engine in asked:
                reasons.append(
                    f"--declared-orders: engine {engine} ran, but its declared orders cannot be read: {why}"
                )
    if comparison is not None and comparison.time_against and not comparison.timed:
        reasons.append(
            f"--time-against {comparison.time_against}: no wall-time ratio compared (no row of "
            "this run and the baseline ran beside it at the same case and step)"
        )
    return reasons


def run_tables(results_path: Path) -> dict[str, pd.DataFrame | None]:
    """``results`` and, beside it, ``stability`` and ``restitution`` (``None`` if absent),
    each read strictly; a run's own ``results.csv`` is also checked against its record
    (:func:`truestep.tables.io.check_recorded_rows`). Raises :class:`GateInputError`."""
    from truestep.tables.io import REQUIRED, TableError, check_recorded_rows, read_table

    if not os.path.lexists(results_path):
        raise GateInputError(f"{results_path}: no such file (run `truestep run` first)")
    try:
        tables: dict[str, pd.DataFrame | None] = {
            "results": read_table(results_path, "results", set(REQUIRED["results"]))
        }
        for name in ("stability", "restitution"):
            path = results_path.parent / f"{name}.csv"
            there = os.path.lexists(path)
            tables[name] = read_table(path, name, set(REQUIRED[name]), rows=False) if there else None
        if results_path.name == "results.csv":  # a run's own table, beside its record
            check_recorded_rows(results_path.parent, tables)
    except TableError as err:
        raise GateInputError(str(err)) from None
    return tables


def engine_names(engines: str | None) -> str | None:
    """``engines`` as engine names: a ``module:Class`` item is the name its adapter
    declares, registered in this process (so that its declared facts are read); an adapter
    that cannot be loaded is a :class:`GateInputError`."""
    if not engines:
        return engines
    from truestep.adapters import EngineNotInstalled, UnknownEngine, resolve_engine

    names = []
    for item in (e.strip() for e in engines.split(",")):
        if ":" not in item:
            names.append(item)
            continue
        try:
            names.append(resolve_engine(item))
        except (UnknownEngine, EngineNotInstalled) as err:
            raise GateInputError(f"--engines: {err}") from None
    return ",".join(names)


def limits_of(items: Iterable[str], trusted: bool) -> dict[str, float]:
    """``KEY=VALUE`` limit items as a mapping (a bad one is a :class:`GateInputError`)."""
    from truestep.cases.limits import parse_override

    try:
        return parse_override(list(items), trusted=trusted)
    except ValueError as err:
        raise GateInputError(str(err)) from None


def _verdicts(request: GateRequest, tables: dict) -> tuple[list[Case], list[GateResult]]:
    """The cases checked and every gate's verdict on the run's ``tables``."""
    from truestep.adapters import registered
    from truestep.cases import load_cases
    from truestep.cases.loader import load_gates_file
    from truestep.ci.gates import refuse_unknown_engines

    results = tables["results"]
    engines = set(registered()) | set(results["engine"].astype(str))
    limits = limits_of(request.limits, request.trust_limits)
    cases = (
        load_cases(request.cases, engines=engines, limits=limits, trust_limits=request.trust_limits)
        if request.cases
        else _cases_of(results, request.results, engines, limits, request.trust_limits)
    )
    refuse_unknown_engines(
        [item for f in request.gates for item in load_gates_file(f)], engines, str(request.results)
    )
    return cases, _verdicts_on(request, tables, cases)


def _verdicts_on(request: GateRequest, tables: dict, cases: list[Case]) -> list[GateResult]:
    """Every gate's verdict on ``tables``: the cases' own, the gates files' and, with
    ``declared_orders``, the methods' declared orders."""
    from truestep.cases.loader import load_gates_file
    from truestep.ci.gates import check_gates

    extra = [item for f in request.gates for item in load_gates_file(f)]
    if request.declared_orders:
        from truestep.measures.declared import run_order_pairs

        extra += run_order_pairs(cases, tables["results"])
    return check_gates(cases, tables["results"], tables["stability"], tables["restitution"], extra=extra)


def _cases_of(
    results: pd.DataFrame, where: Path, engines: set[str], limits: dict[str, float], trusted: bool
) -> list[Case]:
    """The cases a results table covers: by the file it names (``case_source``), else by
    name in the case library, under ``limits`` (``trusted``: past their ceiling); their
    gates may name ``engines``."""
    from truestep.cases import library, load_case

    lib = library()
    sources = {}
    if "case_source" in results:
        sources = dict(results[["case", "case_source"]].dropna().drop_duplicates("case").values)
    cases = []
    for name in dict.fromkeys(results["case"].astype(str)):
        src = str(sources.get(name, name))
        if src != name and Path(src).is_file():
            cases.append(load_case(src, engines=engines, limits=limits, trust_limits=trusted))
        elif name in lib:
            cases.append(load_case(lib[name], engines=engines, limits=limits, trust_limits=trusted))
        else:
            raise GateInputError(
                f"{where}: case {_quoted(name)} is not in the case library and its "
                f"file {_quoted(src)} is not here; name its file or directory with "
                "--cases"
            )
    return cases


def _quoted(value: object) -> str:
    """``repr`` of a value from outside, cut short and with hidden characters shown."""
    text = visible(value)
    return repr(text if len(text) <= 60 else text[:57] + "...")


def tolerances_of(items: Iterable[str], files: Iterable[str]) -> dict[str, float]:
    """Baseline tolerances: the ``[baseline]`` tables of the gates ``files``, then the
    ``QUANTITY=X`` ``items`` over them (a bad one is a :class:`GateInputError`)."""
    from truestep.cases.loader import load_baseline_tolerances
    from truestep.ci.baseline import TOLERANCES

    tol: dict[str, float] = {}
    for f in files:
        tol.update(load_baseline_tolerances(f))
    for item in items:
        key, sep, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = float("nan")
        if not sep or key not in TOLERANCES or not number >= 0:
            raise GateInputError(
                f"--tolerance: expected QUANTITY=NUMBER >= 0 with QUANTITY one of "
                f"{', '.join(TOLERANCES)}, got {item!r}"
            )
        tol[key] = number
    unknown = set(tol) - set(TOLERANCES)
    if unknown:
        raise GateInputError(
            f"[baseline]: unknown quantity {sorted(unknown)[0]!r}; known: {', '.join(TOLERANCES)}"
        )
    return tol


def _compare(
    request: GateRequest, tables: dict, cases: list[Case], engines: str | None, report: GateReport
) -> dict | None:
    """The comparison with the request's baseline, into ``report`` (with ``--identical``'s
    note); returns the baseline's tables whole, or ``None`` without a baseline."""
    from truestep.ci.baseline import narrow

    if request.baseline is None:
        if request.tolerances or request.time_against or request.identical or request.require_identical:
            raise GateInputError(
                "--tolerance, --time-against, --identical and --require-identical compare against a "
                "baseline: add --baseline DIR"
            )
        return None
    base_dir = request.baseline
    if not os.path.lexists(base_dir / "results.csv"):
        raise GateInputError(f"--baseline: {base_dir}/results.csv: no such file")
    whole = run_tables(base_dir / "results.csv")
    if request.time_against and "/" not in request.time_against:
        raise GateInputError(f"--time-against: expected ENGINE/METHOD, got {_quoted(request.time_against)}")
    scope_cases, scope_engines = _baseline_scope(request, tables["results"], cases, engines)
    baseline = narrow(whole, cases=scope_cases)
    current = narrow(tables, cases=scope_cases)
    report.comparison = compare_with(
        baseline,
        current,
        cases,
        scope_engines,
        tolerances=tolerances_of(request.tolerances, request.gates),
        time_against=request.time_against,
    )
    if request.time_against:
        report.notes += _other_machine(base_dir, request.results.parent)
    if request.identical or request.require_identical:
        line, compared = _identical(
            report.comparison,
            narrow(baseline, engines=scope_engines),
            narrow(current, engines=scope_engines),
            base_dir,
            request.results.parent,
        )
        report.notes.append(line)
        if request.require_identical and not compared:
            report.reasons.append(f"--require-identical: {line.removeprefix('--identical: ')}")
    return whole


def compare_with(
    baseline: dict,
    current: dict,
    cases: list[Case],
    engines: set[str] | None,
    *,
    tolerances: dict[str, float] | None = None,
    time_against: str | None = None,
) -> Comparison:
    """``current``'s tables compared with ``baseline``'s (:func:`truestep.ci.baseline.compare`)
    on the rows of ``engines`` (``None``: all), each case's errors on its own scale: the
    comparison ``truestep gate --baseline`` and the pytest mark's ``baseline=`` both make."""
    from truestep.ci.baseline import compare

    return compare(
        baseline,
        current,
        tolerances=tolerances,
        time_against=time_against,
        scales={c.name: c.error_scale for c in cases},
        engines=engines,
    )


def _baseline_scope(
    request: GateRequest, results: pd.DataFrame, cases: list[Case], engines: str | None
) -> tuple[set[str], set[str]]:
    """The cases and engines a baseline is compared on: those the current run was asked
    for (its ``run.json``; else those in its results), narrowed by the request's cases and
    ``engines``. Baseline rows outside them are not "vanished": the run never asked for
    them."""
    from truestep.reporting.run_record import read_run_record

    record = read_run_record(request.results.parent) or {}
    ran_cases = set(record.get("cases") or results["case"].astype(str))
    ran_engines = set(record.get("engines") or results["engine"].astype(str))
    if request.cases:
        ran_cases &= {c.name for c in cases}
    if engines:
        ran_engines &= {e.strip() for e in engines.split(",") if e.strip()}
    return ran_cases, ran_engines


def _other_machine(base_dir: Path, run_dir: Path) -> list[str]:
    """A note where ``--time-against`` compares timings measured on two kinds of machine
    (their ``run.json``'s ``machine``): a ratio to one engine cancels the CPU's speed only
    where every engine gains or loses alike on the other CPU."""
    from truestep.reporting.run_record import read_run_record
    from truestep.runtime.machine import line, timed_alike

    old, new = (read_run_record(d) or {} for d in (base_dir, run_dir))
    a, b = old.get("machine"), new.get("machine")
    if timed_alike(a, b):
        return []
    return [f"--time-against: the baseline was timed on {line(a)}, this run on {line(b)}"]


def not_bit_for_bit(old: Mapping, new: Mapping) -> list[str]:
    """What keeps two runs' records (``run.json``) from promising equal non-timing cells:
    another truestep version, then each difference of their floating-point environment
    (:func:`truestep.numerics.differences`), one short line each; empty where the promise
    holds. The machine they ran on (``machine``) is not among them: it moves timings only."""
    from truestep.numerics import differences

    diff = differences(old.get("numerics", {}), new.get("numerics", {}))
    if old.get("truestep") != new.get("truestep"):
        diff.insert(0, f"truestep {old.get('truestep')} -> {new.get('truestep')}")
    return diff


def _identical(
    comparison: Comparison, baseline: dict, current: dict, base_dir: Path, run_dir: Path
) -> tuple[str, bool]:
    """``--identical``: every non-timing cell equal to the baseline's (its findings go into
    ``comparison``), when both runs had the same packages and floating-point environment
    (their ``run.json``). Returns the line that says how many cells differ, or why the
    promise does not apply and the tolerances alone decide; and whether the cells were
    compared bit for bit."""
    from truestep.ci.baseline import identical
    from truestep.reporting.run_record import read_run_record

    old, new = read_run_record(base_dir), read_run_record(run_dir)
    if old is None or new is None:
        missing = base_dir if old is None else run_dir
        return (
            f"--identical: {missing}/run.json is missing: cannot tell whether both runs "
            "had the same packages; compared with tolerances only",
            False,
        )
    diff = not_bit_for_bit(old, new)
    if diff:
        return (
            f"--identical: not comparable bit for bit ({'; '.join(diff)[:300]}); "
            "compared with tolerances only",
            False,
        )
    findings, cells = identical(baseline, current)
    seen = {(f.change, f.table, f.key) for f in comparison.findings if f.change in ("appeared", "vanished")}
    comparison.findings += [  # a row the comparison already found appeared or vanished, once
        f for f in findings if (f.change, f.table, f.key) not in seen
    ]
    differ = sum(f.change == "differs" for f in findings)
    return f"--identical: {cells} non-timing cells compared, {differ} differ", True
