"""The functions behind every ``truestep`` command, for use from Python: each command is a
parser and a call into this module (``run``, ``gate``, ``engines`` for ``list``,
``save_baseline``, ``history_add``, ``history``, ``benchmark_json``, ``lecture_figures``,
``environment``).

Everything here takes and returns plain values and pandas tables::

    import truestep

    cases = truestep.load_cases("harmonic-oscillator,./my-cases")
    tables = truestep.run(cases, engines=["reference", "mine"], quick=True)
    verdicts = truestep.check(tables, gates="my-gates.toml")
    assert (verdicts["verdict"] != "fail").all()
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os
import sys
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path

import pandas as pd

from truestep.adapters import adapter_class, devices, engine_status, registered, resolve_engine, shadowed
from truestep.adapters.devices import DeviceError
from truestep.cases import Case, load_case, load_cases
from truestep.cases.limits import DEFAULT as _DEFAULT_LIMITS
from truestep.cases.loader import load_gates_file, read_gate
from truestep.ci.gate_report import GateInputError, GateReport, GateRequest
from truestep.ci.gates import GateResult, check_gates, refuse_unknown_engines, verdict_table
from truestep.ci.history import HistoryError
from truestep.ci.saved import BaselineRefused
from truestep.execution.bench_defaults import BUDGET_S as BENCH_BUDGET_S
from truestep.execution.bench_defaults import SIZES as BENCH_SIZES
from truestep.execution.cluster import ClusterError
from truestep.execution.experiment import Experiment, Finished, Tables
from truestep.execution.journal import JournalError
from truestep.numerics import own_run
from truestep.runtime import collector
from truestep.runtime.folder import OutRefused
from truestep.runtime.interrupts import Interrupted
from truestep.runtime.run_lock import LockBusy
from truestep.runtime.visible import visible
from truestep.tables.io import TableError

MAX_PARTICLES = _DEFAULT_LIMITS.particles
"""The most particles a scene may have under the default limits (``truestep bench``'s
largest size: the rain scene is read as a case)."""

__all__ = [
    "BENCH_BUDGET_S",
    "BENCH_SIZES",
    "MAX_PARTICLES",
    "BaselineRefused",
    "ClusterError",
    "DeviceError",
    "EngineInfo",
    "GateInputError",
    "GateReport",
    "GateRequest",
    "History",
    "HistoryError",
    "Interrupted",
    "JournalError",
    "LockBusy",
    "OutRefused",
    "TableError",
    "Tables",
    "bench",
    "benchmark_json",
    "check",
    "check_report_folder",
    "compare",
    "compile_ahead",
    "engines",
    "engines_for_run",
    "environment",
    "gate",
    "gate_results",
    "history",
    "history_add",
    "interruptible",
    "lecture_figures",
    "resumable",
    "run",
    "save_baseline",
    "select_cases",
    "select_engines",
    "shadowed",
]


def select_engines(
    engines: str | Iterable[str] | None = None, *, say: Callable[[str], None] | None = None
) -> list[str]:
    """Engine names to run: each item of ``engines`` (a registered name or
    ``module:Class``), or by default every registered engine that is installed; an
    engine left out because its library is missing is named through ``say``.

    Raises :class:`~truestep.adapters.UnknownEngine` for a name nothing registers and
    :class:`~truestep.adapters.EngineNotInstalled` for a named engine whose library is
    missing.
    """
    with collector.paused():  # the engines' imports: a million objects that stay
        return _select_engines(engines, say)


def _select_engines(engines: str | Iterable[str] | None, say: Callable[[str], None] | None) -> list[str]:
    if say is not None:
        for line in shadowed():
            say(line)
    if engines is None or (isinstance(engines, str) and not engines.strip()):
        chosen = []
        for name in registered():
            status = engine_status(name)
            if status == "installed":
                chosen.append(name)
            elif say is not None:
                say(f"engine {name} left out: {status}")
        return chosen
    items = engines.split(",") if isinstance(engines, str) else list(engines)
    names = []
    for item in (i.strip() for i in items if i.strip()):
        name = resolve_engine(item, say)
        adapter_class(name)  # raises EngineNotInstalled when its library is missing
        if name not in names:
            names.append(name)
    return names


def engines_for_run(
    engines: str | Iterable[str] | None = None, *, say: Callable[[str], None] | None = None
) -> list[str]:
    """:func:`select_engines` for a run in this process: the engines' modules are imported
    with the garbage collector paused and frozen after (they live to the process's end,
    so its later collections do not walk them again)."""
    with collector.paused():
        names = select_engines(engines, say=say)
        collector.settle()
    return names


@contextlib.contextmanager
def interruptible() -> Iterator[None]:
    """Inside, SIGTERM, SIGINT and SIGHUP stop what runs: the isolated children are killed
    and :class:`Interrupted` is raised (its ``signum``; ``published`` once the new report
    is in place). Main thread only; the previous handlers are restored on the way out.
    ``truestep run`` runs :func:`run` inside it."""
    from truestep.runtime.interrupts import handled

    with handled():
        yield


def resumable(out: str | Path) -> tuple[int, Path] | None:
    """What a run interrupted while writing its report to ``out`` left for ``resume``: the
    sweeps it finished and the journal's folder (``.<name>.partial`` beside ``out``), or
    ``None`` where there is no journal to continue."""
    from truestep.execution.journal import Journal

    kept = Journal(Path(out))
    return (kept.finished(), kept.dir) if kept.holds_run() else None


def check_report_folder(out: str | Path, *, flag: str = "--out") -> Path:
    """The folder ``out`` leads to, if :func:`run` can publish its report there; raises
    :class:`OutRefused` (one line that starts with ``flag``) before any work if not: a
    folder that is not a report truestep wrote, a mount point, a place this process cannot
    write, or too little free space beside it
    (:func:`truestep.runtime.folder.check_publishable`)."""
    from truestep.runtime.folder import check_publishable

    return check_publishable(Path(out), flag=flag)


def select_cases(
    selection: str | Iterable[str] = "*",
    *,
    quick: bool = False,
    limits: Iterable[str] = (),
    trust_limits: bool = False,
) -> list[Case]:
    """The cases of a selection as ``--cases`` takes it (names, globs, files, directories),
    under the cost limits ``limits`` (``KEY=VALUE`` items, as ``--limit`` takes them; past
    the ceiling a case file cannot pass only with ``trust_limits``): what ``truestep run``
    and ``truestep list`` run and list. With ``quick`` and the whole library (``"*"``),
    the cases marked for a quick run (every case where none is), as ``truestep run --quick``
    chooses. A bad limit item is a :class:`~truestep.cases.limits.LimitError`; a bad case file a
    :class:`~truestep.cases.errors.CaseError`, a selection that names nothing a
    :class:`~truestep.cases.errors.SelectionError` (both ``ValueError``, each one line)."""
    from truestep.cases.limits import parse_override

    chosen = load_cases(
        selection,
        limits=parse_override(list(limits), trusted=trust_limits),
        trust_limits=trust_limits,
    )
    if quick and selection == "*":
        chosen = [c for c in chosen if c.in_quick] or chosen
    return chosen


def _cases(cases: str | Iterable[str] | Iterable[Case]) -> list[Case]:
    items = [cases] if isinstance(cases, str) else list(cases)
    loaded = [c for c in items if isinstance(c, Case)]
    if items and len(loaded) == len(items):
        return loaded
    return load_cases([str(c) for c in items])


@own_run()
def run(
    cases: str | Iterable[str] | Iterable[Case] = "*",
    engines: str | Iterable[str] | None = None,
    *,
    quick: bool = False,
    analyses: bool = True,
    out: str | Path | None = None,
    progress: Callable[[str], None] | None = None,
    resume: str | Path | None = None,
    scheduler: str | None = None,
    budget: float | None = None,
    lecture_figures: bool = False,
    argv: list[str] | None = None,
    device: str | Mapping[str, str] | None = None,
) -> Tables:
    """Run the matrix (and, with ``analyses``, the stability searches, the restitution
    sweep and scaling) and return the tables; with ``out``, also write the report there, as
    ``truestep run --out`` does (a folder truestep may replace, locked for the run, else
    :class:`~truestep.runtime.folder.OutRefused` or :class:`~truestep.runtime.run_lock.LockBusy`),
    checkpointing each finished sweep in a journal beside it until the report is in place.
    ``truestep run`` is this function (:mod:`truestep.execution.experiment`).

    ``cases``: a selection as ``--cases`` takes it (names, globs, files, directories) or
    loaded :class:`Case` objects; ``engines``: as :func:`select_engines`; ``progress``:
    each result row's line and what the run says (default: a progress bar and the lines on
    standard error); ``resume``: a folder whose journal the run continues from (``out``
    defaults to it); ``scheduler``: a Dask scheduler or ``local:N``; ``budget``: the run's
    time budget, s; ``lecture_figures``: also draw the lecture's figures; ``argv``: the
    command line the report says reproduces the run; ``device``: where the engines that
    take a device compute, as ``--device`` takes it (``"cuda:0"``, ``"newton=cuda:0"``) or
    a mapping engine -> device (default: every engine on the CPU); a device this machine
    lacks, or an engine that takes none, is a :class:`~truestep.adapters.devices.DeviceError`
    raised before anything runs or is written.
    """
    say = progress or (lambda msg: print(visible(msg), file=sys.stderr))
    with collector.paused() as collecting:  # the engines' imports, until they are frozen
        chosen = _cases(cases)
        names = select_engines(engines, say=say)
        if out is None and resume is not None:
            out = resume
        on = devices.resolve(devices.parse(device), names, {n: adapter_class(n) for n in names})
        if on and scheduler is not None and not scheduler.startswith("local:"):
            raise DeviceError(
                f"{devices.words(on)} with --scheduler {scheduler}: the cluster's workers make their "
                "adapters in their own environment, where this run's devices do not reach; run "
                "the GPU engines without --scheduler, or with --scheduler local:N"
            )
        exp = Experiment(
            chosen,
            names,
            quick=quick,
            analyses=analyses,
            out=None if out is None else Path(out),
            resume=None if resume is None else Path(resume),
            scheduler=scheduler,
            budget=budget,
            argv=argv or ["run"],
            lecture_figures=lecture_figures,
            rows=progress,
            say=say,
            devices=on,
        )
        with collector.frozen(collecting=collecting), devices.used(on):
            return _run_locked(exp)


def _run_locked(exp: Experiment) -> Tables:
    """:func:`run`'s experiment, with its report folder checked and locked when it has one."""
    from truestep.execution.experiment import run_experiment

    if exp.out is None:
        return run_experiment(exp)
    exp.report = functools.partial(_publish, exp)
    from truestep.runtime.folder import check_out
    from truestep.runtime.run_lock import RunLock

    check_out(exp.out)
    locks = [
        RunLock(Path(p)) for p in dict.fromkeys(os.path.realpath(p) for p in (exp.out, exp.resume or exp.out))
    ]
    try:
        for lock in locks:
            lock.acquire()
        for lock in locks:
            if lock.took_over is not None:
                exp.say(f"{lock.out}: took over the lock of truestep run pid {lock.took_over}, which is gone")
        return run_experiment(exp)
    finally:
        for lock in locks:
            lock.release()


