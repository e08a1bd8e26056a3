"""The largest stable time step: a stability criterion and a bisection on dt.

A run is **unstable** when its state goes non-finite, or when its energy grows without
bound. Growth is judged by comparing the late half of the run with the early half,
not by a fixed blow-up factor. With ``D(t) = E(t) - E(0)`` and the early half's band
``[lo, hi]`` of ``D`` (``D(0) = 0`` included), the run grows when the late half's peak
exceeds ``hi + tol (hi - lo)`` plus a round-off floor: the energy climbs above everything
it did early by more than ``tol`` of the early swing.

- A bounded oscillation of energy (a symplectic method below its limit) repeats its band.
  The band's edges may drift while modes beat against each other or a slow mode turns
  round (a chain's light particles rattling between heavy ones), by far less than the
  band is wide; a method whose energy error stays below ``E(0)`` (Verlet's, often) has
  ``hi = 0`` and wobbles near it without counting as growth.
- Growth from ``D(0) = 0`` that is exponential (or faster than linear) gives
  ``D(T) >= 2 D(T/2)``, with ``lo = 0``: a rise of 100% of the band, whatever the rate.
- A damped or dissipative run's energy only falls: its late peak stays below ``hi``.

In a **dissipative** scene (damping, drag or inelastic contact, and no energy source) the
exact energy never rises, so a run whose energy *stays* above its start is unstable
wherever in the run the rise happened (:func:`energy_stays_up`): near their limit,
methods on a damped cloth pump energy in faster than the dampers take it out, and the
energy swings up to tens of times its start and stays there without growing further.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from truestep.adapters.base import Trajectory
from truestep.cases.case import Case

GROWTH_TOL = 0.25
"""Rise of the late half's energy peak above the early half's band, as a fraction of the
band's width, that counts as growth.

Exponential growth rises by at least 100%; bounded oscillations of multi-mode scenes
drift by about 10% over a few thousand steps (spring-chain, mass-ratio-chain). Near a
limit the growth is fast enough that the tolerance moves a bisection by far less than
its 0.1% bracket (measured on the oscillators: the limits do not change)."""
ROUNDOFF = 1e-9
"""Energy rises below this fraction of the energy scale are round-off, not growth."""
MIN_STEPS = 5000  # the default of StabilitySpec.min_steps
"""The default least number of steps of a search run (``[stability] min_steps``): slow
growth near a limit needs them."""
QUICK_MIN_STEPS = 2000
"""Steps per run in ``--quick`` searches, which stop at 1% of the limit."""


def energy_grows(t: np.ndarray, energy: np.ndarray, *, tol: float | None = None) -> bool:
    """Whether ``energy`` (J, shape (T,), at times ``t``) grows without bound.

    ``tol`` defaults to :data:`GROWTH_TOL`.
    """
    tol = GROWTH_TOL if tol is None else tol
    energy = np.asarray(energy, float)
    if not np.all(np.isfinite(energy)):
        return True
    d = energy - energy[0]
    half = max(int(np.searchsorted(t, t[0] + 0.5 * (t[-1] - t[0]))), 1)
    early, late = d[:half], d[half:]
    if not len(late):
        return False
    scale = max(abs(energy[0]), float(np.max(np.abs(energy))), 1e-300)
    hi, lo = float(np.max(early)), float(np.min(early))
    return float(np.max(late)) > hi + tol * (hi - lo) + ROUNDOFF * scale


SETTLE_TOL = 0.5
"""In a dissipative scene: how far above its start the late half's median energy may stay,
as a fraction of the energy the run gave off (``E(0) - min E``). Stable runs end below
their start (hanging-cloth at 0.9x the old limit: -0.37); runs that pump energy in stay
above it by about one to seventy times what they gave off (0.95x to 0.995x the old
limit: 0.76 to 71). Both are checked in ``tests/test_stability_and_restitution.py``."""


def energy_stays_up(t: np.ndarray, energy: np.ndarray, *, tol: float | None = None) -> bool:
    """Whether ``energy`` (J, shape (T,), at times ``t``) of a dissipative scene stays
    above its start: the median of the late half exceeds ``E(0)`` by more than ``tol``
    (default :data:`SETTLE_TOL`) times the energy given off, ``E(0) - min E``."""
    tol = SETTLE_TOL if tol is None else tol
    energy = np.asarray(energy, float)
    if not np.all(np.isfinite(energy)):
        return True
    half = max(int(np.searchsorted(t, t[0] + 0.5 * (t[-1] - t[0]))), 1)
    late = energy[half:]
    if not len(late):
        return False
    scale = max(float(np.max(np.abs(energy))), 1e-300)
    given_off = max(float(energy[0] - np.min(energy)), ROUNDOFF * scale)
    return float(np.median(late)) - float(energy[0]) > tol * given_off


def energy_keeps_growing(t: np.ndarray, energy: np.ndarray, *, tol: float | None = None) -> bool:
    """Whether ``energy`` grows in every quarter of the run: each quarter's peak rises above
    the band of the quarter before it (the test of :func:`energy_grows`, quarter by
    quarter). Exponential or steady growth does; a single jump (a close encounter taken
    with too large a step) followed by a plateau does not, wherever the jump falls."""
    energy = np.asarray(energy, float)
    if not np.all(np.isfinite(energy)):
        return True
    tol = GROWTH_TOL if tol is None else tol
    edges = np.searchsorted(t, t[0] + (t[-1] - t[0]) * np.array([0.25, 0.5, 0.75]))
    quarters = [q for q in np.split(energy - energy[0], edges) if len(q)]
    if len(quarters) < 4:
        return energy_grows(t, energy, tol=tol)
    start = abs(float(energy[0]))
    for before, now in itertools.pairwise(quarters):
        hi, lo = max(float(np.max(before)), 0.0), min(float(np.min(before)), 0.0)
        # Round-off is judged against the energy so far, not the run's largest: a run that
        # explodes would otherwise hide its early quarters' growth under its final size.
        floor = ROUNDOFF * max(start, float(np.max(np.abs(before + energy[0]))), 1e-300)
        if not float(np.max(now)) > hi + tol * (hi - lo) + floor:
            return False
    return True


def is_stable(traj: Trajectory, *, dissipative: bool = False) -> bool:
    """Stable: finished, finite, and (where it has one) energy that does not grow; in a
    ``dissipative`` scene, also energy that does not stay above its start."""
    if traj.status != "ok":
        return False
    if traj.energy is None:
        return True
    if dissipative and energy_stays_up(traj.t, traj.energy):
        return False
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


class SearchTimeout(Exception):
    """A search still running when its safety limit (``[stability] budget_s``) ran out:
    its row is ``timeout`` and reports no limit, so that no machine's speed decides one."""


