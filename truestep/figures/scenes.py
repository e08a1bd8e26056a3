"""The scenes of the lecture's figures: case files, run by the reference adapter.

Every figure's scene is a case file, of ``cases/figures/`` (installed as
``truestep/cases/figures/``; ``truestep run`` does not run them) or of the case library,
loaded by :func:`truestep.cases.loader.load_case` and run by
:class:`truestep.adapters.reference.ReferenceAdapter` like any row of a benchmark. A
figure that sweeps a parameter (another step, duration, start or restitution) runs
variants of one case made with :func:`dataclasses.replace`; the figures only draw what
the trajectories hold.
"""

from __future__ import annotations

from dataclasses import replace

from truestep.adapters.base import Trajectory
from truestep.adapters.reference import ReferenceAdapter
from truestep.cases.case import Case
from truestep.cases.loader import CASE_DIR, load_case

FIGURE_CASE_DIR = CASE_DIR / "figures"
"""Directory of the figures' own case files."""


def figure_case(name: str) -> Case:
    """The case ``cases/figures/<name>.toml``."""
    return load_case(FIGURE_CASE_DIR / f"{name}.toml")


def library_case(name: str) -> Case:
    """The case ``<name>`` of truestep's own case library (``cases/<name>.toml``)."""
    return load_case(CASE_DIR / f"{name}.toml")


def run_reference(case: Case, method: str, dt: float | None = None) -> Trajectory:
    """``case`` run by the reference adapter with ``method``, every step recorded.

    ``dt`` : step (s), or tolerance for an adaptive method; default the first of the
    case's sweep. A run that does not end ``ok`` raises, naming the case: a figure drawn
    from a failed run would show something else than its caption says.
    """
    adapter = ReferenceAdapter()
    adaptive = method in adapter.adaptive_methods
    if dt is None:
        dt = case.sweep(adaptive=adaptive, quick=False)[0]
    if not adaptive:
        case = replace(case, max_records=max(case.max_records, case.steps_for(dt)[0]))
    traj = adapter.simulate(case, method, dt)
    if traj.status != "ok":
        raise RuntimeError(
            f"figure case {case.name}: reference / {method} at {dt:g} ended "
            f"{traj.status} (t = {traj.t_fail}) {traj.message}".rstrip()
        )
    return traj


def step_taken(case: Case, dt: float) -> float:
    """The step (s) the adapter takes for a nominal ``dt``: the one that fills the duration."""
    return case.steps_for(dt)[1]