def _publish(exp: Experiment, run: Finished) -> None:
    """Write the report of ``run`` into ``exp.out`` (the experiment's ``report`` hook)."""
    from truestep.reporting.report import write_report

    assert exp.out is not None
    write_report(
        exp.out,
        exp.cases,
        run.results,
        run.tables,
        quick=exp.quick,
        argv=exp.argv,
        traces=None if exp.quick else run.traces,
        with_lecture_figures=exp.lecture_figures,
        findings=run.findings,
        progress=exp.rows,
        seconds=run.seconds,
    )


def gate_results(
    tables: Tables, *, gates: str | Path | Iterable | None = None, case_gates: bool = True
) -> list[GateResult]:
    """Every gate's verdict (:class:`~truestep.ci.gates.GateResult`) on ``tables``.

    ``gates``: a gates file, several, or gate dictionaries (the keys of a ``[[gates]]``
    table, with ``cases``); ``case_gates``: also check the gates in the case files. A
    gate naming an engine that is neither registered nor in the results is refused
    (:class:`~truestep.cases.CaseError`), as ``truestep gate`` refuses it.
    """
    extra: list = []
    for g in [] if gates is None else [gates] if isinstance(gates, str | Path | dict) else gates:
        if isinstance(g, dict):
            from truestep.cases.fields import Fields

            table = dict(g)
            patterns = table.pop("cases", "*")
            extra.append(
                (
                    [patterns] if isinstance(patterns, str) else list(patterns),
                    read_gate(Fields("<gate>", table), f"gates[{len(extra)}]"),
                )
            )
        else:
            extra += load_gates_file(g)
    refuse_unknown_engines(
        extra, set(registered()) | set(tables.results["engine"].astype(str)), "the results"
    )
    cases = tables.cases if case_gates else [dataclasses.replace(c, gates=[]) for c in tables.cases]
    return check_gates(cases, tables.results, tables.stability, tables.restitution, extra=extra)