def bisect_limit(
    stable_at: Callable[[float], bool],
    dt_lo: float,
    dt_hi: float,
    *,
    rel_tol: float = 1e-3,
    max_runs: int = 30,
    budget_s: float = math.inf,
) -> SearchResult:
    """Bisect (geometrically) for the boundary between stable and unstable steps.

    Assumes stability is monotone in dt. Bounded by work alone: it stops when
    ``dt_unstable / dt_limit - 1`` is below ``rel_tol`` or after ``max_runs`` calls of
    ``stable_at``, so the same code gives the same bracket on every machine. ``budget_s``
    is a safety valve, not a bound: a search whose calls have taken longer raises
    :class:`SearchTimeout` instead of reporting the bracket it happened to reach.
    """
    start = time.perf_counter()

    def stable(dt: float) -> bool:
        if time.perf_counter() - start > budget_s:
            raise SearchTimeout(f"still searching after its {budget_s:g} s safety limit "
                                f"([stability] budget_s), at {runs} runs: no limit reported")
        return stable_at(dt)

    runs = 1
    if not stable(dt_lo):
        return SearchResult(0.0, dt_lo, runs, f"unstable at every step tried (even {dt_lo:g} s)")
    runs += 1
    if stable(dt_hi):
        return SearchResult(dt_hi, math.inf, runs, f"stable at every step tried (up to {dt_hi:g} s)")
    lo, hi = dt_lo, dt_hi
    while hi / lo - 1 > rel_tol and runs < max_runs:
        mid = math.sqrt(lo * hi)
        runs += 1
        if stable(mid):
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
    :data:`QUICK_MIN_STEPS` steps. A search still running after ``budget_s`` seconds
    raises :class:`SearchTimeout` (a safety valve: it never shortens a search).
    """
    from truestep.metrics import energy_behaviour

    spec = case.stability
    min_steps = min(QUICK_MIN_STEPS, spec.min_steps) if quick else spec.min_steps
    rel_tol = max(spec.rel_tol, 1e-2) if quick else spec.rel_tol
    dissipative = energy_behaviour(case) == "dissipative"

    def stable_at(dt: float) -> bool:
        n = max(min_steps, math.ceil(spec.horizon / dt))
        trial = dataclasses.replace(case, duration=n * dt, max_records=n)
        return is_stable(simulate(trial, dt), dissipative=dissipative)

    return bisect_limit(stable_at, spec.dt_lo, spec.dt_hi, rel_tol=rel_tol,
                        max_runs=spec.max_runs, budget_s=spec.budget_s)
