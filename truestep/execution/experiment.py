"""The one experiment driver: a run of cases and engines from the sweep to its findings.

``truestep run`` and :func:`truestep.run` both come here (:func:`run_experiment`) once their
cases and engines are chosen and the output folder, if any, is checked and locked. It owns
what every run shares: the journal beside the output (checkpoints for ``--resume``), the
run's budget (:func:`truestep.runtime.isolation.set_run_budget`), the Dask cluster of
``--scheduler`` (:mod:`truestep.execution.cluster`), the sweep
(:func:`truestep.execution.runner.run_matrix`, each run isolated in a process of its own),
the analyses (:func:`truestep.execution.analyses.run_analyses`: stability searches, the
restitution sweep, scaling); it returns the tables and findings, and the caller's
``report`` hook (the API's) publishes them while the journal still keeps the run.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd

from truestep.cases.case import Case
from truestep.measures.restitution import with_contact_notes

if TYPE_CHECKING:
    from truestep.execution.cluster import Cluster
    from truestep.measures.findings import Findings
    from truestep.runtime.isolation import Lanes


@dataclass
class Tables:
    """The tables of one run (as ``truestep run`` writes them) and the cases they cover.

    results : one row per (case, engine, method, dt) (``results.csv``)
    stability : largest stable steps (``stability.csv``), empty if not searched
    restitution : bounces per engine, method, step and set restitution (``restitution.csv``)
    scaling : particle-steps per second against n on the rain scene (``scaling.csv``),
        empty in a ``quick`` run or without the rain case
    seconds : wall time of each phase of the run that made them (``sweep``, ``analyses``,
        ``report``), s
    findings : what the run found (:class:`truestep.measures.findings.Findings`: picks, orders,
        scorecard), computed once beside the analyses; ``None`` without them
    numerics : the floating-point environment the run computed in
        (:func:`truestep.numerics.fingerprint`, as ``run.json`` records it): a run with the
        same record and truestep version gives the same non-timing cells bit for bit
    """

    results: pd.DataFrame
    stability: pd.DataFrame = field(default_factory=pd.DataFrame)
    restitution: pd.DataFrame = field(default_factory=pd.DataFrame)
    cases: list[Case] = field(default_factory=list)
    scaling: pd.DataFrame = field(default_factory=pd.DataFrame)
    seconds: dict[str, float] = field(default_factory=dict)
    findings: Findings | None = None
    numerics: dict = field(default_factory=dict)


@dataclass
class Experiment:
    """What to run and where its outputs go.

    cases, engines : the cases and the engines' registered names
    quick : the ``--quick`` sweep;  analyses : also the stability searches, the restitution
    sweep and scaling
    out : the report's folder (checked and locked by the caller), or ``None`` for tables only
    resume : a folder whose journal the run continues from (``--resume``)
    scheduler : a Dask scheduler address or ``local:N`` (``--scheduler``)
    budget : the run's time budget, s (``--budget``)
    argv : the ``truestep`` arguments that reproduce the run (the report names them)
    lecture_figures : also draw the lecture's figures into the report
    rows : each result row's line goes here (default: a progress bar on standard error)
    say : what the run has to say (resuming, a lost lock taken over)
    report : what publishes the report once the analyses are done (the API's, with an
        output folder), while the journal still keeps the run; ``None``: tables only
    devices : the engines put off the CPU and their devices (``--device``, resolved by
        :func:`truestep.adapters.devices.resolve`; the caller sets them in the environment)
    """

    cases: list[Case]
    engines: list[str]
    quick: bool = False
    analyses: bool = True
    out: Path | None = None
    resume: Path | None = None
    scheduler: str | None = None
    budget: float | None = None
    argv: list[str] = field(default_factory=lambda: ["run"])
    lecture_figures: bool = False
    rows: Callable[[str], None] | None = None
    say: Callable[[str], None] = print
    report: Callable[[Finished], None] | None = None
    devices: dict[str, str] = field(default_factory=dict)


@dataclass
class Finished:
    """A run's sweep and analyses as its report reads them (:attr:`Experiment.report`).

    results : the results table;  tables : the analyses' tables by name (``stability``,
    ``restitution``, ``scaling``);  traces : the trajectories the report's figures draw,
    by (case, engine, method);  findings : what the run found, ``None`` without analyses;
    seconds : wall time of each phase so far, s (``run.json`` keeps them)
    """

    results: pd.DataFrame
    tables: dict[str, pd.DataFrame]
    traces: dict
    findings: Findings | None
    seconds: dict[str, float]


def run_experiment(exp: Experiment) -> Tables:
    """Run ``exp``: the sweep (checkpointed in the journal when there is an output folder),
    the analyses, then ``exp.report`` (the driver draws nothing itself). Raises
    :class:`~truestep.execution.journal.JournalError` when ``resume`` holds no run of these
    cases and engines, and :class:`~truestep.execution.cluster.ClusterError` (saying what the
    journal keeps) when the cluster cannot be reached or goes away."""
    from truestep.execution.runner import run_matrix
    from truestep.measures.findings import find
    from truestep.numerics import fingerprint
    from truestep.runtime import publish
    from truestep.runtime.isolation import Lanes, set_run_budget, untimed_workers

    journal = None
    if exp.out is not None:
        for line in publish.recover(exp.out):
            exp.say(f"{exp.out}: {line} (left by a killed run)")
        journal = _journal(exp)
    set_run_budget(exp.budget)
    laps = _Laps()
    traces: dict = {}
    kinds: dict[str, float] = {}  # the analyses' seconds, per kind
    try:
        with _cluster(exp.scheduler, journal) as cluster:
            ahead = _untimed_ahead(exp, journal, cluster)
            with Lanes(untimed_workers(), ahead or ()) as lanes:
                results = run_matrix(
                    exp.cases,
                    exp.engines,
                    quick=exp.quick,
                    progress=exp.rows,
                    traces=traces,
                    journal=journal,
                    cluster=cluster,
                    lanes=lanes,
                )
                results = _refined(exp, results, lanes)
                laps.lap("sweep")
                tables = _analyses(exp, results, journal, kinds, ahead, lanes)
            contact = {c.name for c in exp.cases if getattr(c.scene, "planes", None)}
            with_contact_notes(results, tables.get("restitution"), contact)
            found = find(exp.cases, results, tables) if exp.analyses else None
            laps.lap("analyses")
        if exp.report is not None:
            seconds = {**laps.seconds, **results.attrs.get("sweep_seconds", {}), **kinds}
            exp.report(Finished(results, tables, traces, found, seconds))
            laps.lap("report")
    finally:
        set_run_budget(None)
    if journal is not None:
        journal.remove()
    return Tables(
        results,
        tables["stability"],
        tables["restitution"],
        exp.cases,
        tables["scaling"],
        seconds=laps.seconds,
        findings=found,
        numerics=fingerprint(),
    )


def _refined(exp: Experiment, results: pd.DataFrame, lanes: Lanes) -> pd.DataFrame:
    """``results`` with the finer steps of the methods short of their declared order
    (:func:`truestep.execution.refine.refine`, run through ``lanes``), which
    ``results.attrs["refined"]`` names for ``run.json``."""
    from truestep.execution.refine import refine

    results, refined = refine(exp.cases, exp.engines, results, quick=exp.quick, say=exp.say, lanes=lanes)
    if refined:
        results.attrs["refined"] = [r.record() for r in refined]
    return results


def _journal(exp: Experiment):
    """The run's journal: started afresh, or (``resume``) the one it continues from."""
    from truestep.execution.journal import Journal, fingerprint

    assert exp.out is not None
    journal = Journal(exp.resume or exp.out)
    fp = fingerprint(exp.cases, exp.engines, exp.quick, exp.devices)
    if exp.resume is None:
        journal.start(fp)
        return journal
    kept = journal.resume(fp)
    exp.say(f"resuming: {kept} finished sweeps in {journal.dir}")
    if journal.ignored_line():
        exp.say(journal.ignored_line())
    return journal


