"""The ``truestep`` command: run, gate, list, figures.

Exit codes: 0 success; 1 a gate failed, something got worse than the baseline, or
nothing was checked; 2 bad input (one line naming the file, the field and the reason,
no traceback; nothing already written is touched).
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from truestep import __version__
from truestep.cases.limits import CEILING
from truestep.cases.limits import KEYS as LIMIT_KEYS
from truestep.runtime.supervisor import DID_NOT_FINISH
from truestep.runtime.visible import visible
from truestep.tables.spec import compared

if TYPE_CHECKING:
    import pandas as pd

    from truestep.cases.case import Case

# The command answers --version and --help without the engines, pandas or scipy: each
# command imports what it uses when it runs.

REPORT_SPACE_MB = 64
"""Room a new report needs beside ``--out`` besides twice the old one's size, MiB (the
published report is about 10 MiB with its figures)."""
RUN_BUDGET_S = 6 * 3600.0
"""The default wall-clock budget of a whole ``truestep run``, s."""
RESULTS_NEEDS = {"case", "engine", "method", "dt", "dt_kind", "status", "error"}
"""Columns ``truestep gate`` needs in a results table."""


class UsageError(Exception):
    """Bad command-line input: printed as one line, exit code 2."""


def _say(msg: str) -> None:
    print(visible(msg), file=sys.stderr)


def _quoted(value: object) -> str:
    """``repr`` of a value from outside, cut short and with hidden characters shown."""
    text = visible(value)
    return repr(text if len(text) <= 60 else text[:57] + "...")


def _limit_arguments(parser: argparse.ArgumentParser, whose: str) -> None:
    """``--limit`` and ``--trust-limits``, alike for ``run`` and ``gate`` (a case run under
    a raised limit is gated under the same limit)."""
    parser.add_argument(
        "--limit",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="set a cost limit for every case, over the defaults and the case "
        "files' [limits] (keys: " + ", ".join(LIMIT_KEYS) + "); repeatable",
    )
    parser.add_argument(
        "--trust-limits",
        action="store_true",
        help=f"the cases of {whose} are trusted: --limit may raise a limit beyond "
        "the ceiling a case file cannot pass ("
        + ", ".join(f"{k} {getattr(CEILING, k):.3g}" for k in LIMIT_KEYS)
        + ")",
    )


def _load(selection: str, limit_items: list[str] | None = None, *, trust_limits: bool = False) -> list[Case]:
    from truestep.cases import load_cases

    return load_cases(selection, limits=_limits(limit_items, trust_limits), trust_limits=trust_limits)


def _limits(items: list[str] | None, trusted: bool) -> dict[str, float]:
    """The ``--limit`` items as a mapping (a bad one is a :class:`UsageError`)."""
    from truestep.cases.limits import parse_override

    try:
        return parse_override(items or [], trusted=trusted)
    except ValueError as err:
        raise UsageError(str(err)) from None


def _reproduce(args: argparse.Namespace) -> list[str]:
    """The ``truestep run`` arguments that reproduce this run."""
    argv = ["run"] + (["--quick"] if args.quick else [])
    if args.cases != "*":
        argv += ["--cases", args.cases]
    if args.engines:
        argv += ["--engines", args.engines]
    if args.out != "reports":
        argv += ["--out", args.out]
    return argv


def _folder(value: str, option: str) -> Path:
    """The folder ``option`` names, refused when the value is empty or blank (``--out
    "$OUTDIR"`` with the variable unset must not mean the working folder) or names the
    working folder or one above it (truestep replaces the folder it writes whole, and a
    shell left in a folder replaced under it is in none)."""
    if not value.strip():
        raise UsageError(f"{option}: an empty path (an unset variable?): name the folder")
    path = Path(value)
    here = Path.cwd().resolve()
    whole = path.resolve()
    if whole == here or whole in here.parents:
        raise UsageError(
            f"{option}: {visible(value)} is the working folder or one above it, which truestep "
            "would replace whole: name a folder inside it"
        )
    return path


def cmd_run(args: argparse.Namespace) -> int:
    """``truestep run``: sweep, analyses, report; checkpointed for ``--resume``.

    SIGTERM or SIGINT stops the run: the children are killed, the staging folder is
    removed, the previous report stays as it was, and the exit code is 128 + the signal
    with one line that says so. Finished sweeps (and the analyses, once done) stay in the
    journal beside ``--out`` (:mod:`truestep.execution.journal`) until the report is published.
    """
    from truestep.runtime.interrupts import Interrupted, handled
    from truestep.runtime.isolation import set_run_budget

    if args.out is not None:  # `--out "$OUTDIR"`, unset: not reports/
        _folder(args.out, "--out")
    from truestep.execution.journal import Journal

    with handled():
        try:
            return _run(args)
        except Interrupted as err:
            out = args.out or args.resume or "reports"
            where = (
                f"the new report is in {out}/"
                if err.published
                else f"{out}/ holds the previous report, untouched"
            )
            kept = Journal(Path(args.resume or out))
            then = (
                f"; the same command with --resume continues from the {kept.finished()} "
                f"finished sweeps in {kept.dir}"
                if kept.holds_run()
                else ""
            )
            _say(f"truestep: interrupted by {signal.Signals(err.signum).name}: {where}{then}")
            return 128 + err.signum
        except OSError as err:  # a full disk, a file too large, a folder gone: one line
            out = args.out or args.resume or "reports"
            what = visible(err.filename) if err.filename else "the report or its checkpoints"
            raise UsageError(
                f"cannot write {what}: {err.strerror or err}; {out}/ holds the "
                "previous report, untouched (finished sweeps are kept for "
                "--resume)"
            ) from None
        finally:
            set_run_budget(None)


def _run(args: argparse.Namespace) -> int:
    """``truestep run`` once its arguments are checked: :func:`truestep.run` (the one
    experiment driver, :mod:`truestep.execution.experiment`) with the report in ``--out``."""
    from truestep.api import run, select_engines
    from truestep.execution.cluster import ClusterError
    from truestep.execution.journal import JournalError
    from truestep.runtime import collector
    from truestep.runtime.folder import OutRefused
    from truestep.runtime.run_lock import LockBusy

    args.out = args.out or args.resume or "reports"
    if not 0 < args.budget < float("inf"):
        raise UsageError(f"--budget: must be a positive number of seconds, got {args.budget:g}")
    with collector.paused():
        engines = select_engines(args.engines, say=_say)
        collector.settle()  # the command's process: its engines live to its end
    if not engines:
        raise UsageError("--engines: no engine is installed")
    cases = _load(args.cases, args.limit, trust_limits=args.trust_limits)
    if args.quick and args.cases == "*":
        cases = [c for c in cases if c.in_quick] or cases
    out = Path(args.out)
    _check_out(out)
    try:
        tables = run(
            cases,
            engines,
            quick=args.quick,
            out=out,
            progress=None,
            resume=None if args.resume is None else (args.resume or args.out),
            scheduler=args.scheduler,
            budget=args.budget,
            lecture_figures=not args.quick,
            argv=_reproduce(args),
        )
    except JournalError as err:
        raise UsageError(f"--resume: {err}") from None
    except (LockBusy, OutRefused, ClusterError) as err:
        raise UsageError(str(err)) from None
    laps = tables.seconds
    try:
        print(
            f"wrote {visible(out)}/ ({len(tables.results)} result rows) in {sum(laps.values()):.1f} s: "
            f"sweep {laps['sweep']:.1f} s, analyses {laps['analyses']:.1f} s, report {laps['report']:.1f} s",
            flush=True,
        )
    except OSError as err:  # stdout full or gone: the report is published all the same
        raise UsageError(
            f"the new report is in {visible(out)}/, but standard output could not be written: "
            f"{err.strerror or err}"
        ) from None
    return 0


def _check_out(out: Path) -> None:
    """Fail before the sweep if the report cannot be published at ``out``: a folder that
    is not a report truestep wrote (:func:`truestep.runtime.folder.check_out`: a file, a
    folder of other things, a link elsewhere), a mount point (the report is put in place
    by renaming a directory), a parent where this process cannot create the staging
    folder and the journal, or too little space beside it."""
    from truestep.runtime.folder import OutRefused, check_out

    try:
        real = check_out(out)
    except OutRefused as err:
        raise UsageError(str(err)) from None
    if real.exists() and os.path.ismount(real):
        raise UsageError(f"--out: {visible(out)} is a mount point; name a directory inside it")
    try:
        real.parent.mkdir(parents=True, exist_ok=True)
        for where in (real.parent, real) if real.exists() else (real.parent,):
            probe = tempfile.NamedTemporaryFile(dir=where, prefix=".truestep-probe-")
            probe.close()
    except OSError as err:
        raise UsageError(f"--out: cannot write in {visible(out)}: {err.strerror or err}") from None
    old = sum(f.stat().st_size for f in real.rglob("*") if f.is_file()) if real.exists() else 0
    need = 2 * old + REPORT_SPACE_MB * 2**20  # the staged report beside the old one
    free = shutil.disk_usage(real.parent).free
    if free < need:
        raise UsageError(
            f"--out: {free / 2**20:.0f} MiB free beside {out}; staging the report "
            f"there needs about {need / 2**20:.0f} MiB"
        )


def _read_csv(path: Path, needs: set[str], kind: str = "results") -> pd.DataFrame:
    from truestep.tables.io import TableError, read_table

    try:
        return read_table(path, kind, needs, rows=kind == "results")
    except TableError as err:
        raise UsageError(str(err)) from None


def _run_tables(results_path: Path) -> dict[str, pd.DataFrame | None]:
    """``results`` and, beside it, ``stability`` and ``restitution`` (``None`` if absent)."""
    if not os.path.lexists(results_path):
        raise UsageError(f"{results_path}: no such file (run `truestep run` first)")
    tables = {"results": _read_csv(results_path, RESULTS_NEEDS, "results")}
    from truestep.tables.io import REQUIRED, TableError, check_recorded_rows

    for name in ("stability", "restitution"):
        path = results_path.parent / f"{name}.csv"
        tables[name] = _read_csv(path, set(REQUIRED[name]), name) if os.path.lexists(path) else None
    if results_path.name == "results.csv":  # a run's own table, beside its record
        try:
            check_recorded_rows(results_path.parent, tables)
        except TableError as err:
            raise UsageError(str(err)) from None
    return tables


def _cases_of(
    results: pd.DataFrame, where: Path, engines: set[str], limits: dict[str, float], trusted: bool
) -> list[Case]:
    """The cases a results table covers: by the file it names (``case_source``), else by
    name in the case library, under ``limits`` (``--limit``, ``trusted`` with
    ``--trust-limits``); their gates may name ``engines``."""
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
            raise UsageError(
                f"{where}: case {_quoted(name)} is not in the case library and its "
                f"file {_quoted(src)} is not here; name its file or directory with "
                "--cases"
            )
    return cases


def declared_gates(cases: list[Case], results: pd.DataFrame) -> list:
    """The declared-order gates (:mod:`truestep.measures.declared`) of the installed engines that
    ran, each on its own case (:func:`unreadable_facts` names the others)."""
    from truestep.measures.declared import declared_order_pairs, recorded_order_pairs
    from truestep.measures.engine_facts import RECORDED_FACTS

    unreadable = unreadable_facts(results, recorded=False)
    ran = [e for e in dict.fromkeys(results["engine"].astype(str)) if e not in unreadable]
    pairs = declared_order_pairs(cases, ran)
    for engine in unreadable:
        if engine in RECORDED_FACTS:
            pairs += recorded_order_pairs(cases, results, engine)
    return pairs


def unreadable_facts(results: pd.DataFrame, *, recorded: bool = True) -> dict[str, str]:
    """The engines that ran (``results``) whose declared facts this process cannot read, each
    with why: not registered here (an adapter run by ``module:Class``, which ``--engines``
    can name again) or not installed; with ``recorded``, not those whose run recorded
    them (its ``run.json``, :mod:`truestep.measures.engine_facts`). ``--declared-orders``
    fails naming them: their order gates would otherwise be missing without a word."""
    from truestep.adapters import engine_status, registered
    from truestep.measures.engine_facts import RECORDED_FACTS

    out = {}
    for engine in dict.fromkeys(results["engine"].astype(str)):
        if recorded and engine in RECORDED_FACTS:
            continue
        if engine not in registered():
            out[engine] = (
                "it is not registered here: name its adapter with --engines module:Class, or "
                "install the package that registers it"
            )
        elif (status := engine_status(engine)) != "installed":
            out[engine] = status
    return out


def _tolerances(items: list[str], files: list[str]) -> dict[str, float]:
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
            raise UsageError(
                f"--tolerance: expected QUANTITY=NUMBER >= 0 with QUANTITY one of "
                f"{', '.join(TOLERANCES)}, got {item!r}"
            )
        tol[key] = number
    unknown = set(tol) - set(TOLERANCES)
    if unknown:
        raise UsageError(
            f"[baseline]: unknown quantity {sorted(unknown)[0]!r}; known: {', '.join(TOLERANCES)}"
        )
    return tol


def _narrowed(tables: dict, cases: set[str] | None, engines: set[str] | None) -> dict:
    from truestep.ci.baseline import narrow

    return narrow(tables, cases=cases, engines=engines)


def _baseline_scope(
    run_dir: Path, results: pd.DataFrame, args: argparse.Namespace, cases: list[Case]
) -> tuple[set[str], set[str]]:
    """The cases and engines a baseline is compared on: those the current run was asked
    for (its ``run.json``; else those in its results), narrowed by ``--cases`` and
    ``--engines``. Baseline rows outside them are not "vanished": the run never asked
    for them."""
    from truestep.reporting.report import read_run_record

    record = read_run_record(run_dir) or {}
    ran_cases = set(record.get("cases") or results["case"].astype(str))
    ran_engines = set(record.get("engines") or results["engine"].astype(str))
    if args.cases:
        ran_cases &= {c.name for c in cases}
    if args.engines:
        ran_engines &= {e.strip() for e in args.engines.split(",") if e.strip()}
    return ran_cases, ran_engines


def _check_identical(comparison, baseline: dict, current: dict, base_dir: Path, run_dir: Path) -> None:
    """``--identical``: every non-timing cell equal to the baseline's, when both runs had
    the same packages and floating-point environment (their ``run.json``); else one line
    saying why the promise does not apply, and the tolerances alone decide."""
    from truestep.ci.baseline import identical
    from truestep.numerics import differences
    from truestep.reporting.report import read_run_record

    old, new = read_run_record(base_dir), read_run_record(run_dir)
    if old is None or new is None:
        missing = base_dir if old is None else run_dir
        print(
            f"--identical: {missing}/run.json is missing: cannot tell whether both runs "
            "had the same packages; compared with tolerances only"
        )
        return
    diff = differences(old.get("numerics", {}), new.get("numerics", {}))
    if old.get("truestep") != new.get("truestep"):
        diff.insert(0, f"truestep {old.get('truestep')} -> {new.get('truestep')}")
    if diff:
        print(
            f"--identical: not comparable bit for bit ({'; '.join(diff)[:300]}); "
            "compared with tolerances only"
        )
        return
    findings, cells = identical(baseline, current)
    comparison.findings += findings
    print(
        f"--identical: {cells} non-timing cells compared, "
        f"{sum(f.change == 'differs' for f in findings)} differ"
    )


def cmd_gate(args: argparse.Namespace) -> int:
    from truestep.measures.engine_facts import take
    from truestep.reporting.report import read_run_record

    results_path = Path(args.results)
    tables = _run_tables(results_path)
    args.engines = _engine_names(args.engines)
    if args.baseline:  # the facts each run was made with, this run's last (they win)
        take(read_run_record(Path(args.baseline)))
    take(read_run_record(results_path.parent))
    asked = _asked_engines(args)
    # every row stays for the gates to read (a no-worse-than gate's other run, the rows a
    # --time-against ratio divides by); --engines chooses whose verdicts count
    cases, verdicts = _gate_verdicts(args, tables, results_path)
    comparison, baseline = _gate_comparison(args, tables, results_path, cases)
    if baseline is not None:
        verdicts = _kept_since_baseline(args, verdicts, cases, baseline)
    if asked is not None:
        verdicts = [v for v in verdicts if v.gate.engine in asked or v.gate.engine == "*"]
    held = [v for v in verdicts if v.verdict == "pass"]
    failed = [v for v in verdicts if v.verdict == "fail"]
    skipped = [v for v in verdicts if v.verdict == "skip"]
    reasons = []
    if not held and not failed and (comparison is None or not comparison.compared):
        reasons.append(
            "nothing was checked: no gate was evaluated"
            + ("" if comparison is None else " and no baseline row matched")
            + f" ({len(skipped)} gates name cases or engines this run left out)"
        )
    elif comparison is not None and not comparison.compared:
        reasons.append(
            "the baseline comparison compared nothing: no row of the baseline matches one of this run"
        )
    if args.declared_orders:
        for engine, why in unreadable_facts(tables["results"]).items():
            if asked is None or engine in asked:
                reasons.append(
                    f"--declared-orders: engine {engine} ran, but its declared orders cannot be read: {why}"
                )
    if comparison is not None and comparison.time_against and not comparison.timed:
        reasons.append(
            f"--time-against {comparison.time_against}: no wall-time ratio compared (no row of "
            "this run and the baseline ran beside it at the same case and step)"
        )
    _print_gate_lines(args, verdicts, comparison)
    worse = comparison.worse() if comparison is not None else []
    passed = not failed and not reasons and not worse
    summary = f"{len(held)} gates held, {len(failed)} failed, {len(skipped)} not evaluated"
    if comparison is not None:
        n = {
            k: sum(f.change == k for f in comparison.findings)
            for k in ("worse", "better", "appeared", "vanished", "differs")
        }
        summary += (
            f"; baseline: {comparison.compared} rows compared, {n['worse']} worse, "
            f"{n['better']} better, {n['appeared']} appeared, {n['vanished']} vanished"
            + (f", {n['differs']} cells differ" if args.identical else "")
        )
    for r in reasons:
        print(visible(f"FAIL {r}"))
    print(summary)
    _write_ci_outputs(args, verdicts, comparison, reasons, passed)
    return 0 if passed else 1


def _engine_names(engines: str | None) -> str | None:
    """``--engines`` of ``truestep gate`` as engine names: a ``module:Class`` item is the
    name its adapter declares, registered in this process (so that its declared facts are
    read); an adapter that cannot be loaded is a usage error."""
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
            raise UsageError(f"--engines: {err}") from None
    return ",".join(names)


def _asked_engines(args: argparse.Namespace) -> set[str] | None:
    """The engines ``--engines`` names, or ``None`` (every engine)."""
    return {e.strip() for e in args.engines.split(",") if e.strip()} if args.engines else None


def _kept_since_baseline(args: argparse.Namespace, verdicts: list, cases: list, baseline: dict) -> list:
    """``verdicts`` with every gate the baseline's tables evaluate and this run cannot
    failed (:func:`truestep.ci.gates.lost_since`)."""
    from truestep.ci.gates import lost_since

    return lost_since(verdicts, _verdicts_on(args, baseline, cases))


def _verdicts_on(args: argparse.Namespace, tables: dict, cases: list) -> list:
    """Every gate's verdict on ``tables`` (the cases' own, the ``--gates`` files' and, with
    ``--declared-orders``, the methods' declared orders)."""
    from truestep.cases.loader import load_gates_file
    from truestep.ci.gates import check_gates

    extra = [item for f in args.gates for item in load_gates_file(f)]
    if args.declared_orders:
        extra += declared_gates(cases, tables["results"])
    return check_gates(cases, tables["results"], tables["stability"], tables["restitution"], extra=extra)


