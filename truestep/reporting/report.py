"""Write the tables, figures and the report pages of one ``truestep run``.

Every sentence that states a result is generated from the tables
(:mod:`truestep.reporting.sections`). The HTML page embeds its figures, so it is one file
that opens offline (:mod:`truestep.reporting.html`).
"""

from __future__ import annotations

import platform
import shutil
import subprocess
from collections.abc import Callable
from importlib import metadata
from pathlib import Path

import pandas as pd

from truestep.cases.case import Case
from truestep.measures.findings import Findings, find, speed_table, speed_tables
from truestep.measures.metrics import CONVERGING, PRE_ASYMPTOTIC, ROUND_OFF, ROUND_OFF_FLOAT32
from truestep.measures.picks import scorecard_table, survival
from truestep.numerics import PACKAGES as RECORDED_PACKAGES
from truestep.reporting import plots
from truestep.reporting.html import markdown_to_html
from truestep.reporting.markdown import folded, link, md_table, text, with_units
from truestep.reporting.run_record import RUN_FILE
from truestep.reporting.scaling import scaling_section
from truestep.reporting.sections import (
    conclusion_sentence,
    costly_lines,
    hard_case_line,
    methods_section,
    phase_sentence,
    refined_lines,
    same_scheme_section,
    scorecard_section,
    speed_section,
    summary,
    twin_section,
)
from truestep.runtime.isolation import (
    finish_isolated,
    run_isolated_all,
    start_isolated,
    untimed_workers,
)
from truestep.runtime.visible import visible
from truestep.tables.spec import TABLES

PACKAGES = (*RECORDED_PACKAGES, "matplotlib")
"""The packages whose versions the page's footer names: those a run records
(:data:`truestep.numerics.PACKAGES`: its numbers follow from them) and what draws its figures."""
__all__ = [
    "hard_case_line",
    "render_markdown",
    "speed_section",
    "speed_table",
    "speed_tables",
    "survival",
    "write_report",
]


def footer(argv: list[str]) -> str:
    """Machine, devices, package versions, git revision and the command that reproduces
    the page."""
    from truestep.adapters.devices import in_use
    from truestep.runtime import machine

    devices = in_use()
    where = (
        "every engine on the CPU"
        if not devices
        else ", ".join(f"{e} on {d}" for e, d in sorted(devices.items())) + ", every other engine on the CPU"
    )
    versions = []
    for p in PACKAGES:
        try:
            versions.append(f"{p} {metadata.version(p)}")
        except metadata.PackageNotFoundError:
            versions.append(f"{p} (not installed)")
    rev = git_revision()
    return (
        "---\n\n"
        f"Machine (what the timings depend on): {machine.line()}, Python {platform.python_version()}.  \n"
        f"Devices: {where} (the `device` column of each table).  \n"
        f"Packages: {', '.join(versions)}.  \n"
        f"Numerics: {numerics_line()}.  \n"
        f"Revision: {rev or 'unknown'}.  \n"
        f"Reproduce: {_command(argv)}\n"
    )


def numerics_line() -> str:
    """The floating-point environment in a few words (:mod:`truestep.numerics`)."""
    from truestep.numerics import fingerprint

    fp = fingerprint()
    simd = ", ".join(fp["numpy_simd"]) or "baseline only"
    return f"BLAS {'; '.join(fp['blas'])}; numpy SIMD dispatch {simd}" + (
        " (TRUESTEP_NUMERICS=native)" if fp["native"] else ""
    )


def _command(argv: list[str]) -> str:
    """``truestep ARGV`` as a code span; an argument that holds a backtick or a hidden
    character (a ``--cases`` item from outside) is shown as text instead."""
    line = f"truestep {' '.join(argv) if argv else 'run'}"
    return f"`{line}`" if "`" not in line and visible(line) == line else text(line)


