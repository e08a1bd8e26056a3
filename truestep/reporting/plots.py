"""Figures of the report: one colour per engine and method, one marker and line style per
engine, the same in every figure (the lecture's figures and the scaling plot too)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from truestep.measures.restitution import PHASES
from truestep.measures.stability import ROUNDOFF_DECIDES
from truestep.runtime.visible import visible
from truestep.style import LEGEND_FONT, legend_height, save, series_colour, series_style


def _plain(title: str) -> str:
    """Case text as a plot title: dollar signs shown, never read as mathtext (an
    unbalanced one would stop the figure)."""
    return title.replace("$", r"\$")


def _pair(engine: object, method: object) -> str:
    """``engine / method`` as a plot label: hidden characters shown, dollar signs never
    read as mathtext, never hidden by a leading underscore."""
    label = _plain(visible(f"{engine} / {method}"))
    return " " + label if label.startswith("_") else label


def work_precision(df: pd.DataFrame, case: str, title: str, path: Path, unit: str = "m") -> Path | None:
    """Error against wall time and against derivative evaluations (log-log), per series.

    ``df`` holds one case's rows; only runs with status ok and a positive error appear.
    ``unit``: the error's (``m`` for particles, the state's units for an ODE). An adaptive
    method's loosest and tightest points are labelled with their tolerance (left panel). Returns the figure's
    path, or ``None`` when no row has an error to plot.
    """
    ok = df[(df["status"] == "ok") & (df["error"].astype(float) > 0)]
    if ok.empty:
        return None
    series = ok.groupby(["engine", "method"], sort=False).ngroups
    fig, axes = plt.subplots(1, 2, figsize=(13, legend_height(series, 5.2)), sharey=True)
    for (engine, method), g in ok.groupby(["engine", "method"], sort=False):
        style = series_style(engine, method)
        label = _pair(engine, method)
        for ax, x in zip(axes, ("wall_s", "nfev"), strict=True):
            g = g.sort_values(x)
            ax.plot(g[x], g["error"], label=label, **style)
            tolerances = g[g["dt_kind"] == "tolerance"] if x == "wall_s" else g.iloc[:0]
            if len(tolerances) > 2:  # the loosest and the tightest: the rest lie between
                tolerances = tolerances.iloc[
                    [int(np.argmax(tolerances["dt"])), int(np.argmin(tolerances["dt"]))]
                ]
            for r in tolerances.itertuples(index=False):
                ax.annotate(
                    f"tol {r.dt:.0e}",
                    (getattr(r, x), r.error),
                    xytext=(4, 3),
                    textcoords="offset points",
                    fontsize=7.5,
                    color=style["color"],
                )
    axes[0].set_xlabel("wall time per run (s, median of repeats)")
    axes[1].set_xlabel("derivative evaluations per run (steps x evaluations per step)")
    axes[0].set_ylabel(f"largest error against the exact solution ({unit})")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="major", alpha=0.3)
    fig.suptitle(f"{_plain(title)}: work against precision")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(
        handles, labels, loc="center left", bbox_to_anchor=(0.79, 0.5), fontsize=LEGEND_FONT, frameon=False
    )
    fig.tight_layout(rect=(0, 0, 0.79, 1))
    return save(fig, path)


SEARCH_FAILED = {"solver-failed": "solver failed", "timeout": "search timed out", "crashed": "crashed"}
"""Stability rows without a limit that the figure still shows, and how it labels them."""


def stability_bars(stab: pd.DataFrame, case: str, path: Path) -> Path | None:
    """Measured largest stable step per engine/method, the exact limit marked beside it.

    A method stable at every step tried has a hatched bar ending at the largest step tried
    (a lower bound); one whose search found no limit (:data:`SEARCH_FAILED`) has a row
    that says so instead of a bar; one whose limit round-off decides (its note says so:
    :data:`~truestep.measures.stability.ROUNDOFF_DECIDES`) has a whisker from its limit to
    its unstable end, where the boundary lies."""
    s = stab[(stab["case"] == case) & stab["status"].isin(["ok", *SEARCH_FAILED])]
    if s.empty or not (s["status"] == "ok").any():
        return None
    labels = [_pair(e, m) for e, m in zip(s["engine"], s["method"], strict=True)]
    y = np.arange(len(s))
    fig, ax = plt.subplots(figsize=(10.5, 0.34 * len(s) + 1.6))
    colours = [series_colour(e, m) for e, m in zip(s["engine"], s["method"], strict=True)]
    ok = (s["status"] == "ok").to_numpy()
    limits = np.where(ok, pd.to_numeric(s["dt_limit"], errors="coerce"), np.nan)
    floor = np.nanmin(np.where(limits > 0, limits, np.nan)) / 10 if np.any(limits > 0) else 1e-4
    bound = ok & np.isinf(pd.to_numeric(s["dt_unstable"], errors="coerce").to_numpy())
    widths = np.where(ok, np.where(limits > 0, limits, floor), 0.0)
    bars = ax.barh(y, widths, color=colours, alpha=0.8)
    for bar, is_bound in zip(bars, bound, strict=True):
        if is_bound:
            bar.set_hatch("//")
            bar.set_edgecolor("white")
    exact = s["dt_limit_exact"].astype(float).to_numpy()
    for yi, ex in zip(y, exact, strict=True):
        if np.isfinite(ex) and ex > 0:
            ax.plot([ex, ex], [yi - 0.4, yi + 0.4], color="black", linewidth=2)
    unstable = pd.to_numeric(s["dt_unstable"], errors="coerce").to_numpy(float)
    notes = s["note"].fillna("").astype(str)
    decided = ok & notes.str.contains(ROUNDOFF_DECIDES, regex=False).to_numpy()
    for yi, lo, hi in zip(y[decided], limits[decided], unstable[decided], strict=True):
        ax.errorbar(
            [np.sqrt(lo * hi)],
            [yi],
            xerr=[[np.sqrt(lo * hi) - lo], [hi - np.sqrt(lo * hi)]],
            fmt="none",
            ecolor="black",
            elinewidth=1.2,
            capsize=4,
        )
    for yi, status in zip(y, s["status"], strict=True):
        if status in SEARCH_FAILED:
            ax.text(
                floor,
                float(yi),
                f" {SEARCH_FAILED[status]}: no limit",
                va="center",
                fontsize=8,
                color="#b2182b",
            )
    ax.set_yticks(y, labels, fontsize=8)
    ax.set_xscale("log")
    ax.set_xlim(left=floor / 2)
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel(
        "largest stable step (s); black tick: exact limit; hatched: stable at every\n"
        "step tried (a lower bound); a stub at the left edge: unstable at every step tried;\n"
        "whisker: where round-off decides the verdict (the boundary lies in it)"
    )
    ax.set_title(f"{case}: largest stable step")
    ax.invert_yaxis()
    fig.tight_layout()
    return save(fig, path)


def restitution_plot(rest: pd.DataFrame, path: Path) -> Path | None:
    """The restitution each engine and method gives on the first bounce, as its deviation
    from the one requested (``e_measured - e_set``) against the one requested: a method
    that keeps what it is asked lies on zero, and the scale shows how far the others miss.
    A bar through each point spans the impact-phase drops' range (``e_phase_min`` to
    ``e_phase_max``), each series shifted a little along the axis so the bars stay apart."""
    r = rest[(rest["status"] == "ok") & (rest["bounce"] == 1)].dropna(subset=["e_measured"])
    if r.empty:
        return None
    dts = sorted(r["dt"].astype(float).unique(), reverse=True)
    series = r.groupby(["engine", "method"]).ngroups + 1
    fig, axes = plt.subplots(
        1,
        len(dts),
        figsize=(max(6.5 * len(dts), 10.5), legend_height(series, 5.0)),
        squeeze=False,
        sharey=True,
    )
    for ax, dt in zip(axes[0], dts, strict=True):
        d = r[np.isclose(r["dt"].astype(float), dt)]
        for k, ((engine, method), g) in enumerate(d.groupby(["engine", "method"], sort=False)):
            g = g.sort_values("e_set")
            e_set = g["e_set"].astype(float).to_numpy()
            deviation = g["e_measured"].astype(float).to_numpy() - e_set
            style = series_style(engine, method)
            (line,) = ax.plot(e_set, deviation, label=_pair(engine, method), **style)
            if {"e_phase_min", "e_phase_max"} <= set(g.columns):
                lo = pd.to_numeric(g["e_phase_min"], errors="coerce").to_numpy() - e_set
                hi = pd.to_numeric(g["e_phase_max"], errors="coerce").to_numpy() - e_set
                seen = np.isfinite(lo) & np.isfinite(hi)
                if seen.any():
                    shift = 0.004 * (k - 0.5 * series)
                    mid = 0.5 * (lo + hi)
                    ax.errorbar(
                        e_set[seen] + shift,
                        mid[seen],
                        yerr=0.5 * (hi - lo)[seen],
                        fmt="none",
                        ecolor=line.get_color(),
                        elinewidth=1.0,
                        capsize=2,
                        alpha=0.7,
                    )
        ax.axhline(0.0, color="black", linewidth=0.8, label="measured = requested")
        ax.set_xlabel("requested restitution e_set (rebound / impact normal speed)")
        ax.set_title(f"dt = 1/{1 / dt:.0f} s; bars: the range over {PHASES} impact phases")
        ax.grid(True, alpha=0.3)
    axes[0][0].set_ylabel("measured - requested restitution (bounce 1)")
    axes[0][-1].legend(fontsize=LEGEND_FONT, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    fig.tight_layout()
    return save(fig, path)


def energy_over_time(
    traces: dict,
    case: str,
    title: str,
    dt_step: float | None,
    tol: float | None,
    path: Path,
    scale: float | None = None,
) -> Path | None:
    """Energy error ``|E(t) - E(0)| / S`` over time (log scale), one line per engine/method:
    fixed-step methods at step ``dt_step``, adaptive ones at tolerance ``tol``. ``S`` is
    ``scale`` (J), the case's energy scale the tables' energy drift is measured on; without
    one, ``|E(0)|``.

    ``traces`` maps ``(case, engine, method, dt_kind, dt)`` to ``(t, energy)``.
    """
    wanted = {"step": dt_step, "tolerance": tol}

    def shown(key: tuple) -> bool:
        at = wanted[key[3]]
        return key[0] == case and at is not None and bool(np.isclose(key[4], at, rtol=1e-9, atol=0.0))

    chosen = {k: v for k, v in traces.items() if shown(k)}
    if not chosen:
        return None
    fig, ax = plt.subplots(figsize=(12, legend_height(len(chosen), 4.8)))
    known = scale is not None and np.isfinite(scale) and scale > 0
    for (_, engine, method, kind, dt), (t, e) in chosen.items():
        s = scale if known else (abs(e[0]) if e[0] != 0 else (np.max(np.abs(e)) or 1.0))
        rel = np.maximum(np.abs(e - e[0]) / s, 1e-16)
        label = f"{_pair(engine, method)} ({'tol' if kind == 'tolerance' else 'dt'} {dt:g})"
        ax.plot(t, rel, label=label, **{**series_style(engine, method), "marker": None})
    ax.set_yscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(
        "|E(t) - E(0)| / energy scale  (floor 1e-16)" if known else "|E(t) - E(0)| / |E(0)|  (floor 1e-16)"
    )
    ax.set_title(f"{_plain(title)}: energy error over time")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=LEGEND_FONT, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    fig.tight_layout()
    return save(fig, path)


SCORECARD_DPI = 96
"""The scorecard is read first and its cells carry numbers: drawn sharper than the rest."""


def scorecard(
    card: pd.DataFrame, fidelity: pd.DataFrame, families: list[str], target: float, path: Path
) -> Path | None:
    """The report's overview: a row per engine/method, three panels.

    Left: the wall time to reach ``target`` of each case's scale, as a multiple of the
    fastest run's, per family of scenes (median over the family's cases reached; ``-``:
    ran, never reached it; blank: did not run). Middle: the largest stable step over the
    exact limit (or the best any method reached), per family. Right: the restitution
    error ``|e_measured - e_set|`` (median over every bounce of the sweep).
    ``card`` is :func:`truestep.measures.picks.scorecard`, ``fidelity``
    :func:`truestep.measures.picks.restitution_fidelity`. No figure (``None``) without a row or
    without a family (a run of cases outside every family has nothing to tabulate).
    """
    if card.empty or not families:
        return None
    rows = list(dict.fromkeys(zip(card["engine"], card["method"], strict=True)))
    index = {r: k for k, r in enumerate(rows)}
    col = {f: k for k, f in enumerate(families)}
    cost = np.full((len(rows), len(families)), np.nan)
    ran = np.zeros_like(cost, dtype=bool)
    limit = np.full_like(cost, np.nan)
    counts = np.full(cost.shape, "", dtype=object)
    zero = np.zeros_like(cost, dtype=bool)
    for r in card.itertuples(index=False):
        if r.family not in col:
            continue
        i, j = index[(r.engine, r.method)], col[r.family]
        cost[i, j], ran[i, j], limit[i, j] = r.cost_ratio, r.cases_run > 0, r.stability_ratio
        counts[i, j] = f"{r.cases_reached}/{r.cases_measured}"
        zero[i, j] = r.stability_zero > 0 and not np.isfinite(r.stability_ratio)
    rest = np.full((len(rows), 1), np.nan)
    for r in fidelity.itertuples(index=False):
        if (r.engine, r.method) in index:
            rest[index[(r.engine, r.method)], 0] = r.median
    fig, axes = plt.subplots(
        1,
        3,
        figsize=(13, 0.42 * len(rows) + 2.4),
        gridspec_kw={"width_ratios": [len(families), len(families), 1.3]},
    )
    panels = [
        (
            axes[0],
            np.log10(np.maximum(cost, 1.0)),
            cost,
            "RdYlGn_r",
            (0, 3),
            f"time to reach {target:g} of the scale, x the fastest\n"
            "(cases reached / cases with an error measure)",
            lambda v: f"{v:.3g}x",
        ),
        (
            axes[1],
            np.clip(limit, 0, 1),
            limit,
            "RdYlGn",
            (0, 1),
            "largest stable step,\n x the exact (or best) limit",
            lambda v: f"{v:.2f}",
        ),
        (
            axes[2],
            np.log10(np.maximum(rest, 1e-4)),
            rest,
            "RdYlGn_r",
            (-4, -0.5),
            "restitution\nerror |de|",
            lambda v: f"{v:.3f}",
        ),
    ]
    for ax, shade, values, cmap, (lo, hi), title, text in panels:
        ax.imshow(np.ma.masked_invalid(shade), cmap=cmap, vmin=lo, vmax=hi, aspect="auto")
        for (i, j), v in np.ndenumerate(values):
            count = f"\n{counts[i, j]}" if values is cost and counts[i, j] else ""
            if np.isfinite(v):
                ax.text(j, i, text(v) + count, ha="center", va="center", fontsize=7.5, linespacing=0.95)
            elif values is cost and ran[i, j]:
                ax.text(j, i, "-" + count, ha="center", va="center", fontsize=7.5, color="#555555")
            elif values is limit and zero[i, j]:
                ax.text(j, i, "exact 0", ha="center", va="center", fontsize=7, color="#555555")
        ax.set_title(title, fontsize=9)
        ax.set_xticks(
            range(values.shape[1]),
            families if values.shape[1] == len(families) else ["sweep"],
            fontsize=8,
            rotation=30,
            ha="right",
        )
        ax.set_yticks(range(len(rows)), [_pair(e, m) for e, m in rows] if ax is axes[0] else [], fontsize=8)
        ax.set_xticks(np.arange(values.shape[1] + 1) - 0.5, minor=True)
        ax.set_yticks(np.arange(len(rows) + 1) - 0.5, minor=True)
        ax.grid(which="minor", color="white", linewidth=1.5)
        ax.tick_params(which="minor", length=0)
    fig.tight_layout()
    return save(fig, path, dpi=SCORECARD_DPI)
