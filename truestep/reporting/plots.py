"""Figures of the report: one colour per engine, one line style per method, everywhere."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from truestep.visible import visible

ENGINE_COLOURS = {
    "reference": "#1f77b4",
    "scipy": "#7f7f7f",
    "pymunk": "#2ca02c",
    "pybullet": "#d62728",
    "mujoco": "#9467bd",
}
METHOD_STYLES = {
    "euler": ("-", "o"),
    "midpoint": ("--", "s"),
    "heun": ("-.", "^"),
    "rk4": (":", "D"),
    "dopri5": ("-", "*"),
    "symplectic-euler": ("--", "v"),
    "verlet": ("-.", "P"),
    "implicit-euler": (":", "X"),
    "lecture": ("-", "h"),
    "RK45": ("-", "*"),
    "DOP853": ("--", "p"),
    "Radau": (":", "X"),
    "default": ("-", "o"),
    "clean": ("--", "s"),
    "Euler": ("-", "o"),
    "implicit": ("--", "s"),
    "implicitfast": ("-.", "^"),
    "RK4": (":", "D"),
}
"""Engines by colour, methods by line style and marker; within an engine the
(line style, marker) pair tells its methods apart."""


REPORT_DPI = 72
"""Resolution of the report's figures: sharp at the page's width, small when inlined."""


def _plain(title: str) -> str:
    """Case text as a plot title: dollar signs shown, never read as mathtext (an
    unbalanced one would stop the figure)."""
    return title.replace("$", r"\$")


def _pair(engine: object, method: object) -> str:
    """``engine / method`` as a plot label: hidden characters shown, dollar signs never
    read as mathtext, never hidden by a leading underscore."""
    label = _plain(visible(f"{engine} / {method}"))
    return " " + label if label.startswith("_") else label


def save(fig, path: Path, dpi: int = REPORT_DPI) -> Path:
    """Write ``fig`` as a compact PNG: ``dpi``, then reduced to a 128-colour palette.

    Line plots use a handful of colours, so the palette loses nothing visible and the
    file (inlined in the HTML report) shrinks about threefold.
    """
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    with Image.open(path) as img:
        small = img.convert("RGB").quantize(colors=128, method=Image.Quantize.MEDIANCUT)
    small.save(path, optimize=True)
    return path


def series_style(engine: str, method: str) -> dict:
    ls, marker = METHOD_STYLES.get(method, ("-", "o"))
    return {
        "color": ENGINE_COLOURS.get(engine, "black"),
        "linestyle": ls,
        "marker": marker,
        "markersize": 4,
        "linewidth": 1.3,
    }


def work_precision(df: pd.DataFrame, case: str, title: str, path: Path) -> Path | None:
    """Error against wall time and against derivative evaluations (log-log), per series.

    ``df`` holds one case's rows; only runs with status ok and a positive error appear.
    Returns the figure's path, or ``None`` when no row has an error to plot.
    """
    ok = df[(df["status"] == "ok") & (df["error"].astype(float) > 0)]
    if ok.empty:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.4), sharey=True)
    for (engine, method), g in ok.groupby(["engine", "method"], sort=False):
        g = g.sort_values("wall_s")
        style = series_style(engine, method)
        label = _pair(engine, method)
        axes[0].plot(g["wall_s"], g["error"], label=label, **style)
        g = g.sort_values("nfev")
        axes[1].plot(g["nfev"], g["error"], label=label, **style)
    axes[0].set_xlabel("wall time per run (s, median of repeats)")
    axes[1].set_xlabel("derivative evaluations (engine steps for engines)")
    axes[0].set_ylabel("error against the exact solution")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="major", alpha=0.3)
    fig.suptitle(f"{_plain(title)}: work against precision")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="center left", bbox_to_anchor=(0.81, 0.5), fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0, 0.81, 1))
    return save(fig, path)


SEARCH_FAILED = {"solver-failed": "solver failed", "timeout": "search timed out", "crashed": "crashed"}
"""Stability rows without a limit that the figure still shows, and how it labels them."""


def stability_bars(stab: pd.DataFrame, case: str, path: Path) -> Path | None:
    """Measured largest stable step per engine/method, the exact limit marked beside it.

    A method stable at every step tried has a hatched bar ending at the largest step tried
    (a lower bound); one whose search found no limit (:data:`SEARCH_FAILED`) has a row
    that says so instead of a bar."""
    s = stab[(stab["case"] == case) & stab["status"].isin(["ok", *SEARCH_FAILED])]
    if s.empty or not (s["status"] == "ok").any():
        return None
    labels = [_pair(e, m) for e, m in zip(s["engine"], s["method"], strict=True)]
    y = np.arange(len(s))
    fig, ax = plt.subplots(figsize=(8, 0.32 * len(s) + 1.4))
    colours = [ENGINE_COLOURS.get(e, "black") for e in s["engine"]]
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
        "step tried (a lower bound); a stub at the left edge: unstable at every step tried"
    )
    ax.set_title(f"{case}: largest stable step")
    ax.invert_yaxis()
    fig.tight_layout()
    return save(fig, path)


def restitution_plot(rest: pd.DataFrame, path: Path) -> Path | None:
    """Requested against measured restitution (first bounce), per engine and method."""
    r = rest[(rest["status"] == "ok") & (rest["bounce"] == 1)].dropna(subset=["e_measured"])
    if r.empty:
        return None
    dts = sorted(r["dt"].astype(float).unique(), reverse=True)
    fig, axes = plt.subplots(1, len(dts), figsize=(5.2 * len(dts), 4.4), squeeze=False)
    for ax, dt in zip(axes[0], dts, strict=True):
        d = r[np.isclose(r["dt"].astype(float), dt)]
        for (engine, method), g in d.groupby(["engine", "method"], sort=False):
            g = g.sort_values("e_set")
            ax.plot(g["e_set"], g["e_measured"], label=_pair(engine, method), **series_style(engine, method))
        ax.plot([0, 1], [0, 1], color="black", linewidth=0.8, label="requested = measured")
        ax.set_xlabel("requested restitution")
        ax.set_ylabel("measured (rebound / impact speed, bounce 1)")
        ax.set_title(f"dt = 1/{1 / dt:.0f} s")
        ax.grid(True, alpha=0.3)
    axes[0][-1].legend(fontsize=7, loc="upper left", frameon=False)
    fig.tight_layout()
    return save(fig, path)


def energy_over_time(
    traces: dict, case: str, title: str, dt_step: float | None, tol: float | None, path: Path
) -> Path | None:
    """Relative energy error ``|E(t) - E(0)| / |E(0)|`` over time (log scale), one line per
    engine/method: fixed-step methods at step ``dt_step``, adaptive ones at tolerance ``tol``.

    ``traces`` maps ``(case, engine, method, dt_kind, dt)`` to ``(t, energy)``.
    """
    wanted = {"step": dt_step, "tolerance": tol}

    def shown(key: tuple) -> bool:
        at = wanted[key[3]]
        return key[0] == case and at is not None and bool(np.isclose(key[4], at, rtol=1e-9, atol=0.0))

    chosen = {k: v for k, v in traces.items() if shown(k)}
    if not chosen:
        return None
    fig, ax = plt.subplots(figsize=(9.5, 4.4))
    for (_, engine, method, kind, dt), (t, e) in chosen.items():
        scale = abs(e[0]) if e[0] != 0 else (np.max(np.abs(e)) or 1.0)
        rel = np.maximum(np.abs(e - e[0]) / scale, 1e-16)
        label = f"{_pair(engine, method)} ({'tol' if kind == 'tolerance' else 'dt'} {dt:g})"
        ax.plot(t, rel, label=label, **{**series_style(engine, method), "marker": None})
    ax.set_yscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("|E(t) - E(0)| / |E(0)|  (floor 1e-16)")
    ax.set_title(f"{_plain(title)}: energy error over time")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
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
    for r in card.itertuples(index=False):
        if r.family not in col:
            continue
        i, j = index[(r.engine, r.method)], col[r.family]
        cost[i, j], ran[i, j], limit[i, j] = r.cost_ratio, r.cases_run > 0, r.stability_ratio
    rest = np.full((len(rows), 1), np.nan)
    for r in fidelity.itertuples(index=False):
        if (r.engine, r.method) in index:
            rest[index[(r.engine, r.method)], 0] = r.median
    fig, axes = plt.subplots(
        1,
        3,
        figsize=(12.5, 0.3 * len(rows) + 2.2),
        gridspec_kw={"width_ratios": [len(families), len(families), 1.3]},
    )
    panels = [
        (
            axes[0],
            np.log10(np.maximum(cost, 1.0)),
            cost,
            "RdYlGn_r",
            (0, 3),
            f"time to reach {target:g} of the scale,\n x the fastest run",
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
            if np.isfinite(v):
                ax.text(j, i, text(v), ha="center", va="center", fontsize=7)
            elif values is cost and ran[i, j]:
                ax.text(j, i, "-", ha="center", va="center", fontsize=8, color="#777777")
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