def middle(values: list[float]) -> float | None:
    """The middle entry of a sweep (the geometric middle for an even count's upper half)."""
    return sorted(values)[len(values) // 2] if values else None


def _case_figures(
    cases: list[Case], results: pd.DataFrame, traces: dict | None, fig_dir: Path
) -> dict[str, tuple[Path | None, Path | None]]:
    """Draw each case's work-precision figure and, for conservative cases with traces,
    its energy figure; return their paths (``None`` where there is nothing to draw)."""
    out = {}
    for case in cases:
        df = results[results["case"] == case.name]
        fig = plots.work_precision(
            df, case.name, case.title, fig_dir / f"{case.name}-work-precision.png", unit=case.scene.error_unit
        )
        energy_fig = None
        if traces and case.conservative:
            steps = df.loc[df["dt_kind"] == "step", "dt"].dropna().astype(float).unique().tolist()
            tols = df.loc[df["dt_kind"] == "tolerance", "dt"].dropna().astype(float).unique().tolist()
            from truestep.measures.energy_scale import energy_scale

            energy_fig = plots.energy_over_time(
                traces,
                case.name,
                case.title,
                middle(steps),
                middle(tols),
                fig_dir / f"{case.name}-energy.png",
                scale=energy_scale(case),
            )
        out[case.name] = (fig, energy_fig)
    return out


def draw_case_figures(
    cases: list[Case], results: pd.DataFrame, traces: dict | None, fig_dir: Path
) -> dict[str, tuple[Path | None, Path | None]]:
    """:func:`_case_figures` for every case, the cases dealt out over one process per core
    (drawing is not timed). A share whose process fails is drawn again here."""
    workers = untimed_workers()
    shares = [cases[k::workers] for k in range(workers) if cases[k::workers]]
    outs = run_isolated_all(
        [(_case_figures, (share, results, traces, fig_dir), 600.0) for share in shares], workers
    )
    drawn: dict[str, tuple[Path | None, Path | None]] = {}
    for share, out in zip(shares, outs, strict=True):
        drawn.update(out.value if out.status == "ok" else _case_figures(share, results, traces, fig_dir))
    return drawn


SECTIONS = (
    "Which engine, which method",
    "Summary",
    "Measured orders of convergence",
    "Work against precision, per case",
    "Stability limits",
    "Restitution",
    "How cost grows with work",
    "Pairs not run",
    "The lecture's figures, reproduced",
    "How the numbers are made",
)
"""The report's top-level sections, in order (its table of contents)."""


def render_markdown(
    out: Path,
    cases: list[Case],
    results: pd.DataFrame,
    tables: dict[str, pd.DataFrame],
    *,
    quick: bool,
    argv: list[str],
    traces: dict | None = None,
    lecture_figures: LectureFigures = None,
    findings: Findings | None = None,
) -> str:
    """The report as Markdown; figures are written under ``out/figures``. It renders
    ``findings`` (default: :func:`truestep.measures.findings.find` of these tables) and computes
    nothing else.

    The question, a table of contents, the scorecard and its picks first; then the
    summary, and the detail behind it with every long table folded away.
    ``lecture_figures``: the lecture's figures as (path, caption) pairs, or a function
    that returns them once they are drawn (called after every other figure), or ``None``
    (a ``--quick`` run: not drawn).
    """
    fig_dir = out / "figures"
    found = findings if findings is not None else find(cases, results, tables)
    parts = ["# truestep report\n"]
    counts = results["status"].value_counts().to_dict()
    parts.append(
        "Which engine and which integrator should animate a scene: how far from the exact "
        "solution each one lands for the time it spends, how its energy drifts, how large a "
        "step it survives and how well it keeps a requested restitution. "
        f"{len(results)} runs over {results['case'].nunique()} cases and "
        f"{results['engine'].nunique()} engines: "
        + ", ".join(f"{v} {k}" for k, v in counts.items())
        + (". This is a `--quick` run: short sweeps." if quick else ".")
        + "\n"
    )
    speed = speed_section(cases, found.speed, found.phase_contact)
    titles = (
        list(SECTIONS[:2])
        + [line[3:].strip() for line in speed if line.startswith("## ")]
        + list(SECTIONS[2:])
    )
    parts.append("Contents: " + " · ".join(link(t) for t in titles) + "\n")
    parts += scorecard_section(cases, found, fig_dir)
    parts += summary(cases, found, tables)
    parts += speed
    orders = found.orders
    parts.append("## Measured orders of convergence\n")
    parts.append(
        "Least-squares slope of log(error) against log(dt) over the sweep, leaving "
        f"out errors above {PRE_ASYMPTOTIC:g} of the case's scale (not yet converged) and below "
        f"{ROUND_OFF:g} of it ({ROUND_OFF_FLOAT32:g} for a float32 engine: round-off).\n"
    )
    parts += refined_lines(results.attrs.get("refined") or [])
    fitted = orders.dropna(subset=["order"])
    disagree = fitted[fitted["agrees"] == "no"]
    flat = disagree[disagree["finest"] < CONVERGING]
    parts.append(
        f"Against the orders the engines declare (on smooth cases with an exact "
        f"solution): {int((fitted['agrees'] == 'yes').sum())} fits agree, "
        f"{len(disagree)} do not"
        + (
            ": "
            + "; ".join(
                f"{r.case} {text(r.engine)} / {text(r.method)} {r.order:.2f} (declared {r.declared:g}"
                + (f"; dt^{r.finest:.2f} at the finest steps" if r.finest < CONVERGING else "")
                + ")"
                for r in disagree.itertuples(index=False)
            )
            if len(disagree)
            else ""
        )
        + ".\n"
    )
    if len(flat):
        parts.append(
            f"Of those, {len(flat)} have an error that does not fall with the step at their "
            f"finest steps (a local order below {CONVERGING:g}). A run carries such a sweep on "
            "to finer steps where every row of it ran `ok` (the sweeps above), and `truestep "
            "gate --declared-orders` fails it if the error stays flat there, well above "
            "round-off: a bug that leaves a floor under the error (a wrong rest length) "
            "converges to something else. It reports the gate as not evaluated where a row "
            "could not be carried on (a row not `ok`), where the finer errors are round-off's, "
            "or where the error is still beginning to fall at the finest step run.\n"
        )
    parts.append(folded(f"{len(fitted)} fitted orders", md_table(fitted)))
    parts += same_scheme_section(found.peers)
    parts += twin_section(found.twins)
    parts.append("## Work against precision, per case\n")
    parts += costly_lines(found.costly)
    drawn = draw_case_figures(cases, results, traces, fig_dir)
    for case in cases:
        df = results[results["case"] == case.name]
        parts.append(f"### {case.name}: {text(case.title)}\n")
        parts.append(text(case.description) + "\n")
        if case.hard:
            parts.append(f"What makes it hard: {text(case.hard)}\n")
        fig, energy_fig = drawn[case.name]
        if fig is not None:
            parts.append(f"![work-precision plot of {case.name}](figures/{fig.name})\n")
        if energy_fig is not None:
            parts.append(f"![energy over time of {case.name}](figures/{energy_fig.name})\n")
        shown = df[~df["status"].isin(["unsupported", "skipped"])]
        cols = [
            "engine",
            "method",
            "dt",
            "dt_kind",
            "status",
            "error",
            "energy_drift",
            "nfev",
            "wall_s",
            "t_fail",
            *case.properties,
        ]
        parts.append(folded(f"{len(shown)} runs of {case.name}", md_table(with_units(shown[cols]))))
        parts += _case_notes(case, shown, found)
    stab = tables.get("stability")
    parts.append("## Stability limits\n")
    if stab is not None and len(stab):
        parts.append(
            "Largest stable step by bisection over each case's horizon (see "
            f"{link('How the numbers are made')}). `dt_limit_exact` is 0 where the "
            "method is unstable at every step and inf where it is stable at every "
            "step.\n"
        )
        for case_name in stab["case"].unique():
            fig = plots.stability_bars(stab, case_name, fig_dir / f"{case_name}-stability.png")
            if fig is not None:
                parts.append(f"![stability limits of {case_name}](figures/{fig.name})\n")
        parts.append(folded(f"{len(stab)} searches", md_table(with_units(stab))))
    else:
        parts.append("No case of this run has a stability search.\n")
    rest = tables.get("restitution")
    parts.append("## Restitution\n")
    if rest is not None and len(rest):
        parts.append(
            "Restitution per bounce of a dropped ball (see "
            f"{link('How the numbers are made')}), from rebound speeds and from apex "
            "heights.\n"
        )
        fig = plots.restitution_plot(rest, fig_dir / "restitution.png")
        if fig is not None:
            parts.append(f"![requested against measured restitution](figures/{fig.name})\n")
        parts.append(folded(f"{len(rest)} bounces", md_table(with_units(rest))))
    else:
        parts.append("Not run: no case of this run is tagged `restitution`.\n")
    parts += scaling_section(tables.get("scaling"), fig_dir)
    absent = results[results["status"].isin(["unsupported", "skipped"])]
    parts.append("## Pairs not run\n")
    parts.append(
        "Every case, engine and method that was not run, and why: `unsupported` "
        "names the features the engine cannot model.\n"
    )
    parts.append(
        folded(
            f"{len(absent)} pairs",
            md_table(absent[["case", "engine", "method", "status", "missing", "message"]]),
        )
    )
    if callable(lecture_figures):
        lecture_figures = lecture_figures()
    parts.append("## The lecture's figures, reproduced\n")
    if lecture_figures is None:
        parts.append("Not redrawn in a `--quick` run: `truestep figures` draws them.\n")
    for path, caption in lecture_figures or []:
        parts.append(f"![{caption}](figures/{path.name})\n")
        parts.append(f"{caption}\n")
    parts += methods_section(cases)
    parts.append(footer(argv))
    return "\n".join(parts)


LectureFigures = list[tuple[Path, str]] | Callable[[], list[tuple[Path, str]]] | None


def _case_notes(case: Case, shown: pd.DataFrame, found: Findings) -> list[str]:
    """The sentences under a case's table: its conclusion, its contact's phases, and the
    error floor of the run it is measured against, where the findings hold them."""
    notes = []
    if case.name in found.conclusions:
        notes.append(conclusion_sentence(case, found.conclusions[case.name]))
    if contact := phase_sentence(case, shown, found.phase_contact):
        notes.append(contact)
    if case.name in found.floors:
        notes.append(found.floors[case.name].words())
    return notes


def start_lecture_figures(fig_dir: Path) -> Callable[[], list[tuple[Path, str]]]:
    """Start drawing the lecture's figures in child processes (one per core, beside this
    one drawing the report's own figures); return the function that waits for them.

    A share whose process fails is drawn again here, so an error surfaces as in a
    sequential run.
    """
    from truestep.figures.lecture import FIGURES, lecture_figure_shares, write_lecture_figures

    shares = lecture_figure_shares(untimed_workers())
    started = [(names, start_isolated(write_lecture_figures, (fig_dir, names), 600.0)) for names in shares]

    def collect() -> list[tuple[Path, str]]:
        drawn: list[tuple[Path, str]] = []
        for names, run in started:
            out = finish_isolated(run)
            drawn += out.value if out.status == "ok" else write_lecture_figures(fig_dir, names)
        rank = {name: k for k, (name, _) in enumerate(FIGURES)}
        return sorted(drawn, key=lambda pc: rank[pc[0].stem])

    return collect


def git_revision() -> str:
    """The short git revision of truestep's source, or ``""`` outside a checkout."""
    try:
        return subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=False,
            cwd=Path(__file__).parent,
        ).stdout.strip()
    except OSError:
        return ""


