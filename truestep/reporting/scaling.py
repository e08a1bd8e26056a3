"""The report's "How cost grows with work" section, from the scaling table of
:func:`truestep.execution.bench.scaling_table` (``scaling.csv``).

Every number in its sentences is read from the table or its ``attrs``
(:func:`scaling_lines` is tested against a recomputation from the table).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from truestep.reporting.markdown import fmt, folded, md_table, text

TITLE = "How cost grows with work"


def percent(fraction: float) -> str:
    """``0.14`` as ``14%``, ``0.0028`` as ``0.28%`` (two digits below 10%)."""
    return f"{fraction:.0%}" if fraction >= 0.1 else f"{100 * fraction:.2g}%"


def best_at(table: pd.DataFrame, n: int) -> pd.DataFrame:
    """Per engine, its fastest ``ok`` row at ``n`` particles (by ``particle_steps_per_s``),
    fastest engine first. Columns as the table's."""
    ok = table[(table["status"] == "ok") & (table["n"] == n)]
    if ok.empty:
        return ok
    best = ok.loc[ok.groupby("engine", sort=False)["particle_steps_per_s"].idxmax()]
    return best.sort_values("particle_steps_per_s", ascending=False)


def comparison_n(table: pd.DataFrame) -> tuple[int, bool] | None:
    """The largest ``n`` at which at least two engines have an ``ok`` row and ``True``, else
    the largest with any and ``False``; ``None`` when no row is ``ok``."""
    ok = table[table["status"] == "ok"]
    if ok.empty:
        return None
    engines = ok.groupby("n")["engine"].nunique()
    shared = engines[engines >= 2]
    return (int(shared.index.max()), True) if len(shared) else (int(engines.index.max()), False)


def scaling_lines(table: pd.DataFrame) -> list[str]:
    """The section's sentences: the copy bandwidth, and at :func:`comparison_n` each
    engine's fastest method with its particle-steps per second, its fraction of the
    bandwidth and its ratio to the fastest engine."""
    bandwidth = float(table.attrs.get("bandwidth_bytes_per_s", float("nan")))
    per_step = int(table.attrs.get("bytes_per_particle_step", 96))
    lines = [
        f"Particle-steps per second (n particles x steps / median timed wall time) of the "
        f"`particle-rain` scene at n from {int(table['n'].min()):,} to "
        f"{int(table['n'].max()):,}, for every fixed-step method of every engine, each run "
        f"in a process of its own, one at a time, after a warm-up; sizes that would not fit "
        f"the {fmt(table.attrs.get('budget_s', float('nan')))} s budget are `skipped` with "
        f"the reason. The copy bandwidth measured in the same run is "
        f"{bandwidth / 1e9:.1f} GB/s, which at {per_step} B per particle-step (positions and "
        f"velocities, float64, read and written once) is "
        f"{bandwidth / per_step:.3g} particle-steps/s. `truestep bench` makes the same table "
        f"with a larger budget.\n"
    ]
    at = comparison_n(table)
    if at is None:
        lines.append("No run of the scaling table finished.\n")
        return lines
    n, shared = at
    best = best_at(table, n)
    top = best.iloc[0]
    cells = [
        f"{text(r.engine)} / {text(r.method)} {r.particle_steps_per_s:.3g} "
        f"({percent(r.bandwidth_fraction)} of the bandwidth"
        + (
            ""
            if r.engine == top.engine
            else f", {top.particle_steps_per_s / r.particle_steps_per_s:.1f}x slower"
        )
        + ")"
        for r in best.itertuples(index=False)
    ]
    lines.append(
        f"At n = {n:,}, the largest n "
        + ("that more than one engine reached" if shared else "any run reached")
        + ", the fastest method of each engine, in particle-steps per second: "
        + "; ".join(cells)
        + "."
        + (
            " A fraction above 100% means the state stayed in cache between steps."
            if (best["bandwidth_fraction"] > 1).any()
            else ""
        )
        + "\n"
    )
    return lines


def scaling_section(table: pd.DataFrame | None, fig_dir: Path) -> list[str]:
    """The section as markdown lines; its figure is written under ``fig_dir``."""
    from truestep.execution.bench import scaling_plot

    parts = [f"## {TITLE}\n"]
    if table is None or not len(table):
        parts.append(
            "Not run: the scaling table is made by a full run that includes the "
            "`particle-rain` case, and by `truestep bench`.\n"
        )
        return parts
    parts += scaling_lines(table)
    if (table["status"] == "ok").any():
        fig = scaling_plot(table, float(table.attrs["bandwidth_bytes_per_s"]), fig_dir / "scaling.png")
        parts.append(f"![particle-steps per second against n](figures/{fig.name})\n")
    shown = table.assign(note=table["note"].str.slice(0, 160))
    parts.append(folded(f"{len(table)} rows of the scaling table", md_table(shown)))
    return parts