def _kept_analyses(exp: Experiment, journal) -> dict | None:
    """The analyses' tables of the run ``exp`` resumes, if it finished them."""
    return journal.analyses() if journal is not None and exp.resume is not None else None


def _untimed_ahead(exp: Experiment, journal, cluster: Cluster | None) -> list | None:
    """The analyses' untimed runs (searches, drops), planned to run on the cores the sweep's
    and the refinement's timed runs leave (:func:`truestep.execution.analyses.untimed_parts`,
    the backlog of the run's :class:`~truestep.runtime.isolation.Lanes`), where they are
    to run on this machine and the run has not kept their tables; else ``None``."""
    from truestep.execution.analyses import untimed_parts
    from truestep.numerics import own_run

    if not exp.analyses or cluster is not None or _kept_analyses(exp, journal) is not None:
        return None
    with own_run():
        return untimed_parts(exp.cases, exp.engines, quick=exp.quick, progress=exp.rows)


def _analyses(
    exp: Experiment,
    results: pd.DataFrame,
    journal,
    seconds: dict[str, float],
    ran: list | None,
    lanes: Lanes,
) -> dict:
    """The analyses' tables: from the journal of a resumed run that finished them, else
    made (their untimed parts in the backlog of ``lanes`` where ``ran`` holds them; kept
    in the journal; ``seconds`` receives each kind's wall time)."""
    from truestep.execution.analyses import run_analyses

    if not exp.analyses:
        return {"stability": pd.DataFrame(), "restitution": pd.DataFrame(), "scaling": pd.DataFrame()}
    tables = _kept_analyses(exp, journal)
    if tables is None:
        tables = run_analyses(
            exp.cases,
            exp.engines,
            results,
            quick=exp.quick,
            progress=exp.rows,
            seconds=seconds,
            ran=ran,
            lanes=lanes,
        )
        if journal is not None:
            journal.put_analyses(tables)
    return tables


class _Laps:
    """Wall time of each phase, s."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, phase: str) -> None:
        now = time.perf_counter()
        self.seconds[phase] = now - self._last
        self._last = now


@contextlib.contextmanager
def _cluster(address: str | None, journal) -> Iterator[Cluster | None]:
    """The Dask cluster of ``--scheduler`` for the sweep and the untimed analyses (``None``
    without one); a cluster that cannot be reached, or goes away, is one
    :class:`~truestep.execution.cluster.ClusterError` saying what the journal keeps for ``--resume``."""
    if address is None:
        yield None
        return
    from truestep.execution.cluster import Cluster, ClusterError
    from truestep.runtime.isolation import set_untimed_runner

    try:
        with Cluster(address) as cluster:
            set_untimed_runner(cluster)
            try:
                yield cluster
            finally:
                set_untimed_runner(None)
    except ClusterError as err:
        kept = (
            f"; {journal.finished()} finished sweeps are kept in {journal.dir} "
            "(the same command with --resume continues from them)"
            if journal is not None
            else ""
        )
        raise ClusterError(f"{err}{kept}") from None