def run_record(
    cases: list[Case],
    results: pd.DataFrame,
    *,
    quick: bool,
    argv: list[str],
    seconds: dict[str, float] | None = None,
    rows: dict[str, int] | None = None,
) -> dict:
    """``run.json``: the truestep version and revision, the command, whether it was quick,
    the cases and engines the run was asked for (in order), the floating-point
    environment (:func:`truestep.numerics.fingerprint`): with equal ``numerics`` and
    revision, two runs' non-timing columns are equal bit for bit; the machine the timings
    were measured on (``machine``: :func:`truestep.runtime.machine.describe`, which decides
    no non-timing number); and, where given, the
    ``precision`` of each engine's state (the facts a verdict on these tables reads, also
    where that engine is not installed: :func:`truestep.measures.metrics.recorded_precision`);
    each method's declared facts, peers and glossary notes (``method_facts``, ``peers``,
    ``method_notes``: :mod:`truestep.measures.engine_facts`, read back the same way);
    ``devices``, the engines the run put off the CPU and their devices (``--device``; absent
    where every engine computed on the CPU);
    wall time of the run's phases before the report (``seconds``: ``sweep``, ``analyses``;
    ``compile``, the part of the sweep spent compiling ahead of the first timed run;
    ``sweep <engine>``, the seconds each engine's sweep processes ran, each from its fork
    to its end with its adapter's ``prepare``, which overlap where sweeps share the cores;
    ``analyses stability`` and ``analyses restitution``, from the first search or drop's
    start to the last one's end, which overlap ``sweep`` where they run beside its timed
    runs, and ``analyses stability <engine>`` and ``analyses restitution <engine>``, the
    seconds of each engine's search and drop processes, counted as the sweep's are;
    ``analyses scaling``; the report's own time is not in
    it, it is being written); ``refined``, the methods whose sweeps were carried on to finer steps
    because their order was not reached yet (:mod:`truestep.execution.refine`); ``rows``,
    the row count of each table written (:func:`truestep.tables.io.check_recorded_rows`:
    a table cut short at the end of a row is refused)."""
    from truestep import __version__
    from truestep.adapters import shadowed
    from truestep.adapters.devices import in_use
    from truestep.measures import engine_facts
    from truestep.measures.metrics import precision_of
    from truestep.numerics import fingerprint
    from truestep.runtime import machine

    return {
        "truestep": __version__,
        "revision": git_revision(),
        "command": "truestep " + " ".join(argv or ["run"]),
        "quick": bool(quick),
        "cases": [c.name for c in cases],
        "engines": list(dict.fromkeys(results["engine"].astype(str))) if len(results) else [],
        "numerics": fingerprint(),
        "machine": machine.describe(),
        "precision": {e: precision_of(e) for e in dict.fromkeys(results["engine"].astype(str))}
        if len(results)
        else {},
        **engine_facts.record(dict.fromkeys(results["engine"].astype(str)) if len(results) else [], cases),
        **({"devices": in_use()} if in_use() else {}),
        **({"shadowed": shadowed()} if shadowed() else {}),
        **({"refined": list(results.attrs["refined"])} if results.attrs.get("refined") else {}),
        **({"seconds": {k: round(float(v), 3) for k, v in seconds.items()}} if seconds else {}),
        **({"rows": dict(rows)} if rows else {}),
    }