def _gate_verdicts(args: argparse.Namespace, tables: dict, results_path: Path) -> tuple[list, list]:
    """The cases a ``truestep gate`` checks and every gate's verdict (the cases' own, the
    ``--gates`` files' and, with ``--declared-orders``, the methods' declared orders)."""
    from truestep.adapters import registered
    from truestep.cases import load_cases
    from truestep.cases.loader import load_gates_file
    from truestep.ci.gates import refuse_unknown_engines

    results = tables["results"]
    engines = set(registered()) | set(results["engine"].astype(str))
    limits = _limits(args.limit, args.trust_limits)
    cases = (
        load_cases(args.cases, engines=engines, limits=limits, trust_limits=args.trust_limits)
        if args.cases
        else _cases_of(results, results_path, engines, limits, args.trust_limits)
    )
    refuse_unknown_engines(
        [item for f in args.gates for item in load_gates_file(f)], engines, str(results_path)
    )
    return cases, _verdicts_on(args, tables, cases)


def _gate_comparison(args: argparse.Namespace, tables: dict, results_path: Path, cases: list) -> tuple:
    """The comparison with ``--baseline`` (:func:`truestep.ci.baseline.compare`) and the
    baseline's tables in the run's scope, or ``(None, None)``."""
    from truestep.ci.baseline import compare

    if not args.baseline:
        if args.tolerance or args.time_against or args.identical:
            raise UsageError(
                "--tolerance, --time-against and --identical compare against a baseline: add --baseline DIR"
            )
        return None, None
    base_dir = Path(args.baseline)
    if not os.path.lexists(base_dir / "results.csv"):
        raise UsageError(f"--baseline: {base_dir}/results.csv: no such file")
    baseline = _run_tables(base_dir / "results.csv")
    if args.time_against and "/" not in args.time_against:
        raise UsageError(f"--time-against: expected ENGINE/METHOD, got {_quoted(args.time_against)}")
    scope_cases, scope_engines = _baseline_scope(results_path.parent, tables["results"], args, cases)
    whole = baseline
    baseline = _narrowed(baseline, scope_cases, None)
    current = _narrowed(tables, scope_cases, None)
    comparison = compare(
        baseline,
        current,
        tolerances=_tolerances(args.tolerance, args.gates),
        time_against=args.time_against,
        scales={c.name: c.error_scale for c in cases},
        engines=scope_engines,
    )
    if args.identical:
        _check_identical(
            comparison,
            _narrowed(baseline, None, scope_engines),
            _narrowed(current, None, scope_engines),
            base_dir,
            results_path.parent,
        )
    return comparison, whole


