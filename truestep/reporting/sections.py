"""The report's sections, each a list of markdown lines generated from the tables.

No sentence here states a number it did not read from a table or from the constant that
made it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from truestep.cases.case import Case
from truestep.cases.gate_kinds import GATE_KINDS
from truestep.measures.findings import Conclusion, Findings
from truestep.measures.peers import SAME
from truestep.measures.picks import (
    ACCURACY_TARGETS,
    SURVIVAL_ENERGY,
    SURVIVAL_ERROR,
)
from truestep.measures.restitution import PHASE_BAND, PHASES
from truestep.reporting.markdown import fmt, folded, md_table, text, with_units

_fmt = fmt


def _run_label(r: pd.Series) -> str:
    """``engine / method (dt ...)`` (a tolerance for adaptive rows)."""
    kind = "tol" if r["dt_kind"] == "tolerance" else "dt"
    return f"{r['engine']} / {r['method']} ({kind} {_fmt(float(r['dt']))})"


def cheapest_table(cases: list[Case], picks: pd.DataFrame) -> pd.DataFrame:
    """Per case, the cheapest run by wall time that reaches each accuracy target, with
    its time, and the cheapest by evaluations where it is another run (``picks``:
    :attr:`Findings.cheapest <truestep.measures.findings.Findings>`)."""
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
            if wall["tied"]:
                tied = wall["tied"].split("; ")
                more = f" and {len(tied) - 3} more" if len(tied) > 3 else ""
                cell += f" (tied within timing noise: {', '.join(tied[:3])}{more})"
            key = ("engine", "method", "dt")
            if [wall[k] for k in key] != [evals[k] for k in key]:
                cell += f"; fewest evaluations: {_run_label(evals)}, {int(evals['nfev'])}"
            row[f"error <= {target:g} scale"] = cell
        rows.append(row)
    return pd.DataFrame(rows)


def summary(cases: list[Case], found: Findings, tables: dict[str, pd.DataFrame]) -> list[str]:
    """The summary, every sentence generated from the findings and the tables."""
    lines = ["## Summary\n"]
    table = cheapest_table(cases, found.cheapest)
    if len(table):
        lines.append(
            "The cheapest run that reaches each accuracy (error at most 1e-2, 1e-4 "
            "and 1e-6 of the case's scale), by wall time; where another run needs "
            "fewer derivative evaluations it is named too:\n"
        )
        lines.append(md_table(table))
    shared = [
        f"- {text(name)}: {text(why)}; there those of the reference's methods are interchangeable "
        f"({text(', '.join(found.shared_methods.get(name, [])))}: the scorecard's cost ratios of these "
        "leave the case out), and its picks compare the engines' handling of events (contacts, "
        "spawns), not integrators."
        for name, why in found.scene_set.items()
    ]
    if shared:
        lines.append("Where no integrator sets the error:\n")
        lines += [*shared, ""]
    rest = tables.get("restitution")
    if rest is not None and len(rest):
        r = rest[(rest["status"] == "ok") & (rest["bounce"] == 1)].dropna(subset=["e_measured"])
        if len(r):
            r = r.assign(gap=(r["e_measured"] - r["e_set"]).abs())
            worst = r.sort_values("gap", ascending=False).drop_duplicates(["engine", "method"]).head(4)
            lines.append("Widest gaps between requested and measured restitution (first bounce):\n")
            for w in worst.itertuples(index=False):
                lines.append(
                    f"- {text(w.engine)} / {text(w.method)}: requested {w.e_set:g}, measured "
                    f"{w.e_measured:.3f} at dt {_fmt(float(w.dt))} s."
                )
            lines.append("")
    lines += phase_lines(found.phase_contact)
    hard = [c for c in cases if c.hard]
    if hard:
        lines.append(
            f"Hard cases: the largest step of the sweep at which each engine/method "
            f"survives: it finishes stable, does not fail what the scene tests (such "
            f"as tunnelling), its error is at most {SURVIVAL_ERROR:g} of the case's "
            f"scale and its energy error at most {SURVIVAL_ENERGY:g} of its energy:\n"
        )
        for c in hard:
            lines.append(hard_case_line(c, found.survival[c.name]))
        lines.append("")
    return lines


def _phase_range(w: pd.Series) -> str:
    return (
        f"asked {w['e_set']:g}, {w['e_phase_min']:.3f} to {w['e_phase_max']:.3f} (median "
        f"{w['e_phase_median']:.3f}) over the impact phases at dt {_fmt(float(w['dt']))} s"
    )


def phase_lines(phase: pd.DataFrame) -> list[str]:
    """The summary's list of engines and methods that do not give the asked restitution at
    every impact phase, within the band (``phase``:
    :func:`truestep.measures.restitution.phase_contact`), each with its farthest range."""
    if phase is None or not len(phase):
        return []
    lines = [
        f"Where the asked restitution is not what every impact phase gets (the restitution "
        f"sweep drops {PHASES} balls per row, their first contacts spread evenly over a step; "
        f"first bounce, farther than {PHASE_BAND:g} from the asked e at some phase), the "
        "farthest row of each:\n"
    ]
    for (engine, method), g in phase.groupby(["engine", "method"], sort=False):
        w = g.iloc[0]
        lines.append(
            f"- {text(engine)} / {text(method)}: {_phase_range(w)} (a spread of "
            f"{w['e_phase_max'] - w['e_phase_min']:.3f} with the phase); {len(g)} "
            f"{'row' if len(g) == 1 else 'rows'} of its sweep leave the band, and its errors on the "
            "contact cases are partly its contact law's."
        )
    return [*lines, ""]


def phase_sentence(case: Case, shown: pd.DataFrame, phase: pd.DataFrame) -> str:
    """A contact case's line naming the engines and methods among its rows (``shown``)
    that do not give the asked restitution at every impact phase (``phase``: as
    :func:`phase_lines`), or ``""``."""
    if phase is None or not len(phase) or not getattr(case.scene, "planes", None):
        return ""
    ran = set(zip(shown["engine"].astype(str), shown["method"].astype(str), strict=True))
    named = [
        f"{text(e)} / {text(m)}"
        for (e, m), _ in phase.groupby(["engine", "method"], sort=False)
        if (str(e), str(m)) in ran
    ]
    if not named:
        return ""
    return (
        "**Contact law:** the restitution sweep's drops do not get the asked restitution at "
        f"every impact phase from {', '.join(named)} (the summary gives each one's range): their "
        "errors here are partly their contact law's, not their integrators'.\n"
    )


def hard_case_line(case: Case, s: pd.DataFrame) -> str:
    """One summary bullet: engine/methods grouped by the largest step they survive
    (``s``: :func:`truestep.measures.picks.survival` of the case)."""
    if s.empty:
        return f"- **{case.name}**: no fixed-step runs."
    groups = []
    for dt, g in sorted(s.dropna(subset=["dt_survived"]).groupby("dt_survived"), key=lambda kv: -kv[0]):
        names = ", ".join(f"{text(e)}/{text(m)}" for e, m in zip(g["engine"], g["method"], strict=True))
        groups.append(f"{_fmt(float(dt))} s: {names}")
    never = s[s["dt_survived"].isna()]
    if len(never):
        names = ", ".join(
            f"{text(e)}/{text(m)} ({text(f or 'failed')})"
            for e, m, f in zip(never["engine"], never["method"], never["failure"], strict=True)
        )
        groups.append(f"at no step of the sweep: {names}")
    return f"- **{case.name}**: " + "; ".join(groups) + "."


def speedup_sentence(gate, others: pd.DataFrame, mine: pd.Series) -> str:
    """How many times as long the fastest engine takes as ``mine`` at the gate's step, with
    the interval the timings' noise leaves (:func:`truestep.measures.picks.noise_interval`); engines
    tied for fastest are named together."""
    from truestep.measures.picks import noise_interval, tied_with_fastest

    tied = others[tied_with_fastest(others)].sort_values(["engine", "method"])
    names = " and ".join(f"{text(r.engine)} / {text(r.method)}" for r in tied.itertuples(index=False))
    fastest = tied.loc[tied["wall_s"].astype(float).idxmin()]
    w_e, w_r = float(fastest["wall_s"]), float(mine["wall_s"])
    (lo_e,), (hi_e,) = noise_interval(np.array([w_e]), np.array([fastest.get("wall_s_spread", np.nan)]))
    (lo_r,), (hi_r,) = noise_interval(np.array([w_r]), np.array([mine.get("wall_s_spread", np.nan)]))
    low, high = lo_e / hi_r, hi_e / lo_r
    who = (
        f"the fastest engine, {names},"
        if len(tied) == 1
        else f"the fastest engines, {names} (tied within timing noise),"
    )
    return (
        f"At dt {_fmt(gate.dt)} s {who} take{'s' if len(tied) == 1 else ''} "
        f"{low:.0f} to {high:.0f} times as long as {text(gate.engine)} / {text(gate.method)} "
        f"({w_e / w_r:.0f} times by the median wall times; the interval is each time's "
        f"noise band; gate: at least {gate.params['min']:g} times).\n"
    )


def speed_section(
    cases: list[Case], speed: dict[tuple[str, str], pd.DataFrame], phase: pd.DataFrame | None = None
) -> list[str]:
    """For each case with a ``speedup`` gate: what modelling only what the scene needs is
    worth, the gated method against every engine at the same steps; under it, the engines
    and methods of its table whose contact does not give the asked restitution at every
    impact phase (``phase``: :func:`truestep.measures.restitution.phase_contact`), whose
    errors there are partly their contact law's (:func:`phase_sentence`)."""
    parts: list[str] = []
    for case in cases:
        for g in (g for g in case.gates if GATE_KINDS[g.kind].speed):
            table = speed[(case.name, g.where)]
            if table.empty or g.dt is None:
                continue
            at = table[np.isclose(table["dt"], g.dt)]
            others = at[at["engine"] != g.engine]
            parts.append(f"## What modelling only what a scene needs is worth: {case.name}\n")
            parts.append(
                f"{text(case.title)}: {text(g.engine)} / {text(g.method)} runs only what the "
                "scene needs (here "
                "a compiled loop over independent particles, on one thread like the "
                "engines), the engines their general machinery (broad phase, contact "
                "solver, one body per particle). Each row: "
                "particle-steps per second at the same step and the error against the exact "
                "bounce solution; `slower_by` is its wall time over "
                f"{text(g.engine)} / {text(g.method)}'s.\n"
            )
            mine = at[(at["engine"] == g.engine) & (at["method"] == g.method)]
            if len(others) and len(mine):
                parts.append(speedup_sentence(g, others, mine.iloc[0]))
            parts.append(md_table(with_units(table)))
            if phase is not None and (contact := phase_sentence(case, table, phase)):
                parts.append(contact)
    return parts