def gate(request: GateRequest | str | Path, **options: object) -> GateReport:
    """Everything ``truestep gate`` checks on a run written to disk, as one
    :class:`~truestep.ci.gate_report.GateReport` (its verdicts, its baseline comparison, why
    it fails, and the console lines, JUnit, markdown and JSON ``truestep gate`` writes).

    ``request``: a :class:`~truestep.ci.gate_report.GateRequest`, or the run's
    ``results.csv`` with the request's other fields as keywords (``baseline=``, ``gates=``,
    ``declared_orders=`` ...). Raises :class:`~truestep.ci.gate_report.GateInputError` for
    a table or option that cannot be used (``truestep gate`` exits 2 on it)::

        report = truestep.gate("reports/results.csv", baseline="tests/baselines/quick")
        assert report.passed, "\n".join(report.console())
    """
    if not isinstance(request, GateRequest):
        fields = dict(options)
        if fields.get("baseline") is not None:
            fields["baseline"] = Path(str(fields["baseline"]))
        for name in ("gates", "tolerances", "limits"):
            if name in fields:
                value = fields[name]
                fields[name] = (value,) if isinstance(value, str | Path) else tuple(value)  # type: ignore[arg-type]
        request = GateRequest(Path(request), **fields)  # type: ignore[arg-type]
    from truestep.ci.gate_report import gate as check_request

    return check_request(request)