def _print_gate_lines(args: argparse.Namespace, verdicts: list, comparison) -> None:
    """The verdicts and baseline findings ``truestep gate`` prints: every one with
    ``--verbose``; else failures, gates not evaluated (unless ``--quiet``), what got worse or
    vanished, and the first 20 cells that differ."""
    for v in verdicts:
        if args.verbose or v.verdict == "fail" or (v.verdict == "skip" and not args.quiet):
            print(visible(v.line()))
    if comparison is None:
        return
    shown = 0
    for f in comparison.findings:
        if args.verbose or f.change in ("worse", "vanished") or (f.change == "differs" and shown < 20):
            shown += f.change == "differs"
            print(visible(f.line()))


def _write_ci_outputs(
    args: argparse.Namespace, verdicts: list, comparison, reasons: list[str], passed: bool
) -> None:
    """The JUnit, Markdown and JSON files ``truestep gate`` was asked for, and the GitHub
    step summary when ``GITHUB_STEP_SUMMARY`` is set."""
    from truestep.ci import outputs as ci_outputs

    md = ci_outputs.markdown(verdicts, comparison, reasons, passed=passed)
    try:
        if args.junit:
            ci_outputs.write(args.junit, ci_outputs.junit(verdicts, comparison, reasons))
        if args.markdown:
            ci_outputs.write(args.markdown, md)
        if os.environ.get("GITHUB_STEP_SUMMARY"):
            ci_outputs.write(os.environ["GITHUB_STEP_SUMMARY"], md, append=True)
        if args.json:
            ci_outputs.write(args.json, ci_outputs.as_json(verdicts, comparison, reasons, passed=passed))
    except OSError as err:
        raise UsageError(
            f"cannot write {visible(err.filename or 'an output')}: {err.strerror or err}"
        ) from None