def _pair(r) -> str:
    """``engine / method`` of a row, as markdown text (:func:`text`)."""
    return f"{text(r.engine)} / {text(r.method)}"


def _tied_group(ranked: pd.DataFrame) -> pd.DataFrame:
    """The head of a scorecard ranking (sorted by cases reached, then cost ratio) that
    cannot be told apart by timing: the same cases reached, and cost ratios within
    timing noise of the first's (:data:`truestep.measures.picks.TIE_NOISE` on each side)."""
    from truestep.measures.picks import TIE_NOISE

    top = ranked.iloc[0]
    ratio = ranked["cost_ratio"].to_numpy(float)
    same = (ranked["cases_reached"].to_numpy() == top.cases_reached) & (
        ratio / (1 + TIE_NOISE) <= float(top.cost_ratio) * (1 + TIE_NOISE)
    )
    return ranked[same]


def family_sentence(
    family: str, names: list[str], card: pd.DataFrame, fidelity: pd.DataFrame, picks: pd.DataFrame
) -> str:
    """One bullet for a family of scenes: the pick for accuracy per second, the pick for
    large steps and, where the scenes bounce, the truest restitution, with the numbers.
    ``picks``: :func:`truestep.measures.picks.cheapest` at the loosest target, named when no run
    reaches the scorecard's."""
    from truestep.cases.case import FAMILIES
    from truestep.measures.picks import SCORECARD_TARGET

    mine = card[card["family"] == family]
    parts = []
    fast = mine[np.isfinite(mine["cost_ratio"].to_numpy(float))].sort_values(
        ["cases_reached", "cost_ratio", "engine", "method"], ascending=[False, True, True, True]
    )
    if len(fast):
        top = fast.iloc[0]
        group = _tied_group(fast)
        picked = " and ".join(
            f"**{_pair(r)}** ({r.cases_reached}/{r.cases_measured})" for r in group.itertuples(index=False)
        )
        tie = " (tied within timing noise)" if len(group) > 1 else ""
        line = (
            f"for accuracy per second (most cases reached, then least time: the scorecard's "
            f"two numbers), {picked}{tie}: {SCORECARD_TARGET:g} of the scale reached on "
            f"{top.cases_reached} case(s) (of those it ran that have an error measure), in "
            f"{float(top.cost_ratio):.3g}x the fastest run's time (median)"
        )
        rest = fast.iloc[len(group) :]
        if len(rest):
            nxt = rest.iloc[0]
            line += (
                f"; next {_pair(nxt)} ({nxt.cases_reached}/{nxt.cases_measured} case(s), "
                f"{float(nxt.cost_ratio):.3g}x)"
            )
        parts.append(line)
    else:
        loose = picks[
            (picks["case"].isin(names)) & (picks["by"] == "wall_s") & (picks["engine"] != "")
        ].sort_values("wall_s")
        line = f"no run reaches {SCORECARD_TARGET:g} of the scale on any of its cases"
        if len(loose):
            r = loose.iloc[0]
            line += (
                f"; the cheapest to reach {r.target:g} is **{_pair(r)}** on {r.case} "
                f"({fmt(float(r.wall_s))} s)"
            )
        parts.append(line)
    steady = mine[np.isfinite(mine["stability_ratio"].to_numpy(float))]
    if len(steady):
        best = float(steady["stability_ratio"].max())
        high = (
            steady["stability_ratio_high"].to_numpy(float)
            if "stability_ratio_high" in steady
            else steady["stability_ratio"].to_numpy(float)
        )
        # tied with the best: within 0.5 %, or an interval that reaches the best's low end
        close = np.isclose(steady["stability_ratio"], best, rtol=5e-3)
        tops = steady[close | (high >= best)]
        tops = tops.sort_values(
            ["stability_ratio", "stability_zero", "stability_cases"],
            ascending=[False, True, False],
            kind="stable",
        )
        overlap = bool(np.any((high >= best) & ~close))
        named = ", ".join(
            f"{_pair(r)} ({r.stability_cases} search(es)"
            + (
                f"; unstable at every step on {r.stability_zero} more, as its exact limit 0 says"
                if r.stability_zero
                else ""
            )
            + ")"
            for r in tops.head(3).itertuples(index=False)
        )
        more = f" and {len(tops) - 3} more" if len(tops) > 3 else ""
        parts.append(
            f"for the largest stable step, {named}{more}: {best:.2f} of the exact or best limit"
            + (" (tied: where round-off decides a limit, their intervals overlap)" if overlap else "")
        )
    if family in ("contact", "particles") and len(fidelity):
        true = fidelity.sort_values("median").iloc[0]
        parts.append(
            f"the truest restitution, {_pair(true)} (median |e_measured - e_set| "
            f"{fmt(float(true['median']))} over {int(true.bounces)} bounces)"
        )
    return f"- **{FAMILIES.get(family, family)}** ({', '.join(names)}): " + "; ".join(parts) + "."