def check(
    tables: Tables, *, gates: str | Path | Iterable | None = None, case_gates: bool = True
) -> pd.DataFrame:
    """The gate verdicts as a table: one row per gate and engine/method
    (:data:`~truestep.ci.gates.GATE_COLUMNS`; ``verdict`` is ``pass``, ``fail`` or ``skip``)."""
    return verdict_table(gate_results(tables, gates=gates, case_gates=case_gates))


def compare(
    baseline: str | Path | Tables,
    current: str | Path | Tables,
    *,
    tolerances: dict[str, float] | None = None,
    time_against: str | None = None,
) -> pd.DataFrame:
    """What got worse or better from ``baseline`` to ``current`` (output directories or
    :class:`Tables`), one row per finding (see :mod:`truestep.ci.baseline`)."""
    from truestep.ci.baseline import compare as _compare
    from truestep.ci.baseline import read_tables

    def tables_of(x: str | Path | Tables) -> dict:
        if isinstance(x, Tables):
            return {
                name: table if len(table.columns) else None
                for name, table in (
                    ("results", x.results),
                    ("stability", x.stability),
                    ("restitution", x.restitution),
                )
            }
        return read_tables(Path(x))

    return _compare(
        tables_of(baseline), tables_of(current), tolerances=tolerances, time_against=time_against
    ).table()