def cmd_baseline(args: argparse.Namespace) -> int:
    """``truestep baseline save DIR``: a run's tables kept as a baseline
    (:func:`truestep.ci.saved.save`)."""
    from truestep.ci.saved import BaselineRefused, save

    try:
        provenance = save(Path(args.results), _folder(args.dir, "DIR"))
    except BaselineRefused as err:
        raise UsageError(str(err)) from None
    except OSError as err:
        raise UsageError(
            f"cannot save the baseline: {visible(err.filename or '')} {err.strerror or err}"
        ) from None
    project = provenance["project"]
    where = (
        f"project revision {project['revision'][:12]}" + (" (with changes)" if project["dirty"] else "")
        if project
        else "no git revision (not a checkout)"
    )
    print(f"saved {args.results} as baseline {args.dir} ({provenance['ran_with']}, {where})")
    return 0


def cmd_history(args: argparse.Namespace) -> int:
    """``truestep history add | show | export`` (:mod:`truestep.ci.history`)."""
    import json

    from truestep.ci import history

    try:
        if args.action == "add":
            entry = history.add(Path(args.results), Path(args.store))
            print(f"added {args.results} to {args.store} as {entry['folder']}")
            return 0
        if args.action == "export":
            from truestep.tables.io import TableError, read_table

            try:
                results = read_table(Path(args.results), "results", set())
            except TableError as err:
                raise UsageError(str(err)) from None
            text = json.dumps(history.benchmark_json(results), indent=1) + "\n"
            if args.out == "-":
                sys.stdout.write(text)
            else:
                Path(args.out).write_text(text)
            return 0
        points = history.series(Path(args.store), args.quantity, args.case, args.engine, args.method, args.dt)
    except history.HistoryError as err:
        raise UsageError(str(err)) from None
    if not points:
        raise UsageError(f"{args.store}: no saved run (truestep history add first)")
    from truestep.ci.baseline import TOLERANCES

    tol = args.tolerance if args.tolerance is not None else TOLERANCES.get(args.quantity, 0.1)
    found = set(history.steps([p.value for p in points], tol))
    for k, p in enumerate(points):
        mark = ""
        if k in found:
            before = points[k - 1].value
            mark = f"  <- stepped: {before:.6g} -> {p.value:.6g}"
        dirty = "+" if p.dirty else " "
        print(f"{p.revision[:12]}{dirty} {p.value:.6g} ({p.status}){mark}")
    print(
        f"{len(found)} step(s) in {len(points)} commits (a change of more than {tol:g}, relative, "
        "between the medians of up to 3 commits on either side)"
    )
    return 0