def write_report(
    out: Path,
    cases: list[Case],
    results: pd.DataFrame,
    tables: dict[str, pd.DataFrame],
    *,
    quick: bool,
    argv: list[str],
    traces: dict | None = None,
    with_lecture_figures: bool = True,
    findings: Findings | None = None,
    progress: Callable[[str], None] | None = None,
    seconds: dict[str, float] | None = None,
) -> None:
    """Write results.csv, stability.csv, restitution.csv, scaling.csv (when the run made
    the table), scorecard.csv, index.md, index.html, figures/ and run.json (with the run's ``seconds``
    per phase, :func:`run_record`); each of its steps is a line with done /
    total and the time left (:class:`~truestep.execution.progress.Progress`; ``progress``
    takes the lines instead).

    The whole new report is written into a staging folder beside ``out`` and put in
    place of the old one as a whole (:mod:`truestep.runtime.publish`): at every instant ``out``
    holds either the whole previous report or the whole new one, also when the process
    is killed. ``out`` must be a folder truestep may replace
    (:func:`truestep.runtime.folder.check_out`: absent, empty, or a report truestep wrote
    holding nothing else), checked again here, after the run; the new report carries the
    marker (:data:`truestep.runtime.folder.MARKER`). On failure or interruption the
    staging folder is removed and the children still drawing are killed.
    """
    from truestep.execution.progress import Progress
    from truestep.runtime import faults, publish
    from truestep.runtime.folder import check_out, write_marker
    from truestep.runtime.isolation import kill_children

    out = publish.target(out)
    publish.recover(out)
    check_out(out)
    stage = publish.new_stage(out)
    bar = Progress(4, "report", say=progress)
    try:
        write_marker(stage)
        results.to_csv(stage / "results.csv", index=False)
        for name in ("stability", "restitution"):  # a run without analyses: a header, no rows
            table = tables[name] if len(tables[name].columns) else TABLES[name].frame([])
            table.to_csv(stage / f"{name}.csv", index=False)
        scaling = tables.get("scaling")
        if scaling is not None and len(scaling):
            from truestep.execution.bench import COLUMNS as SCALING_COLUMNS

            scaling.to_csv(stage / "scaling.csv", index=False, columns=SCALING_COLUMNS)
        import json

        written = {"results": len(results), **{n: len(tables[n]) for n in ("stability", "restitution")}}
        if scaling is not None and len(scaling):
            written["scaling"] = len(scaling)
        record = run_record(cases, results, quick=quick, argv=argv, seconds=seconds, rows=written)
        (stage / RUN_FILE).write_text(json.dumps(record, indent=1) + "\n")
        findings = findings if findings is not None else find(cases, results, tables)
        scorecard_table(findings.scorecard, findings.fidelity).to_csv(stage / "scorecard.csv", index=False)
        faults.point("report-csv")
        bar.done("tables written")
        lecture = start_lecture_figures(stage / "figures") if with_lecture_figures else None
        md = render_markdown(
            stage,
            cases,
            results,
            tables,
            quick=quick,
            argv=argv,
            traces=traces,
            lecture_figures=lecture,
            findings=findings,
        )
        faults.point("report-figures")
        (stage / "index.md").write_text(md)
        bar.done(f"figures drawn, index.md written ({len(cases)} cases)")
        faults.point("report-index")
        (stage / "index.html").write_text(markdown_to_html(md, stage))
        bar.done("index.html written")
        publish.swap(stage, out)
        bar.done(f"published in {out}")
    except BaseException:
        kill_children()
        raise
    finally:
        bar.close()
        shutil.rmtree(stage, ignore_errors=True)
