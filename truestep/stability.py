"""The largest stable time step: a stability criterion and a bisection on dt.

A run is **unstable** when its state goes non-finite, or when its energy grows without
bound. Growth is judged by comparing the late half of the run with the early half,
not by a fixed blow-up factor: with ``D(t) = E(t) - E(0)``, the run grows when
``max D`` over the second half exceeds ``(1 + tol)`` times ``max(max D over the first
half, 0)`` plus a round-off floor. A bounded oscillation of energy (a symplectic method
below its limit) reaches the same peaks in both halves; exponential growth from
``D(0) = 0`` gives a ratio of at least 2 (``(a^2 - 1) / (a - 1) = a + 1``); a decaying
or dissipated energy never rises above its start.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from adapters.base import Trajectory
from cases.case import Case

GROWTH_TOL = 0.05
"""Relative rise of the late-half energy peak over the early-half peak that counts as growth.

Bounded oscillations sampled over many periods repeat their peaks to far better than 5%;
exponential growth gives a ratio of at least 2."""
ROUNDOFF = 1e-9
"""Energy rises below this fraction of the energy scale are round-off, not growth."""
MIN_STEPS = 5000  # the default of StabilitySpec.min_steps
"""The default least number of steps of a search run (``[stability] min_steps``): slow
growth near a limit needs them."""
QUICK_MIN_STEPS = 2000
"""Steps per run in ``--quick`` searches, which stop at 1% of the limit."""


def energy_grows(t: np.ndarray, energy: np.ndarray, *, tol: float = GROWTH_TOL) -> bool:
    """Whether ``energy`` (J, shape (T,), at times ``t``) grows without bound."""
    energy = np.asarray(energy, float)
    if not np.all(np.isfinite(energy)):
        return True
    d = energy - energy[0]
    half = np.searchsorted(t, t[0] + 0.5 * (t[-1] - t[0]))
    early, late = d[: max(half, 1)], d[max(half, 1) :]
    if not len(late):
        return False
    scale = max(abs(energy[0]), float(np.max(np.abs(energy))), 1e-300)
    late_peak = float(np.max(late))
    early_peak = max(float(np.max(early)), 0.0)
    return late_peak > (1 + tol) * early_peak + ROUNDOFF * scale


def is_stable(traj: Trajectory) -> bool:
    """Stable: finished, finite, and (where it has one) energy that does not grow."""
    if traj.status != "ok":
        return False
    if traj.energy is None:
        return True
    return not energy_grows(traj.t, traj.energy)


@dataclass
class SearchResult:
    """The outcome of one bisection.

    dt_limit : largest step found stable (s); 0 if even ``dt_lo`` was unstable
    dt_unstable : smallest step found unstable (s); inf if even ``dt_hi`` was stable
    runs : simulations made;  note : how to read the limit
    """

    dt_limit: float
    dt_unstable: float
    runs: int
    note: str


def bisect_limit(
    stable_at: Callable[[float], bool],
    dt_lo: float,
    dt_hi: float,
    *,
    rel_tol: float = 1e-3,
    max_runs: int = 30,
) -> SearchResult:
    """Bisect (geometrically) for the boundary between stable and unstable steps.

    Assumes stability is monotone in dt. Stops when ``dt_unstable / dt_limit - 1`` is
    below ``rel_tol`` or after ``max_runs`` calls of ``stable_at``.
    """
    runs = 1
    if not stable_at(dt_lo):
        return SearchResult(0.0, dt_lo, runs, f"unstable at every step tried (even {dt_lo:g} s)")
    runs += 1
    if stable_at(dt_hi):
        return SearchResult(dt_hi, math.inf, runs, f"stable at every step tried (up to {dt_hi:g} s)")
    lo, hi = dt_lo, dt_hi
    while hi / lo - 1 > rel_tol and runs < max_runs:
        mid = math.sqrt(lo * hi)
        runs += 1
        if stable_at(mid):
            lo = mid
        else:
            hi = mid
    note = "" if hi / lo - 1 <= rel_tol else f"stopped after {runs} runs"
    return SearchResult(lo, hi, runs, note)


def search_case(case: Case, simulate: Callable[[Case, float], Trajectory], *,
                quick: bool = False) -> SearchResult:
    """Bisect ``case.stability``'s bracket; ``simulate(case, dt)`` runs one engine and method.

    Each run covers the horizon, and at least :data:`MIN_STEPS` steps, recording every step.
    ``quick`` stops at 1% instead of the case's ``rel_tol`` and runs at least
    :data:`QUICK_MIN_STEPS` steps.
    """
    spec = case.stability
    min_steps = min(QUICK_MIN_STEPS, spec.min_steps) if quick else spec.min_steps
    rel_tol = max(spec.rel_tol, 1e-2) if quick else spec.rel_tol

    def stable_at(dt: float) -> bool:
        n = max(min_steps, math.ceil(spec.horizon / dt))
        trial = dataclasses.replace(case, duration=n * dt, max_records=n)
        return is_stable(simulate(trial, dt))

    return bisect_limit(stable_at, spec.dt_lo, spec.dt_hi, rel_tol=rel_tol,
                        max_runs=spec.max_runs)