@dataclasses.dataclass(frozen=True)
class EngineInfo:
    """What ``truestep list`` says of an engine: its ``status`` (``installed``, or why it
    cannot run here, with the pip line that adds it), and, installed, its ``methods`` and
    ``capabilities`` (empty where its adapter could not be made: ``status`` says why), and
    whether it takes a device (``devices``: ``truestep run --device`` can put it on a GPU,
    :func:`truestep.adapters.devices.takes_device`)."""

    name: str
    status: str
    methods: tuple[str, ...] = ()
    capabilities: tuple[str, ...] = ()
    devices: bool = False


def engines(names: Iterable[str] | None = None) -> Iterator[EngineInfo]:
    """:class:`EngineInfo` of each engine of ``names`` (default: every registered one), in
    that order, one at a time as each is looked at (``truestep list`` prints each line
    before it imports the next engine); a name nothing registers is ``unknown engine``."""
    from truestep.adapters import UnknownEngine, get_adapter

    for name in list(registered()) if names is None else list(names):
        status = engine_status(name) if name in registered() else "unknown engine"
        if status != "installed":
            yield EngineInfo(name, status)
            continue
        try:
            adapter = get_adapter(name)
        except UnknownEngine as err:  # its adapter could not be made
            yield EngineInfo(name, f"unusable: {err}")
            continue
        yield EngineInfo(
            name,
            status,
            tuple(map(str, adapter.methods)),
            tuple(sorted(map(str, adapter.capabilities))),
            devices.takes_device(adapter_class(name)),
        )


def save_baseline(results: str | Path, dest: str | Path) -> dict:
    """Keep a run's tables as a baseline in the folder ``dest`` (``truestep baseline
    save``): its provenance (:func:`truestep.ci.saved.save`). Raises
    :class:`~truestep.ci.saved.BaselineRefused` for a folder that is not new, empty or a
    baseline saved before, or a run that cannot be read."""
    from truestep.ci.saved import save

    return save(Path(results), Path(dest))


@dataclasses.dataclass(frozen=True)
class History:
    """One row's quantity over the commits of a history (``truestep history show``): the
    saved ``points`` (:class:`truestep.ci.history.Point`, oldest first), the indices of
    those where it ``stepped``, the relative ``tolerance`` a step exceeds, and, for a
    timing, the indices of those timed on ``another_machine`` than the point before, each
    with that machine in words (:func:`truestep.ci.history.machine_changes`)."""

    points: list
    stepped: list[int]
    tolerance: float
    another_machine: dict[int, str] = dataclasses.field(default_factory=dict)


def history_add(results: str | Path, store: str | Path = ".truestep-history") -> dict:
    """Save a run into the history ``store`` under the project's git revision
    (``truestep history add``): the entry written. Raises
    :class:`~truestep.ci.history.HistoryError` for a run or store that cannot be used."""
    from truestep.ci import history

    return history.add(Path(results), Path(store))


def history(
    quantity: str,
    case: str,
    engine: str,
    method: str,
    *,
    dt: float | None = None,
    store: str | Path = ".truestep-history",
    tolerance: float | None = None,
) -> History:
    """A row's ``quantity`` over the saved commits and where it stepped (``truestep history
    show``; ``tolerance`` defaults to the baseline comparison's for the quantity, else
    0.1). Raises :class:`~truestep.ci.history.HistoryError` for a store that cannot be
    read."""
    from truestep.ci import history as kept
    from truestep.ci.baseline import TOLERANCES
    from truestep.tables.spec import RESULTS

    points = kept.series(Path(store), quantity, case, engine, method, dt)
    tol = tolerance if tolerance is not None else TOLERANCES.get(quantity, 0.1)
    moved = kept.machine_changes(points) if quantity in RESULTS.where(machine=True) else {}
    return History(points, sorted(set(kept.steps([p.value for p in points], tol))), tol, moved)