def scorecard_section(cases: list[Case], found: Findings, fig_dir) -> list[str]:
    """The overview at the top of the report: the scorecard figure and a sentence per
    family of scenes naming the picks."""
    from truestep.cases.case import FAMILIES
    from truestep.measures.picks import SCORECARD_TARGET
    from truestep.reporting import plots

    card, fidelity = found.scorecard, found.fidelity
    families = [f for f in FAMILIES if any(c.family == f for c in cases)]
    lines = [
        "## Which engine, which method\n",
        f"Each row is an engine and method; each column of the left panel a family of "
        f"scenes. Left: the wall time it takes to reach an error of {SCORECARD_TARGET:g} "
        f"of each case's scale, as a multiple of the fastest run that does (median over "
        f"the family's cases it reaches; `-`: it ran but never got there), and under it how "
        f"many of the family's cases it reached that accuracy on, of those it ran that have "
        f"an error measure; the sentences below rank by those two numbers, cases first. "
        f"Middle: its largest stable step over the exact limit, or over the best any method "
        f"reached where none is known (`exact 0`: the method is unstable at every step there, "
        f"as theory says). Right: how far the restitution it gives is from the one asked "
        f"(median over the bounces of the restitution sweep).\n",
    ]
    fig = plots.scorecard(card, fidelity, families, SCORECARD_TARGET, fig_dir / "scorecard.png")
    if fig is not None:
        lines.append(
            f"![scorecard: cost to reach the accuracy, stability, restitution](figures/{fig.name})\n"
        )
    loose = found.cheapest[found.cheapest["target"] == ACCURACY_TARGETS[0]]
    for family in families:
        names = [c.name for c in cases if c.family == family]
        lines.append(family_sentence(family, names, card, fidelity, loose))
    lines.append("")
    lines.append(glossary(found.notes))
    return lines


