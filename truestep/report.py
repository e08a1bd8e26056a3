"""Write the tables, figures and the report pages of one ``truestep run``.

Every sentence that states a result is generated from the tables. The HTML page embeds
its figures, so it is one file that opens offline.
"""

from __future__ import annotations

import base64
import html
import os
import platform
import re
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd

from truestep import plots
from truestep.cases.case import Case
from truestep.isolation import (
    finish_isolated,
    run_isolated_all,
    start_isolated,
    untimed_workers,
)
from truestep.metrics import fit_order
from truestep.picks import (
    ACCURACY_TARGETS,
    SURVIVAL_ENERGY,
    SURVIVAL_ERROR,
    cheapest,
    survival,
)

PACKAGES = ("numpy", "scipy", "pandas", "matplotlib", "numba", "pymunk", "pybullet", "mujoco")


def _fmt(x: object, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "" if x is None or np.isnan(x) else ("inf" if x > 0 else "-inf")
    if isinstance(x, float | np.floating):
        return f"{x:.{digits}g}"
    return str(x)


def md_table(df: pd.DataFrame) -> str:
    """A pipe table with numbers to three significant digits."""
    if df.empty:
        return "_(no rows)_\n"
    head = "| " + " | ".join(str(c) for c in df.columns) + " |"
    sep = "|" + "|".join("---" for _ in df.columns) + "|"
    body = ["| " + " | ".join(_fmt(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join([head, sep, *body]) + "\n"


def orders_table(results: pd.DataFrame, cases: list[Case]) -> pd.DataFrame:
    """Fitted order of convergence per case, engine and fixed-step method."""
    rows = []
    scales = {c.name: c.error_scale for c in cases}
    steps = results[(results["dt_kind"] == "step") & (results["status"] == "ok")]
    for (case, engine, method), g in steps.groupby(["case", "engine", "method"], sort=False):
        order = fit_order(g["dt"].astype(float), g["error"].astype(float),
                          scale=scales.get(case, 1.0))
        rows.append({"case": case, "engine": engine, "method": method, "order": order,
                     "points": int(g["error"].notna().sum())})
    return pd.DataFrame(rows, columns=["case", "engine", "method", "order", "points"])


def footer(argv: list[str]) -> str:
    """Machine, package versions, git revision and the command that reproduces the page."""
    versions = []
    for p in PACKAGES:
        try:
            versions.append(f"{p} {metadata.version(p)}")
        except metadata.PackageNotFoundError:
            versions.append(f"{p} (not installed)")
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, check=False, cwd=Path(__file__).parent).stdout.strip()
    except OSError:
        rev = ""
    return (
        "---\n\n"
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, {platform.system()} "
        f"{platform.release()}, Python {platform.python_version()}.  \n"
        f"Packages: {', '.join(versions)}.  \n"
        f"Revision: {rev or 'unknown'}.  \n"
        f"Reproduce: `truestep {' '.join(argv) if argv else 'run'}`\n"
    )


def middle(values: list[float]) -> float | None:
    """The middle entry of a sweep (the geometric middle for an even count's upper half)."""
    return sorted(values)[len(values) // 2] if values else None


def _run_label(r: pd.Series) -> str:
    """``engine / method (dt ...)`` (a tolerance for adaptive rows)."""
    kind = "tol" if r["dt_kind"] == "tolerance" else "dt"
    return f"{r['engine']} / {r['method']} ({kind} {_fmt(float(r['dt']))})"


def cheapest_table(cases: list[Case], results: pd.DataFrame) -> pd.DataFrame:
    """Per case, the cheapest run by wall time that reaches each accuracy target, with
    its time, and the cheapest by evaluations where it is another run."""
    picks = cheapest(results, cases)
    rows = []
    for case in cases:
        mine = picks[picks["case"] == case.name]
        if mine.empty:
            continue
        row = {"case": case.name}
        for target in ACCURACY_TARGETS:
            wall = mine[(mine["target"] == target) & (mine["by"] == "wall_s")].iloc[0]
            evals = mine[(mine["target"] == target) & (mine["by"] == "nfev")].iloc[0]
            if not wall["engine"]:
                row[f"error <= {target:g} scale"] = "none of the runs"
                continue
            cell = f"{_run_label(wall)}, {_fmt(float(wall['wall_s']))} s"
            key = ("engine", "method", "dt")
            if [wall[k] for k in key] != [evals[k] for k in key]:
                cell += f"; fewest evaluations: {_run_label(evals)}, {int(evals['nfev'])}"
            row[f"error <= {target:g} scale"] = cell
        rows.append(row)
    return pd.DataFrame(rows)


def summary(cases: list[Case], results: pd.DataFrame, tables: dict[str, pd.DataFrame]) -> list[str]:
    """The summary, every sentence generated from the tables."""
    lines = ["## Summary\n"]
    table = cheapest_table(cases, results)
    if len(table):
        lines.append("The cheapest run that reaches each accuracy (error at most 1e-2, 1e-4 "
                     "and 1e-6 of the case's scale), by wall time; where another run needs "
                     "fewer derivative evaluations it is named too:\n")
        lines.append(md_table(table))
    rest = tables.get("restitution")
    if rest is not None and len(rest):
        r = rest[(rest["status"] == "ok") & (rest["bounce"] == 1)].dropna(subset=["e_measured"])
        if len(r):
            r = r.assign(gap=(r["e_measured"] - r["e_set"]).abs())
            worst = r.sort_values("gap", ascending=False).drop_duplicates(["engine", "method"]).head(4)
            lines.append("Widest gaps between requested and measured restitution (first bounce):\n")
            for w in worst.itertuples(index=False):
                lines.append(f"- {w.engine} / {w.method}: requested {w.e_set:g}, measured "
                             f"{w.e_measured:.3f} at dt {_fmt(float(w.dt))} s.")
            lines.append("")
    hard = [c for c in cases if c.hard]
    if hard:
        lines.append(f"Hard cases: the largest step of the sweep at which each engine/method "
                     f"survives: it finishes stable, does not fail what the scene tests (such "
                     f"as tunnelling), its error is at most {SURVIVAL_ERROR:g} of the case's "
                     f"scale and its energy error at most {SURVIVAL_ENERGY:g} of its energy:\n")
        for c in hard:
            lines.append(hard_case_line(c, results))
        lines.append("")
    return lines


def hard_case_line(case: Case, results: pd.DataFrame) -> str:
    """One summary bullet: engine/methods grouped by the largest step they survive."""
    s = survival(case, results)
    if s.empty:
        return f"- **{case.name}**: no fixed-step runs."
    groups = []
    for dt, g in sorted(s.dropna(subset=["dt_survived"]).groupby("dt_survived"),
                        key=lambda kv: -kv[0]):
        names = ", ".join(f"{e}/{m}" for e, m in zip(g["engine"], g["method"], strict=True))
        groups.append(f"{_fmt(float(dt))} s: {names}")
    never = s[s["dt_survived"].isna()]
    if len(never):
        names = ", ".join(f"{e}/{m} ({f or 'failed'})"
                          for e, m, f in zip(never["engine"], never["method"], never["failure"],
                                             strict=True))
        groups.append(f"at no step of the sweep: {names}")
    return f"- **{case.name}**: " + "; ".join(groups) + "."


def speed_table(case: Case, results: pd.DataFrame, engine: str, method: str) -> pd.DataFrame:
    """Particle-steps per second of every engine/method beside ``engine/method``'s, per step.

    Columns: ``dt`` (s), ``engine``, ``method``, ``wall_s`` (s), ``particle_steps_per_s``
    (particles x steps / wall time), ``error`` and ``slower_by`` (that row's wall time over
    ``engine/method``'s at the same step). Rows with status ok, fixed steps only.
    """
    n = case.model.n if case.model is not None else 1
    d = results[(results["case"] == case.name) & (results["dt_kind"] == "step")
                & (results["status"] == "ok")].dropna(subset=["wall_s"])
    rows = []
    for dt, g in d.groupby(d["dt"].astype(float)):
        base = g[(g["engine"] == engine) & (g["method"] == method)]
        base_wall = float(base["wall_s"].iloc[0]) if len(base) else np.nan
        for r in g.sort_values("wall_s").itertuples(index=False):
            rows.append({"dt": dt, "engine": r.engine, "method": r.method, "wall_s": r.wall_s,
                         "particle_steps_per_s": n * r.steps / r.wall_s, "error": r.error,
                         "slower_by": r.wall_s / base_wall})
    return pd.DataFrame(rows, columns=["dt", "engine", "method", "wall_s",
                                       "particle_steps_per_s", "error", "slower_by"])


def speed_section(cases: list[Case], results: pd.DataFrame) -> list[str]:
    """For each case with a ``speedup`` gate: what modelling only what the scene needs is
    worth, the gated method against every engine at the same steps."""
    parts: list[str] = []
    for case in cases:
        for g in (g for g in case.gates if g.kind == "speedup"):
            table = speed_table(case, results, g.engine, g.method)
            if table.empty:
                continue
            at = table[np.isclose(table["dt"], g.dt)]
            others = at[at["engine"] != g.engine]
            parts.append(f"## What modelling only what a scene needs is worth: {case.name}\n")
            parts.append(
                f"{case.title}: {g.engine} / {g.method} runs only what the scene needs (here "
                "a compiled loop over independent particles, on one thread like the "
                "engines), the engines their general machinery (broad phase, contact "
                "solver, one body per particle). Each row: "
                "particle-steps per second at the same step and the error against the exact "
                "bounce solution; `slower_by` is its wall time over "
                f"{g.engine} / {g.method}'s.\n")
            if len(others):
                fastest = others.sort_values("wall_s").iloc[0]
                parts.append(
                    f"At dt {_fmt(g.dt)} s the fastest engine, {fastest.engine} / "
                    f"{fastest.method}, takes {fastest.slower_by:.0f} times as long as "
                    f"{g.engine} / {g.method} (gate: at least {g.params['min']:g} times).\n")
            parts.append(md_table(table))
    return parts


def _case_figures(cases: list[Case], results: pd.DataFrame, traces: dict | None,
                  fig_dir: Path) -> dict[str, tuple[Path | None, Path | None]]:
    """Draw each case's work-precision figure and, for conservative cases with traces,
    its energy figure; return their paths (``None`` where there is nothing to draw)."""
    out = {}
    for case in cases:
        df = results[results["case"] == case.name]
        fig = plots.work_precision(df, case.name, case.title,
                                   fig_dir / f"{case.name}-work-precision.png")
        energy_fig = None
        if traces and case.conservative:
            steps = df.loc[df["dt_kind"] == "step", "dt"].dropna().astype(float).unique().tolist()
            tols = df.loc[df["dt_kind"] == "tolerance", "dt"].dropna().astype(float).unique().tolist()
            energy_fig = plots.energy_over_time(traces, case.name, case.title, middle(steps),
                                                middle(tols), fig_dir / f"{case.name}-energy.png")
        out[case.name] = (fig, energy_fig)
    return out


def draw_case_figures(cases: list[Case], results: pd.DataFrame, traces: dict | None,
                      fig_dir: Path) -> dict[str, tuple[Path | None, Path | None]]:
    """:func:`_case_figures` for every case, the cases dealt out over one process per core
    (drawing is not timed). A share whose process fails is drawn again here."""
    workers = untimed_workers()
    shares = [cases[k::workers] for k in range(workers) if cases[k::workers]]
    outs = run_isolated_all([(_case_figures, (share, results, traces, fig_dir), 600.0)
                             for share in shares], workers)
    drawn: dict[str, tuple[Path | None, Path | None]] = {}
    for share, out in zip(shares, outs, strict=True):
        drawn.update(out.value if out.status == "ok"
                     else _case_figures(share, results, traces, fig_dir))
    return drawn


def render_markdown(out: Path, cases: list[Case], results: pd.DataFrame,
                    tables: dict[str, pd.DataFrame], *, quick: bool, argv: list[str],
                    traces: dict | None = None,
                    lecture_figures: LectureFigures = None) -> str:
    """The report as Markdown; figures are written under ``out/figures``.

    ``lecture_figures``: the lecture's figures as (path, caption) pairs, or a function
    that returns them once they are drawn (called after every other figure), or ``None``
    (a ``--quick`` run: not drawn).
    """
    fig_dir = out / "figures"
    parts = ["# truestep report\n"]
    counts = results["status"].value_counts().to_dict()
    parts.append(
        "Which engine and which integrator should animate a scene: how far from the exact "
        "solution each one lands for the time it spends, how its energy drifts, how large a "
        "step it survives and how well it keeps a requested restitution. "
        f"{len(results)} runs over {results['case'].nunique()} cases and "
        f"{results['engine'].nunique()} engines: "
        + ", ".join(f"{v} {k}" for k, v in counts.items())
        + (". This is a `--quick` run: short sweeps." if quick else ".") + "\n"
    )
    parts.append("Comparisons are normalised: scenes are built outside the timed region; "
                 "every run is warmed up and timed as the median of repeats, alone on the "
                 "machine; engine defaults that would distort a comparison are switched off "
                 "(pybullet's linear and angular damping; pymunk's pixel-scale collision "
                 "slop; MuJoCo's joint armature, damping and friction loss) and no damping "
                 "or clamp is added anywhere.\n")
    parts += summary(cases, results, tables)
    parts += speed_section(cases, results)
    orders = orders_table(results, cases)
    parts.append("## Measured orders of convergence\n")
    parts.append("Least-squares slope of log(error) against log(dt) over the sweep, leaving "
                 "out errors above a tenth of the case's scale (not yet converged) and below "
                 "1e-11 of it (round-off).\n")
    parts.append(md_table(orders.dropna(subset=["order"])))
    parts.append("## Work against precision, per case\n")
    drawn = draw_case_figures(cases, results, traces, fig_dir)
    for case in cases:
        df = results[results["case"] == case.name]
        parts.append(f"### {case.name}: {case.title}\n")
        parts.append(" ".join(case.description.split()) + "\n")
        if case.hard:
            parts.append(f"What makes it hard: {' '.join(case.hard.split())}\n")
        fig, energy_fig = drawn[case.name]
        if fig is not None:
            parts.append(f"![work-precision plot of {case.name}](figures/{fig.name})\n")
        if energy_fig is not None:
            parts.append(f"![energy over time of {case.name}](figures/{energy_fig.name})\n")
        shown = df[~df["status"].isin(["unsupported", "skipped"])]
        cols = ["engine", "method", "dt", "dt_kind", "status", "error", "energy_drift", "nfev",
                "wall_s", "t_fail", *case.properties]
        parts.append(md_table(shown[cols]))
    stab = tables.get("stability")
    if stab is not None and len(stab):
        parts.append("## Stability limits\n")
        parts.append("Largest stable step by bisection over a fixed horizon (at least 5000 "
                     "steps); a run is unstable when its state goes non-finite or its energy "
                     "peaks higher in the second half of the run than in the first. "
                     "`dt_limit_exact` is 0 where the method is unstable at every step and "
                     "inf where it is stable at every step.\n")
        for case_name in stab["case"].unique():
            fig = plots.stability_bars(stab, case_name, fig_dir / f"{case_name}-stability.png")
            if fig is not None:
                parts.append(f"![stability limits of {case_name}](figures/{fig.name})\n")
        parts.append(md_table(stab))
    rest = tables.get("restitution")
    if rest is not None and len(rest):
        parts.append("## Restitution\n")
        parts.append("A ball of radius 0.05 m dropped from 1 m onto a floor; restitution per "
                     "bounce from rebound speeds and from apex heights, both extrapolated "
                     "ballistically to contact height.\n")
        fig = plots.restitution_plot(rest, fig_dir / "restitution.png")
        if fig is not None:
            parts.append(f"![requested against measured restitution](figures/{fig.name})\n")
        parts.append(md_table(rest))
    absent = results[results["status"].isin(["unsupported", "skipped"])]
    if len(absent):
        parts.append("## Pairs not run\n")
        parts.append("Every case, engine and method that was not run, and why: `unsupported` "
                     "names the features the engine cannot model.\n")
        parts.append(md_table(absent[["case", "engine", "method", "status", "missing", "message"]]))
    if callable(lecture_figures):
        lecture_figures = lecture_figures()
    if lecture_figures is None:
        parts.append("## The lecture's figures, reproduced\n")
        parts.append("Not redrawn in a `--quick` run: `truestep figures` draws them.\n")
    if lecture_figures:
        parts.append("## The lecture's figures, reproduced\n")
        for path, caption in lecture_figures:
            parts.append(f"![{caption}](figures/{path.name})\n")
            parts.append(f"{caption}\n")
    parts.append(footer(argv))
    return "\n".join(parts)


def markdown_to_html(md: str, base: Path) -> str:
    """A small Markdown-to-HTML conversion for the report's own subset, images inlined."""
    out: list[str] = []
    lines = md.splitlines()
    i = 0

    def inline(text: str) -> str:
        text = html.escape(text)
        text = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", text)
        text = re.sub(r"`(.+?)`", r"<code>\1</code>", text)
        return text.replace("  ", "<br>") if text.endswith("  ") else text

    while i < len(lines):
        line = lines[i]
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            out.append(f"<h{level}>{inline(line[level:].strip())}</h{level}>")
        elif line.startswith("!["):
            m = re.match(r"!\[(.*?)\]\((.*?)\)", line)
            if m:
                data = base64.b64encode((base / m.group(2)).read_bytes()).decode()
                out.append(f'<figure><img alt="{html.escape(m.group(1))}" '
                           f'src="data:image/png;base64,{data}"></figure>')
        elif line.startswith("|"):
            rows = []
            while i < len(lines) and lines[i].startswith("|"):
                rows.append([c.strip() for c in lines[i].strip("|").split("|")])
                i += 1
            head, body = rows[0], rows[2:]
            out.append("<table><thead><tr>" + "".join(f"<th>{inline(c)}</th>" for c in head)
                       + "</tr></thead><tbody>")
            out.extend("<tr>" + "".join(f"<td>{inline(c)}</td>" for c in r) + "</tr>" for r in body)
            out.append("</tbody></table>")
            continue
        elif line.startswith("- "):
            out.append("<ul>")
            while i < len(lines) and lines[i].startswith("- "):
                out.append(f"<li>{inline(lines[i][2:])}</li>")
                i += 1
            out.append("</ul>")
            continue
        elif line.strip() == "---":
            out.append("<hr>")
        elif line.strip():
            out.append(f"<p>{inline(line)}</p>")
        i += 1
    style = ("body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;"
             "padding:0 1em;color:#222}table{border-collapse:collapse;font-size:12px;"
             "margin:1em 0}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}"
             "th{background:#f3f3f3}img{max-width:100%}code{background:#f3f3f3}")
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>truestep report</title><style>{style}</style></head><body>\n"
            + "\n".join(out) + "\n</body></html>\n")


LectureFigures = list[tuple[Path, str]] | Callable[[], list[tuple[Path, str]]] | None


def start_lecture_figures(fig_dir: Path) -> Callable[[], list[tuple[Path, str]]]:
    """Start drawing the lecture's figures in child processes (one per core, beside this
    one drawing the report's own figures); return the function that waits for them.

    A share whose process fails is drawn again here, so an error surfaces as in a
    sequential run.
    """
    from truestep.figures import FIGURES, lecture_figure_shares, write_lecture_figures

    shares = lecture_figure_shares(untimed_workers())
    started = [(names, start_isolated(write_lecture_figures, (fig_dir, names), 600.0))
               for names in shares]

    def collect() -> list[tuple[Path, str]]:
        drawn = []
        for names, run in started:
            out = finish_isolated(run)
            drawn += out.value if out.status == "ok" else write_lecture_figures(fig_dir, names)
        rank = {name: k for k, (name, _) in enumerate(FIGURES)}
        return sorted(drawn, key=lambda pc: rank[pc[0].stem])

    return collect


def write_report(out: Path, cases: list[Case], results: pd.DataFrame,
                 tables: dict[str, pd.DataFrame], *, quick: bool, argv: list[str],
                 traces: dict | None = None, with_lecture_figures: bool = True) -> None:
    """Write results.csv, stability.csv, restitution.csv, index.md, index.html, figures/.

    Everything is written into a scratch directory first and moved into ``out`` at the
    end, so a failure midway leaves the previous report whole.
    """
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out.parent if out.parent.exists() else None) as tmp:
        stage = Path(tmp)
        results.to_csv(stage / "results.csv", index=False)
        for name in ("stability", "restitution"):
            tables[name].to_csv(stage / f"{name}.csv", index=False)
        lecture = start_lecture_figures(stage / "figures") if with_lecture_figures else None
        md = render_markdown(stage, cases, results, tables, quick=quick, argv=argv,
                             traces=traces, lecture_figures=lecture)
        (stage / "index.md").write_text(md)
        (stage / "index.html").write_text(markdown_to_html(md, stage))
        figures = out / "figures"
        if (stage / "figures").exists():
            if figures.exists():
                shutil.rmtree(figures)
            shutil.move(str(stage / "figures"), figures)
        for f in stage.iterdir():
            os.replace(f, out / f.name)