def cmd_list(args: argparse.Namespace) -> int:
    from truestep.adapters import UnknownEngine, engine_status, get_adapter, registered, shadowed

    cases = _load(args.cases)
    if args.quick and args.cases == "*":
        cases = [c for c in cases if c.in_quick] or cases  # as `truestep run --quick` chooses
    print("cases" + (" of a --quick run:" if args.quick else ":"))
    for c in cases:
        print(f"  {c.name:24s} {c.kind:9s} features: {', '.join(sorted(c.features))}")
        steps = ", ".join(f"{h:.4g}" for h in c.sweep(adaptive=False, quick=args.quick))
        tols = ", ".join(f"{t:g}" for t in c.sweep(adaptive=True, quick=args.quick))
        print(f"  {'':24s} {'':9s} steps (s): {steps or '-'}; tolerances: {tols or '-'}")
    print("engines:")
    for line in shadowed():
        print(visible(f"  {line}"))
    names = list(registered()) if not args.engines else [e.strip() for e in args.engines.split(",")]
    for name in names:
        status = engine_status(name) if name in registered() else "unknown engine"
        if status != "installed":
            print(visible(f"  {name:10s} {status}"))
            continue
        try:
            a = get_adapter(name)
        except UnknownEngine as err:  # its adapter could not be made: one line, the list goes on
            print(visible(f"  {name:10s} unusable: {err}"))
            continue
        print(visible(f"  {name:10s} methods: {', '.join(map(str, a.methods))}"))
        print(visible(f"  {'':10s} capabilities: {', '.join(sorted(map(str, a.capabilities)))}"))
    return 0