def _light_watches() -> str:
    """Which built-in engines' methods are timed from their watched run, and from which
    step (their ``watched_step_s``, read without importing an engine)."""
    from truestep.adapters.base import COPY_HIDDEN_STEP_S

    return (
        f"Drake's fixed-step methods and the reference's implicit Euler at steps of "
        f"{1000 * COPY_HIDDEN_STEP_S:g} ms or more; Drake's error-controlled methods and the "
        f"reference's Dormand-Prince at any step and however the run ended, their plain runs "
        f"keeping every step too"
    )


def methods_section(cases: list[Case]) -> list[str]:
    """How the numbers are made, with every number read from the constant that sets it."""
    from truestep.execution.analyses import RESTITUTION_DTS, RESTITUTION_SET, drop_geometry
    from truestep.execution.runner import Timing
    from truestep.measures.picks import TIE_NOISE
    from truestep.measures.stability import GROWTH_TOL, LEAVE_TOL, RISE_TOL

    radius, height, _ = drop_geometry()

    timing = Timing()
    steps = sorted({c.stability.min_steps for c in cases if c.stability})
    lines = [
        "## How the numbers are made\n",
        f"- **Timing**: scenes are built outside the timed region; each case, engine and "
        f"method runs in a process of its own, one at a time, on one thread; each row is "
        f"first run untimed and watched at every step (its numbers come from that run, "
        f"which also warms the process up), then timed, each timed run checked to end "
        f"where it did (a row of {timing.long_run_s:g} s or more is timed from its watched "
        f"run where the watch adds only a copy of the state a step, under 1% of it: "
        f"{_light_watches()}); runs shorter than "
        f"{1000 * timing.min_total_s:.0f} ms are repeated until they add up to "
        f"{1000 * timing.min_total_s:.0f} ms (at least {timing.min_repeats}, at most "
        f"{timing.max_repeats} runs), runs up to {timing.long_run_s:g} s are timed twice, "
        f"longer ones once; the wall time is the median and `wall_s_spread` half the "
        f"interquartile range. Noise is taken as a factor: a time `t` known to `r` "
        f"(its spread over `t`, and at least {100 * TIE_NOISE:.0f}%) lies between "
        f"`t / (1 + r)` and `t (1 + r)`. Runs whose intervals overlap are **tied**: a "
        f"pick names them together.",
        "- **One answer on every machine**: every column but the timings and the host "
        "is the same, bit for bit, for the same revision and package versions "
        "(`run.json` records them, and the floating-point environment).",
        "- **Engines as configured**: engine defaults that would distort a comparison "
        "are switched off (pybullet's linear and angular damping; pymunk's pixel-scale "
        "collision slop; MuJoCo's joint armature, damping and friction loss); no damping "
        "or clamp is added anywhere.",
        f"- **Errors** are distances from the exact solution (or, where none exists, "
        f"from a fine run of the reference that the case names, known along the whole "
        f"run) in the case's units, the worst over the run (`error`; `error_final` at "
        f"the end, `error_v` the velocities'); the targets "
        f"{', '.join(f'{t:g}' for t in ACCURACY_TARGETS)} are fractions of each case's "
        f"scale. **Energy drift** is the energy error over the case's energy scale (the "
        f"largest kinetic energy, or swing of potential energy, along the exact motion: "
        f"the same wherever the potential's zero lies), over every step.",
        f"- **Unstable**: the state goes non-finite; or the motion does what the scene "
        f"cannot: a bound orbit reaches its escape energy and keeps it, a damped scene "
        f"stays more than {RISE_TOL:g} of its energy scale above its start through the "
        f"late half (median), a conservative scene more than {LEAVE_TOL:g} of it through "
        f"the whole late half, or the energy keeps growing through every quarter of the "
        f"run, read at every step. A "
        f"solver that cannot solve a step is `solver-failed`, never unstable. Searches "
        f"bisect the step over each case's horizon, with at least "
        f"{', '.join(str(s) for s in steps)} steps per run; there the late half's peak "
        f"may also not rise above the early half's band by more than {GROWTH_TOL:g} of "
        f"its width; the limit found is checked below itself for a boundary that is not "
        f"monotone.",
        f"- **Surviving a hard case**: stable, not failing what the scene tests, an "
        f"error at most {SURVIVAL_ERROR:g} of the scale and an energy error at most "
        f"{SURVIVAL_ENERGY:g} of the energy.",
        f"- **Restitution**: a ball of radius {radius:g} m dropped from "
        f"{height:g} m onto a floor, restitution {', '.join(f'{e:g}' for e in RESTITUTION_SET)}"
        f" at steps {', '.join(f'1/{1 / d:.0f}' for d in RESTITUTION_DTS)} s, every step "
        f"recorded; per bounce from the rebound and impact speeds (the samples either "
        f"side of the contact) and from apex heights (the highest height each flight "
        f"reached at a step).",
        "",
    ]
    from truestep.tables.spec import markdown as columns

    lines.append(
        folded(
            "The columns of the tables (results.csv, stability.csv, restitution.csv, scaling.csv)", columns()
        )
    )
    return lines


