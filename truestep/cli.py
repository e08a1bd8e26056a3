"""The ``truestep`` command: run, gate, list, figures.

Exit codes: 0 success; 1 a gate failed; 2 bad input (one line naming the file, the
field and the reason, no traceback; nothing already written is touched).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import pandas as pd

from truestep.adapters import ADAPTERS, get_adapter
from truestep.cases import CaseError, load_cases
from truestep.cases.case import Case


class UsageError(Exception):
    """Bad command-line input: printed as one line, exit code 2."""


def _load(pattern: str) -> list[Case]:
    from truestep.properties import PROPERTIES

    cases = load_cases(pattern)
    if not cases:
        raise UsageError(f"--cases: no case matches {pattern!r}")
    for c in cases:
        for p in c.properties:
            if p not in PROPERTIES:
                raise CaseError(c.file, "properties", f"unknown property {p!r}")
        for g in c.gates:
            if g.kind == "property" and g.params["name"] not in c.properties:
                raise CaseError(c.file, f"{g.where}.name",
                                f"{g.params['name']!r} is not in this case's properties")
            if g.engine not in ADAPTERS:
                raise CaseError(c.file, f"{g.where}.engine", f"unknown engine {g.engine!r}")
    return cases


def _engines(text: str | None) -> list[str]:
    if not text:
        return list(ADAPTERS)
    names = [e.strip() for e in text.split(",") if e.strip()]
    for e in names:
        if e not in ADAPTERS:
            raise UsageError(f"--engines: unknown engine {e!r}; known: {', '.join(ADAPTERS)}")
    return names


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


def cmd_run(args: argparse.Namespace) -> int:
    from truestep.analyses import run_analyses
    from truestep.report import write_report
    from truestep.runner import run_matrix

    cases = _load(args.cases)
    if args.quick:
        cases = [c for c in cases if c.in_quick] or cases
    engines = _engines(args.engines)
    out = Path(args.out)
    clock = [time.perf_counter()]

    def lap() -> float:
        clock.append(time.perf_counter())
        return clock[-1] - clock[-2]

    traces: dict = {}
    results = run_matrix(cases, engines, quick=args.quick, traces=traces)
    t_sweep = lap()
    tables = run_analyses(cases, engines, results, quick=args.quick)
    t_analyses = lap()
    write_report(out, cases, results, tables, quick=args.quick, argv=_reproduce(args),
                 traces=None if args.quick else traces, with_lecture_figures=not args.quick)
    t_report = lap()
    print(f"wrote {out}/ ({len(results)} result rows) in {clock[-1] - clock[0]:.1f} s: "
          f"sweep {t_sweep:.1f} s, analyses {t_analyses:.1f} s, report {t_report:.1f} s")
    return 0


def cmd_gate(args: argparse.Namespace) -> int:
    from truestep.gates import check_gates

    cases = _load(args.cases)
    results_path = Path(args.results)
    if not results_path.is_file():
        raise UsageError(f"{results_path}: no such file (run `truestep run` first)")
    try:
        results = pd.read_csv(results_path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as err:
        raise UsageError(f"{results_path}: cannot read as CSV: {err}") from None
    missing = {"case", "engine", "method", "dt", "status", "error"} - set(results.columns)
    if missing:
        raise UsageError(f"{results_path}: missing columns {', '.join(sorted(missing))}")
    stab_path = results_path.parent / "stability.csv"
    stability = pd.read_csv(stab_path) if stab_path.is_file() else None
    verdicts = check_gates(cases, results, stability)
    failed = [v for v in verdicts if v.evaluated and not v.passed]
    for v in verdicts:
        if args.verbose or not v.passed or not v.evaluated:
            print(v.line())
    held = sum(v.evaluated and v.passed for v in verdicts)
    skipped = sum(not v.evaluated for v in verdicts)
    print(f"{held} gates held, {len(failed)} failed, {skipped} not evaluated")
    return 1 if failed else 0


def cmd_list(args: argparse.Namespace) -> int:
    cases = _load(args.cases)
    print("cases:")
    for c in cases:
        print(f"  {c.name:24s} {c.kind:9s} features: {', '.join(sorted(c.features))}")
    print("engines:")
    for name in _engines(args.engines):
        a = get_adapter(name)
        print(f"  {name:10s} methods: {', '.join(a.methods)}")
        print(f"  {'':10s} capabilities: {', '.join(sorted(a.capabilities))}")
    return 0


def cmd_figures(args: argparse.Namespace) -> int:
    from truestep.figures import write_lecture_figures

    for path, caption in write_lecture_figures(Path(args.out) / "figures"):
        print(f"{path}: {caption}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="truestep", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="run the matrix, the analyses, and write the report")
    run.add_argument("--quick", action="store_true",
                     help="short sweeps of the quick cases, no energy or lecture figures (CI)")
    run.add_argument("--cases", default="*", help="glob(s) of case names, comma-separated")
    run.add_argument("--engines", default=None, help="engine names, comma-separated")
    run.add_argument("--out", default="reports", help="output directory (default: reports)")
    run.set_defaults(func=cmd_run)

    gate = sub.add_parser("gate", help="check every case's gates against results.csv")
    gate.add_argument("--results", default="reports/results.csv")
    gate.add_argument("--cases", default="*")
    gate.add_argument("-v", "--verbose", action="store_true", help="print gates that held too")
    gate.set_defaults(func=cmd_gate)

    lst = sub.add_parser("list", help="print cases, engines, capabilities and methods")
    lst.add_argument("--cases", default="*")
    lst.add_argument("--engines", default=None)
    lst.set_defaults(func=cmd_list)

    fig = sub.add_parser("figures", help="reproduce the lecture's figures")
    fig.add_argument("--out", default="reports")
    fig.set_defaults(func=cmd_figures)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (CaseError, UsageError) as err:
        print(f"truestep: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