def cmd_figures(args: argparse.Namespace) -> int:
    from truestep.figures.lecture import write_lecture_figures
    from truestep.runtime.folder import OutRefused, prepare

    try:
        out = prepare(_folder(args.out, "--out"))
    except OutRefused as err:
        raise UsageError(str(err)) from None
    for path, caption in write_lecture_figures(out / "figures"):
        print(f"{path}: {caption}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    import pandas as pd

    from truestep.api import select_engines
    from truestep.execution.bench import COLUMNS, scaling_plot, scaling_table

    try:
        sizes = [float(s) for s in args.sizes.split(",") if s.strip()]
    except ValueError:
        sizes = []
    if not sizes or not all(math.isfinite(n) and n >= 1 for n in sizes):
        raise UsageError(
            f"--sizes: expected particle counts of 1 or more, comma-separated, got {args.sizes!r}"
        )
    from truestep.cases.limits import DEFAULT

    if max(sizes) > DEFAULT.particles:
        raise UsageError(
            f"--sizes: {max(sizes):g} particles is over the {DEFAULT.particles:g} a scene may have "
            "(the rain scene is read as a case, under the default limits)"
        )
    if not 0 < args.budget <= BENCH_BUDGET_MAX_S:
        raise UsageError(
            f"--budget: expected seconds above 0 and at most {BENCH_BUDGET_MAX_S:g}, got {args.budget:g}"
        )
    folder = _folder(args.out, "--out")
    engines = select_engines(args.engines, say=_say)
    if not engines:
        raise UsageError("--engines: no engine is installed")
    from truestep.runtime.folder import OutRefused, check_out, prepare

    try:
        check_out(folder)
    except OutRefused as err:
        raise UsageError(str(err)) from None
    start = time.perf_counter()
    table = scaling_table(engines, sizes=sizes, budget_s=args.budget)
    bandwidth = table.attrs["bandwidth_bytes_per_s"]
    try:
        out = prepare(folder)
    except OutRefused as err:
        raise UsageError(str(err)) from None
    table.to_csv(out / "scaling.csv", index=False, columns=COLUMNS)
    figure = scaling_plot(table, bandwidth, out / "figures" / "scaling.png")
    shown = table.assign(note=table["note"].str.slice(0, 100))
    with pd.option_context(
        "display.width",
        250,
        "display.max_rows",
        None,
        "display.max_colwidth",
        100,
        "display.float_format",
        "{:.4g}".format,
    ):
        print("\n".join(visible(line) for line in shown.to_string(index=False).splitlines()))
    per_step = table.attrs["bytes_per_particle_step"]
    print(
        f"copy bandwidth {bandwidth / 1e9:.2f} GB/s (numpy copy, best of 5, measured in this "
        f"run) = {bandwidth / per_step:.3g} particle-steps/s at {per_step} B per particle-step "
        f"(positions and velocities, float64, read and written)"
    )
    warm = table.attrs["warmup_s"]
    print(
        f"wrote {out / 'scaling.csv'} and {figure} in {time.perf_counter() - start:.1f} s: "
        f"the table took {table.attrs['elapsed_s']:.1f} s of the {args.budget:g} s budget "
        f"(compiling and warm-ups {warm:.1f} s of it)"
    )
    return 0


BENCH_BUDGET_MAX_S = 86400.0
"""The longest ``truestep bench --budget`` (a day): a budget of ``inf`` or ``1e308``
overflowed the step counts it sizes, with a traceback."""


def cmd_env(args: argparse.Namespace) -> int:
    """``truestep env``: the variables that give this machine truestep's numbers, as shell
    ``export`` lines (for processes truestep does not start itself: Dask workers)."""
    import shlex

    from truestep.numerics import environment

    for key, value in environment().items():
        print(f"export {key}={shlex.quote(os.environ.get(key, value))}")
    return 0


def cmd_compile(args: argparse.Namespace) -> int:
    """``truestep compile``: compile the reference's loops for every case file of the library
    and of the figures, every fixed-step method, on every core, into numba's cache (what a
    first ``truestep run`` does before its first timed run): a build step for a fresh
    machine."""
    import time

    from truestep.cases import load_case, load_cases
    from truestep.figures.scenes import FIGURE_CASE_DIR
    from truestep.reference_impl.precompile import compile_all

    began = time.perf_counter()
    cases = [*load_cases("*"), *(load_case(p) for p in sorted(FIGURE_CASE_DIR.glob("*.toml")))]
    models = [c.model for c in cases if c.model is not None]
    workers = len(os.sched_getaffinity(0))
    compile_all(models, workers=workers, progress=lambda line: print(line, flush=True))
    print(f"reference loops ready in {time.perf_counter() - began:.1f} s ({workers} workers)")
    from truestep.adapters import adapter_class, engine_status, registered

    for engine in registered():
        if engine_status(engine) != "installed":
            continue
        warm = getattr(adapter_class(engine), "warm", None)
        if warm is not None:
            began = time.perf_counter()
            built = warm(cases, say=lambda line: print(line, flush=True))
            print(f"{engine} kernels ready in {time.perf_counter() - began:.1f} s ({built} scenes)")
    return 0


CASES_HELP = (
    "cases: names or shell globs of the case library, case files and directories, "
    "comma-separated (default: every case of the library); each item must match"
)
ENGINES_HELP = (
    "engines: registered names or module:Class of an adapter, comma-separated "
    "(default: every installed engine)"
)


def _results_argument(parser: argparse.ArgumentParser) -> None:
    """``--results FILE`` of a command that reads a run's folder (``baseline save``,
    ``history add`` and ``export``)."""
    parser.add_argument(
        "--results",
        default="reports/results.csv",
        metavar="FILE",
        help="the run's results.csv; its other tables and run.json beside it (default: reports/results.csv)",
    )


class _Parser(argparse.ArgumentParser):
    """argparse's parser, except that help and usage that cannot be written (standard
    output on a full device) raise :class:`OSError` rather than pass in silence: the
    command then says so and ends 2 (argparse would exit 0 after ``--help`` wrote nothing)."""

    def _print_message(self, message: str, file: Any = None) -> None:
        if message:
            (file or sys.stderr).write(message)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="truestep",
        description="truestep: a verification and benchmark harness for "
        "physically based animation. Exit codes: 0 success, 1 a gate failed or nothing was "
        "checked, 2 bad input.",
    )
    parser.add_argument("--version", action="version", version=f"truestep {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = sub.add_parser(
        "run",
        help="run the matrix and the analyses, write the tables and the report",
        description="Run every case with every engine and method that can model "
        "it, the stability searches and the restitution sweep; write results.csv, "
        "stability.csv, restitution.csv, scorecard.csv, index.md, index.html and figures/. The "
        "report is put in place as a whole: a run that fails or is killed leaves "
        "the previous one as it was. SIGTERM or SIGINT stops the run (exit 128 + "
        "the signal); its finished sweeps are kept for --resume.",
    )
    run.add_argument(
        "--quick",
        action="store_true",
        help="short sweeps of the quick cases, no energy or lecture figures (CI smoke run)",
    )
    run.add_argument("--cases", default="*", metavar="ITEMS", help=CASES_HELP)
    run.add_argument("--engines", default=None, metavar="NAMES", help=ENGINES_HELP)
    run.add_argument(
        "--out", default=None, metavar="DIR", help="output directory (default: reports, or the --resume DIR)"
    )
    run.add_argument(
        "--resume",
        nargs="?",
        const="",
        default=None,
        metavar="DIR",
        help="continue the interrupted run whose --out was DIR (default: --out): "
        "take its finished sweeps (and analyses) from .DIR.partial beside it and "
        "run the rest; the cases, engines, their code, --quick and truestep version must be "
        "the same (else exit 2). Without --resume a run starts afresh",
    )
    _limit_arguments(run, "this run")
    run.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run the sweeps and the untimed analyses on a Dask cluster: "
        "tcp://HOST:PORT of a running `dask scheduler`, or local:N for a "
        "LocalCluster of N single-threaded worker processes; one timed run per "
        "host at a time (needs truestep[dask])",
    )
    run.add_argument(
        "--budget",
        type=float,
        default=RUN_BUDGET_S,
        metavar="S",
        help=f"wall-clock budget of the whole run, s (default {RUN_BUDGET_S:g}): work "
        "still running when it ends, and work not started, are timeout rows that say "
        "so, and the report is written",
    )
    run.set_defaults(func=cmd_run)

    gate = sub.add_parser(
        "gate",
        help="check gates (and a baseline) against a run's tables",
        description="Check the gates of the case files, and of --gates files, "
        "against a run's tables; with --baseline, compare the run with an earlier "
        "one row by row. Exit 0 when everything checked holds and something was "
        "checked, 1 otherwise, 2 on bad input.",
    )
    gate.add_argument(
        "--results",
        default="reports/results.csv",
        metavar="FILE",
        help="the run's results.csv; stability.csv and restitution.csv are read from "
        "beside it (default: reports/results.csv)",
    )
    gate.add_argument(
        "--cases",
        default=None,
        metavar="ITEMS",
        help=CASES_HELP.replace("every case of the library", "the cases of the results"),
    )
    _limit_arguments(gate, "the results (those the run read with --limit)")
    gate.add_argument(
        "--gates",
        action="append",
        default=[],
        metavar="FILE",
        help="a gates file ([[gates]] tables with a `cases` pattern; optional "
        "[baseline] tolerances); repeatable",
    )
    gate.add_argument(
        "--declared-orders",
        action="store_true",
        help="also gate every fixed-step method's fitted order against the order "
        "its engine declares, on every smooth case with an exact solution",
    )
    gate.add_argument(
        "--baseline",
        default=None,
        metavar="DIR",
        help="an earlier run's output directory to compare with, row by row",
    )
    gate.add_argument(
        "--engines",
        default=None,
        metavar="NAMES",
        help="only the verdicts and baseline rows of these engines (comma-separated names, or "
        "module:Class of an adapter, whose declared facts --declared-orders then reads); the rows "
        "a gate or --time-against compares with are read whatever their engine",
    )
    gate.add_argument(
        "--identical",
        action="store_true",
        help="with --baseline: also require every non-timing cell to equal the "
        "baseline's, bit for bit (when both runs' run.json name the same packages "
        "and floating-point environment; else says why not and uses tolerances)",
    )
    gate.add_argument(
        "--tolerance",
        action="append",
        default=[],
        metavar="QUANTITY=X",
        help=f"override a baseline tolerance ({', '.join(compared())}); repeatable",
    )
    gate.add_argument(
        "--time-against",
        default=None,
        metavar="ENGINE/METHOD",
        help="compare wall time with the baseline as a ratio to this engine/method's "
        "rows of the same case and step (off by default)",
    )
    gate.add_argument("--junit", default=None, metavar="FILE", help="write a JUnit XML report")
    gate.add_argument(
        "--markdown",
        default=None,
        metavar="FILE",
        help="write a markdown summary (also appended to $GITHUB_STEP_SUMMARY when set)",
    )
    gate.add_argument("--json", default=None, metavar="FILE", help="write every verdict as JSON")
    gate.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="print gates that held and baseline rows that got better or appeared",
    )
    gate.add_argument("-q", "--quiet", action="store_true", help="do not print gates not evaluated")
    gate.set_defaults(func=cmd_gate)

    base = sub.add_parser(
        "baseline",
        help="keep a run as a baseline, with its provenance",
        description="Keep a run's tables as a baseline for `truestep gate --baseline DIR`.",
    )
    actions = base.add_subparsers(dest="action", required=True, metavar="ACTION")
    save = actions.add_parser(
        "save",
        help="save a run's tables and their provenance into DIR",
        description="Copy a run's results.csv, stability.csv, restitution.csv and "
        "run.json into DIR cell for cell, without the host name or absolute paths "
        "(made relative to the working directory, the project's root), beside a "
        "provenance.json: the truestep that ran them, every engine's distribution "
        "version and the project's git revision. DIR must be new, empty, or a "
        "baseline saved before (replaced as a whole); anything else is exit 2.",
    )
    save.add_argument("dir", metavar="DIR", help="the baseline's folder")
    _results_argument(save)
    save.set_defaults(func=cmd_baseline)

    hist = sub.add_parser(
        "history",
        help="keep runs by commit and show a quantity over commits",
        description="A history is a folder of runs saved by the project's git revision "
        "(as `truestep baseline save` saves one). `add` saves a run; `show` prints one "
        "row's quantity over the saved commits and names the commits where it stepped; "
        "`export` writes a run as the JSON github-action-benchmark reads.",
    )
    steps = hist.add_subparsers(dest="action", required=True, metavar="ACTION")
    h_add = steps.add_parser("add", help="save a run into the history under the project's git revision")
    h_show = steps.add_parser("show", help="a row's quantity over the saved commits, and where it stepped")
    h_export = steps.add_parser(
        "export", help="a run as github-action-benchmark JSON (customSmallerIsBetter)"
    )
    for p in (h_add, h_show):
        p.add_argument(
            "--store",
            default=".truestep-history",
            metavar="DIR",
            help="the history's folder (default: .truestep-history)",
        )
    for p in (h_add, h_export):
        _results_argument(p)
    h_show.add_argument(
        "quantity", metavar="QUANTITY", help="a numeric column of results.csv (error, wall_s, nfev ...)"
    )
    h_show.add_argument("--case", required=True)
    h_show.add_argument("--engine", required=True)
    h_show.add_argument("--method", required=True)
    h_show.add_argument("--dt", type=float, default=None, help="the row's step (or tolerance)")
    h_show.add_argument(
        "--tolerance",
        type=float,
        default=None,
        metavar="X",
        help="relative change that is a step (default: the baseline's tolerance for the quantity, else 0.1)",
    )
    h_export.add_argument("--out", default="-", metavar="FILE", help="where to write (default: stdout)")
    hist.set_defaults(func=cmd_history)

    lst = sub.add_parser(
        "list",
        help="print cases, engines (installed or not), capabilities and methods",
        description="Print the cases with their features and the engines with "
        "their methods and capabilities; an engine that is not installed is listed "
        "with the pip line that adds it.",
    )
    lst.add_argument("--cases", default="*", metavar="ITEMS", help=CASES_HELP)
    lst.add_argument("--engines", default=None, metavar="NAMES", help="engine names, comma-separated")
    lst.add_argument(
        "--quick",
        action="store_true",
        help="the cases a `truestep run --quick` runs (without --cases: those marked for it) "
        "and the steps and tolerances of their quick sweeps",
    )
    lst.set_defaults(func=cmd_list)

    fig = sub.add_parser(
        "figures",
        help="reproduce the lecture's figures",
        description="Draw the lecture's figures into DIR/figures.",
    )
    fig.add_argument("--out", default="reports", metavar="DIR", help="output directory (default: reports)")
    fig.set_defaults(func=cmd_figures)

    env = sub.add_parser(
        "env",
        help="print the environment that gives truestep's numbers",
        description="Print, as shell export lines, the variables truestep sets "
        "in its own processes so that every machine computes the same numbers "
        "(one BLAS thread, the same OpenBLAS kernels, numpy's SIMD dispatch up "
        'to AVX2). Start Dask workers after `eval "$(truestep env)"`.',
    )
    env.set_defaults(func=cmd_env)

    comp = sub.add_parser(
        "compile",
        help="compile the reference's loops ahead (a build step)",
        description="Compile the reference implementation's loops for every "
        "case of the library and of the figures and every fixed-step method, "
        "on every core, into numba's on-disk cache, as a first `truestep run` "
        "does before its first timed run (about 80 s on 2 cores when the cache "
        "is empty; a second call only loads them); with MuJoCo Warp installed, "
        "also its kernels for every scene it runs, into Warp's kernel cache "
        "(about 60 s on one core when empty).",
    )
    comp.set_defaults(func=cmd_compile)

    from truestep.execution.bench_defaults import BUDGET_S, SIZES

    sizes = ",".join(f"{n:.0e}".replace("e+0", "e") for n in SIZES)
    bench = sub.add_parser(
        "bench",
        help="particle-steps per second against n on the rain scene",
        description="How cost grows with work: run the particle-rain scene with "
        "n particles (1e2 to 1e6) through every fixed-step method of every engine, "
        "one timed run at a time in a process of its own, and print "
        "particle-steps per second with the fraction of the copy bandwidth "
        "measured in the same run; write DIR/scaling.csv and "
        "DIR/figures/scaling.png. Sizes that do not fit in the budget are "
        "rows that say so.",
    )
    bench.add_argument("--engines", default=None, metavar="NAMES", help=ENGINES_HELP)
    bench.add_argument("--out", default="bench", metavar="DIR", help="output directory (default: bench)")
    bench.add_argument(
        "--budget",
        default=BUDGET_S,
        type=float,
        metavar="S",
        help=f"seconds for the timed runs (default: {BUDGET_S:g}; one warm-up per "
        "engine/method comes on top); each engine/method gets an equal share of "
        "what is left, and skips the sizes that would not fit",
    )
    bench.add_argument(
        "--sizes",
        default=sizes,
        metavar="N,N,...",
        help=f"particle counts, comma-separated (default: {sizes})",
    )
    bench.set_defaults(func=cmd_bench)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from truestep.adapters import EngineNotInstalled, UnknownEngine
    from truestep.cases.errors import CaseError, SelectionError
    from truestep.cases.plugins import PluginError

    try:
        return args.func(args)
    except (CaseError, UsageError, SelectionError, UnknownEngine, EngineNotInstalled, PluginError) as err:
        print(f"truestep: error: {visible(err)}", file=sys.stderr)
        return 2
    except SystemExit as err:  # argparse is done: only code the command ran gets here
        print(
            f"truestep: error: code the command ran called sys.exit({visible(repr(err.code))}) "
            "(an adapter, a case library or an exact solution): the command did not finish",
            file=sys.stderr,
        )
        return DID_NOT_FINISH


if __name__ == "__main__":
    sys.exit(main())