def _run_words(run: tuple[str, str, float, str, float]) -> str:
    engine, method, dt, kind, _ = run
    at = f"tol {dt:g}" if kind == "tolerance" else f"dt {dt:g} s"
    return f"{text(engine)} / {text(method)} ({at})"


def conclusion_sentence(case: Case, c: Conclusion) -> str:
    """The line that ends a case's section: how many runs ended ok, the most accurate,
    the least and most energy drift (conserved-energy cases), and what failed; every
    number from :class:`~truestep.measures.findings.Conclusion`, none a timing."""
    if not c.runs:
        return "**In short:** no engine ran this case.\n"
    unit = case.scene.error_unit
    parts = [f"{c.ok} of {c.runs} runs ended ok"]
    if c.most_accurate is not None:
        parts.append(
            f"the most accurate is {_run_words(c.most_accurate)}, error {fmt(c.most_accurate[4])} {unit}"
        )
    if c.least_drift:
        least = ", ".join(f"{_run_words(r)} {fmt(r[4])}" for r in c.least_drift)
        parts.append(f"the least energy drift (of the energy scale): {least}")
    if c.most_drift:
        most = ", ".join(f"{_run_words(r)} {fmt(r[4])}" for r in c.most_drift)
        parts.append(f"the most: {most}")
    if c.failed:
        shown = ", ".join(f"{text(e)} / {text(m)} ({n} {st})" for e, m, st, n in c.failed[:6])
        more = f" and {len(c.failed) - 6} more" if len(c.failed) > 6 else ""
        parts.append(f"not ok: {shown}{more}")
    return "**In short:** " + "; ".join(parts) + ".\n"