def benchmark_json(results: str | Path) -> list[dict]:
    """A run's ``results.csv`` as the JSON github-action-benchmark reads
    (``customSmallerIsBetter``; ``truestep history export``). Raises
    :class:`~truestep.tables.io.TableError` for a table that cannot be read."""
    from truestep.ci import history
    from truestep.tables.io import read_table

    return history.benchmark_json(read_table(Path(results), "results", set()))


def lecture_figures(out: str | Path = "reports") -> list[tuple[Path, str]]:
    """Draw the lecture's figures into ``out/figures`` (``truestep figures``): each
    figure's path and caption, in slide order. Raises
    :class:`~truestep.runtime.folder.OutRefused` for a folder truestep may not write."""
    from truestep.figures.lecture import write_lecture_figures
    from truestep.runtime.folder import prepare

    return write_lecture_figures(prepare(Path(out)) / "figures")


def environment() -> dict[str, str]:
    """The variables that give this machine truestep's numbers (``truestep env``): each
    one's value here where it is set, else the value truestep's own processes set."""
    from truestep.numerics import environment as wanted

    return {key: os.environ.get(key, value) for key, value in wanted().items()}


def compile_ahead(say: Callable[[str], None] = print) -> list[str]:
    """Compile ahead what runs compile on first use (``truestep compile``): the reference's
    loops for every case of the library and of the figures on every core, and each
    installed engine's kernels in a forked process beside them; each line of progress
    through ``say``. The engines whose kernels failed to compile (``truestep compile``
    exits 1 on them)."""
    from truestep.execution.build_step import compile_everything
    from truestep.figures.scenes import FIGURE_CASE_DIR

    figures = [load_case(path) for path in sorted(FIGURE_CASE_DIR.glob("*.toml"))]
    return compile_everything([*load_cases("*"), *figures], say)


def bench(
    engines: Iterable[str],
    *,
    sizes: Iterable[float] | None = None,
    budget_s: float | None = None,
    out: str | Path = "bench",
    threads: int = 1,
    device: str | Mapping[str, str] | None = None,
) -> pd.DataFrame:
    """Particle-steps per second against n on the rain scene (``truestep bench``): the
    scaling table (:func:`truestep.execution.bench.scaling_table`; its ``attrs`` hold the
    copy bandwidth, bytes per particle-step, the time it took and its warm-ups), written
    with its figure into ``out`` (``scaling.csv`` and ``figures/scaling.png``, whose paths
    are ``attrs["csv"]`` and ``attrs["figure"]``). ``sizes`` default to :data:`BENCH_SIZES`, ``budget_s`` to
    :data:`BENCH_BUDGET_S`; ``threads``: the threads of the engines that take a count (the
    reference, whose tiles of independent particles then run that many at once; its rows
    say so); ``device``: where the engines that take one compute, as :func:`run` takes it
    (each row names its ``device``). Raises :class:`~truestep.runtime.folder.OutRefused`
    for a folder truestep may not write, and :class:`~truestep.adapters.devices.DeviceError`
    for a device this machine lacks or an engine that takes none, before anything runs."""
    from truestep.execution.bench import COLUMNS, scaling_plot, scaling_table
    from truestep.runtime.folder import check_out, prepare

    folder = Path(out)
    check_out(folder)
    names = list(engines)
    on = devices.resolve(devices.parse(device), names, {n: adapter_class(n) for n in names})
    with devices.used(on):
        table = scaling_table(
            names,
            sizes=list(BENCH_SIZES if sizes is None else sizes),
            budget_s=BENCH_BUDGET_S if budget_s is None else budget_s,
            threads=threads,
        )
    written = prepare(folder)
    table.attrs["csv"] = written / "scaling.csv"
    table.to_csv(table.attrs["csv"], index=False, columns=COLUMNS)
    table.attrs["figure"] = scaling_plot(
        table, table.attrs["bandwidth_bytes_per_s"], written / "figures" / "scaling.png"
    )
    return table