TERMS = (
    (
        "scale",
        "each case's length scale for errors (its `[reference] scale`, 1 m unless the case says): "
        '"0.0001 of the scale" is an error of 1e-4 times it',
    ),
    (
        "dt",
        "the fixed step of a run, s; for an adaptive method (`dt_kind` tolerance) the tolerance it ran at "
        '(rtol = atol), shown as "tol"',
    ),
    ("error", "the largest distance from the exact solution over the run (m; an ODE's state units)"),
    (
        "energy drift",
        "the largest energy error over the run (|E(t) - E(0)| where energy is conserved, else "
        "against the exact energy curve), as a fraction of the case's energy scale (the "
        "energy the motion exchanges)",
    ),
    (
        "nfev",
        "derivative (force) evaluations: counted where the engine exposes them, else steps x its "
        "evaluations per step",
    ),
    (
        "x the fastest",
        "wall time over the fastest run that reaches the same accuracy; runs within timing "
        "noise of each other are tied and count as 1x",
    ),
)
"""The report's words and abbreviations, each in a line."""


def glossary(notes: dict[tuple[str, str], str]) -> str:
    """What the report's words and every engine/method of the run mean, folded: shown
    where the names first appear (under the scorecard)."""
    lines = [f"- **{name}**: {meaning}" for name, meaning in TERMS]
    lines += [f"- **{text(e)} / {text(m)}**: {text(note)}" for (e, m), note in notes.items()]
    return folded("What the names and numbers mean", "\n".join(lines) + "\n")


def same_scheme_section(peers: pd.DataFrame) -> list[str]:
    """ "Same scheme, same steps": each engine method beside the reference method it names
    as its scheme (the adapter's ``peers``), the ratio of their errors at equal steps, and
    a sentence naming every method whose ratio says it computes something else."""
    compared = peers[peers["rows"] > 0]
    if not len(compared):
        return []
    lo, hi = SAME
    off = compared[~compared["ratio"].between(lo, hi)]
    lines = [
        "### Same scheme, same steps\n",
        "An engine's method that names a reference method as its scheme, beside it: the ratio "
        "of their errors (engine / reference) on the same case at the same step, over every "
        "pair of rows that ended ok on the cases without contact (where engines model the "
        f"physics differently). A median ratio within {lo:g}-{hi:g} confirms the name; "
        f"{len(compared) - len(off)} of {len(compared)} do"
        + (
            ". "
            + " ".join(
                f"**{text(r.engine)} / {text(r.method)}** makes a median {_fmt(r.ratio)} times the "
                f"error of reference / {text(r.peer)} at the same step "
                f"({_fmt(r.ratio_min)} to {_fmt(r.ratio_max)} over {r.rows} rows on {r.cases} cases): "
                f"it is not {text(r.peer)} as such."
                for r in off.itertuples(index=False)
            )
            if len(off)
            else "."
        )
        + "\n",
    ]
    lines.append(folded(f"{len(compared)} engine methods beside their named scheme", md_table(compared)))
    return lines


def twin_section(twins: pd.DataFrame) -> list[str]:
    """ "One engine on two devices": each twin's rows (an engine off the CPU) beside its CPU
    engine's at the same case, method and step, and a sentence naming every row where they
    part (:func:`~truestep.measures.twins.twin_rows`); nothing where the run had no twins."""
    if not len(twins):
        return []
    lines = ["### One engine on two devices\n"]
    for (engine, base), pair in twins.groupby(["engine", "twin_of"], sort=False):
        parting = pair[pair["parts"]]
        device, there = pair["device"].iloc[0], pair["twin_device"].iloc[0]
        lines.append(
            f"**{text(engine)}** on {text(device)} is **{text(base)}** on {text(there)}: over "
            f"{len(pair)} rows at the same case, method and step, the two end alike and their errors "
            f"differ by at most {fmt(pair['band'].iloc[0])} of the case's scale (round-off) in "
            f"{len(pair) - len(parting)}; they part in {len(parting)}"
            + (
                ": "
                + "; ".join(
                    f"{text(r.case)} {text(r.method)} at {fmt(r.dt)} ("
                    + (
                        f"{text(r.status)} on {text(device)}, {text(r.twin_status)} on {text(there)}"
                        if r.status != r.twin_status
                        else f"errors {fmt(r.error)} and {fmt(r.twin_error)}, "
                        f"{fmt(r.difference)} of the scale apart"
                    )
                    + ")"
                    for r in parting.head(12).itertuples(index=False)
                )
                + (f"; and {len(parting) - 12} more" if len(parting) > 12 else "")
                + "."
                if len(parting)
                else "."
            )
            + "\n"
        )
    lines.append(folded(f"{len(twins)} twin rows", md_table(twins)))
    return lines


def costly_lines(costly: pd.DataFrame) -> list[str]:
    """The rows of over :data:`~truestep.measures.picks.LONG_ROW_S` of stepping, each with
    what it buys against its next coarser step (:func:`~truestep.measures.picks.costly_rows`)."""
    from truestep.measures.picks import LONG_ROW_S

    if not len(costly):
        return []
    lines = [
        f"The rows of more than {LONG_ROW_S:g} s of stepping, and what each buys against the same "
        "method's next coarser step of its case:\n"
    ]
    for r in costly.itertuples(index=False):
        kind = "tol" if r.dt_kind == "tolerance" else "dt"
        unit = "" if kind == "tol" else " s"
        run = f"{text(r.case)} {text(r.engine)} / {text(r.method)}"
        head = f"- {run} at {kind} {_fmt(r.dt)}{unit}: {r.wall_s:.3g} s"
        error = f"error {r.error:.3g}" if np.isfinite(r.error) else "no error measured"
        if not np.isfinite(r.coarser_dt):
            lines.append(f"{head}, {error}; the coarsest step it ran.")
            continue
        was = f"error {r.coarser_error:.3g}" if np.isfinite(r.coarser_error) else "no error measured"
        gain = (
            f": {r.wall_s / r.coarser_wall_s:.3g} times the time for an error "
            f"{r.coarser_error / r.error:.3g} times smaller"
            if np.isfinite(r.error) and np.isfinite(r.coarser_error) and r.error > 0 and r.coarser_wall_s > 0
            else ""
        )
        lines.append(
            f"{head}, {error}; at {kind} {_fmt(r.coarser_dt)}{unit}: {r.coarser_wall_s:.3g} s, {was} "
            f"({r.coarser_dt / r.dt:.3g} times the {'tolerance' if kind == 'tol' else 'step'}{gain})."
        )
    lines.append("")
    return lines


def refined_lines(refined: list[dict]) -> list[str]:
    """The methods whose sweeps the run carried on to finer steps
    (:mod:`truestep.execution.refine`, ``run.json``'s ``refined``), each with the order its
    case's sweep gave and the steps added."""
    if not refined:
        return []
    said = "; ".join(
        f"{text(r['case'])} {text(r['engine'])} / {text(r['method'])}: {float(r['order']):.2f} over the "
        f"case's sweep (declared {float(r['declared']):g}), also run at dt "
        + ", ".join(_fmt(float(d)) for d in r["dts"])
        + " s"
        for r in refined
    )
    return [
        "Sweeps carried on to finer steps, because the order fitted over the case's own steps "
        "fell short of the declared one, or the error did not fall there at all (a correct "
        f"method converges there and is judged there; a wrong one does not, and fails): {said}.\n"
    ]
