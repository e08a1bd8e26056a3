"""Stable or not, read from the motion; and the largest stable time step, by bisection.

A run is **unstable** when its state goes non-finite, or when its motion does what the
scene cannot do (:func:`motion_failure`), each judged against the case's energy scale
``S`` (:func:`truestep.measures.energy_scale.energy_scale`, the same wherever the potential's zero
lies), over every step where the run was watched at every step:

- **escape**: a case that declares an escape energy (``[reference] escape_energy``: a bound
  orbit's is 0) reaches it and stays there to the end (a symplectic method's energy
  error spikes through a close encounter and comes back: no escape);
- **gain**: a dissipative scene (damping, drag, inelastic or frictional contact, no energy
  source) keeps its energy more than :data:`RISE_TOL` of ``S`` above its start through the
  late half of the run (its median), wherever in the run the rise began (a stable
  method's overshoot that it then gives off is no gain);
- **left for good**: a conservative scene's energy rises above its start by more than
  :data:`LEAVE_TOL` of ``S`` and never comes back within it in the late half of the run
  (a jump to another energy that then stays, as an orbit taken with too large a step
  through its pericentre does);
- **growth**: the energy of a passive scene keeps growing through every quarter of the
  run (:func:`energy_keeps_growing`) once it has moved by more than ``S``;
- **self-excited**: a dissipative scene that came near rest (its kinetic energy, the
  largest over a stretch of :data:`WINDOWS`-th of the run, fallen below :data:`SETTLED` of
  its earlier largest) and then moves again, its kinetic energy :data:`REGROWN` times that
  and more, with energy put in to do it (the total energy above its lowest before by at
  least :data:`PUT_IN` of that kinetic energy): a flapping that a scene which only loses energy cannot
  start (Newton's VBD on the hanging cloth at 0.02 s, settled by 2.5 s, flapping from 5 s
  on with its total energy still far below its start). Kinetic energy that merely comes
  back from potential energy (a ball falling again from its apex) puts no energy in.

A bounded oscillation of energy (a symplectic method below its limit) comes back to its
start in every period and is none of these; a damped run's energy falls.

The stability search (:func:`search_case`) is stricter about growth: the late half's peak
may not rise above the early half's band (:func:`energy_grows`). With ``D(t) = E(t) -
E(0)`` and the early half's band ``[lo, hi]`` of ``D`` (``D(0) = 0`` included), the run
grows when the late half's peak exceeds ``hi + tol (hi - lo)`` plus a round-off floor.
Exponential growth from ``D(0) = 0`` gives ``D(T) >= 2 D(T/2)``: a rise of 100% of the
band, whatever the rate. A step at which the solver fails (status ``solver-failed``) is
neither stable nor unstable: the search stops and says so.
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
from truestep.cases.case import Case, OdeSpec

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
WINDOWS = 30
SETTLED = 1e-2
REGROWN = 100.0
MOVES = 1e-4
PUT_IN = 0.25
"""How a self-excited run is told (see the module docstring): the run cut into
:data:`WINDOWS` stretches of equal time, each read by its largest kinetic energy; settled
below :data:`SETTLED` of the largest before, moving again at :data:`REGROWN` times the settled
stretch's and at least :data:`MOVES` of the energy scale, the total energy then above its
lowest before by :data:`PUT_IN` of that kinetic energy or more."""
QUICK_MIN_STEPS = 2000
"""Steps per run in ``--quick`` searches, which stop at 1% of the limit."""


def _floor(scale: float | None, energy: np.ndarray) -> float:
    """The round-off floor of energy changes, J: :data:`ROUNDOFF` of the energy scale (of
    the largest energy of the run when no scale is given)."""
    if scale is None or not np.isfinite(scale):
        scale = max(float(np.max(np.abs(energy))), 1e-300)
    return ROUNDOFF * scale


def energy_grows(
    t: np.ndarray, energy: np.ndarray, *, tol: float | None = None, scale: float | None = None
) -> bool:
    """Whether ``energy`` (J, shape (T,), at times ``t``) grows without bound: the late
    half's peak above the early half's band (the search's test, see the module docstring).

    ``tol`` defaults to :data:`GROWTH_TOL`; ``scale`` is the case's energy scale (J), whose
    :data:`ROUNDOFF` is the floor below which a rise is round-off.
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
    hi, lo = float(np.max(early)), float(np.min(early))
    return float(np.max(late)) > hi + tol * (hi - lo) + _floor(scale, energy)


def energy_keeps_growing(
    t: np.ndarray, energy: np.ndarray, *, tol: float | None = None, scale: float | None = None
) -> bool:
    """Whether ``energy`` grows in every quarter of the run: each quarter's peak rises above
    the band of the quarter before it (the test of :func:`energy_grows`, quarter by
    quarter). Exponential or steady growth does; a single jump (a close encounter taken
    with too large a step) followed by a plateau does not, wherever the jump falls.
    ``scale``: as :func:`energy_grows` (without one, the energy so far sets the floor)."""
    energy = np.asarray(energy, float)
    if not np.all(np.isfinite(energy)):
        return True
    tol = GROWTH_TOL if tol is None else tol
    edges = np.searchsorted(t, t[0] + (t[-1] - t[0]) * np.array([0.25, 0.5, 0.75]))
    quarters = [q for q in np.split(energy - energy[0], edges) if len(q)]
    if len(quarters) < 4:
        return energy_grows(t, energy, tol=tol, scale=scale)
    start = abs(float(energy[0]))
    for before, now in itertools.pairwise(quarters):
        hi, lo = max(float(np.max(before)), 0.0), min(float(np.min(before)), 0.0)
        # Without a scale, round-off is judged against the energy so far, not the run's
        # largest: a run that explodes would hide its early quarters' growth under its end.
        floor = (
            ROUNDOFF * scale
            if scale is not None and np.isfinite(scale)
            else ROUNDOFF * max(start, float(np.max(np.abs(before + energy[0]))), 1e-300)
        )
        if not float(np.max(now)) > hi + tol * (hi - lo) + floor:
            return False
    return True


RISE_TOL = 0.1
"""How far above its start, as a fraction of the energy scale, a dissipative scene's energy
may stay through the late half of a run (its median there). A stable method may overshoot
for a while and then give the energy off: symplectic Euler on the damped oscillator at 0.47
of its limit peaks 0.16 of the scale above the start, at 0.99 of it 24 scales, and both
decay to nothing; methods that pump a damped cloth near their limit keep it 0.5 to 12
scales above the start through the late half."""
LEAVE_TOL = 0.5
"""How far above its start, as a fraction of the energy scale, a conservative scene's energy
may stay through the late half of a run. A bounded energy error comes back to the start in
every period of the motion; an orbit taken through its pericentre with too large a step
jumps by 0.49 to 11 of its scale and stays there."""


@dataclass(frozen=True)
class Failure:
    """Why a finite run's motion is not the scene's: when (s) and what happened."""

    t: float
    reason: str


def motion_failure(case: Case, traj: Trajectory, scale: float) -> Failure | None:
    """How a finite run's motion broke what the scene allows, or ``None``.

    ``scale``: the case's energy scale, J (:func:`truestep.measures.energy_scale.energy_scale`).
    Reads the energy at every step where the run was watched at every step
    (:meth:`Trajectory.watched`), else at its records. See the module docstring for the
    four failures: escape, gain, left for good, growth.
    """
    from truestep.measures.metrics import energy_behaviour

    t, e = traj.watched()
    if e is None or len(e) < 2 or not np.isfinite(scale):
        return None
    t, e = np.asarray(t, float), np.asarray(e, float)
    e0 = float(e[0])
    escape = case.escape_energy
    if escape is not None and e[-1] >= escape:
        below = np.nonzero(e < escape)[0]
        first = int(below[-1]) + 1 if len(below) else 0  # above it from here to the end
        return Failure(
            float(t[first]),
            f"escaped: its energy rose to {e[first]:.4g} J, at or "
            f"above the case's escape energy {escape:g} J, and stayed there",
        )
    behaviour = energy_behaviour(case)
    if behaviour == "source":
        return None
    rise = e - e0
    far = np.abs(rise) > scale
    if far.any() and energy_keeps_growing(t, e, scale=scale):
        first = int(np.argmax(far))
        return Failure(
            float(t[first]),
            f"finite, but its energy grew from {e0:.4g} J to {e[-1]:.4g} J and was still rising",
        )
    half = max(int(np.searchsorted(t, t[0] + 0.5 * (t[-1] - t[0]))), 1)
    late = rise[half:]
    if behaviour == "dissipative" and (excited := self_excited(case, traj, scale)) is not None:
        return excited
    if behaviour == "dissipative":
        if len(late) and float(np.median(late)) > RISE_TOL * scale:
            first = int(np.argmax(rise > RISE_TOL * scale))
            return Failure(
                float(t[first]),
                f"a dissipative scene gained energy and kept it: "
                f"{rise[first] / scale:.3g} of its scale ({scale:.4g} J) above its "
                f"start from here, {float(np.median(late)) / scale:.3g} through the "
                "late half (median)",
            )
    else:
        if len(late) and float(np.min(late)) > LEAVE_TOL * scale:
            first = int(np.argmax(rise > LEAVE_TOL * scale))
            return Failure(
                float(t[first]),
                f"its energy left its start for good: "
                f"{rise[first] / scale:.3g} of its scale ({scale:.4g} J) above it "
                "and never back in the late half",
            )
    return None


def self_excited(case: Case, traj: Trajectory, scale: float) -> Failure | None:
    """A dissipative scene's run that settled and then moves again with energy put in
    (the module docstring's **self-excited**), read from its records' velocities and
    energies; ``None`` otherwise."""
    model = case.particles if case.kind == "particles" else None
    if model is None or traj.v is None or traj.energy is None or len(traj.t) < 2 * WINDOWS:
        return None
    t, e = np.asarray(traj.t, float), np.asarray(traj.energy, float)
    mass = np.where(model.fixed, 0.0, model.mass)
    with np.errstate(invalid="ignore", over="ignore"):
        kinetic = 0.5 * np.sum(mass * np.sum(np.nan_to_num(traj.v) ** 2, axis=-1), axis=-1)
    edges = np.searchsorted(t, np.linspace(t[0], t[-1], WINDOWS + 1)[1:-1])
    stretches = [i for i in np.split(np.arange(len(t)), edges) if len(i)]  # an adaptive run's may be empty
    peak = np.array([kinetic[i].max() for i in stretches])
    before = np.maximum.accumulate(peak)
    for w in range(1, len(stretches) - 1):
        if not peak[w] < SETTLED * before[w - 1]:
            continue
        settled_at = stretches[w][np.argmax(kinetic[stretches[w]])]
        lowest = float(np.min(e[: stretches[w][-1] + 1]))
        for v in range(w + 1, len(stretches)):
            moving = peak[v] >= REGROWN * peak[w] and peak[v] >= MOVES * scale
            put_in = float(np.max(e[stretches[v]])) - lowest >= PUT_IN * (peak[v] - peak[w])
            if moving and put_in:
                k = int(stretches[v][np.argmax(kinetic[stretches[v]])])
                return Failure(
                    float(t[stretches[v][0]]),
                    f"self-excited: a scene that only loses energy came near rest (kinetic "
                    f"energy {peak[w]:.3g} J by t={t[settled_at]:.4g} s, under {SETTLED:g} of its "
                    f"earlier {before[w - 1]:.3g} J), then moved again: {kinetic[k]:.3g} J at "
                    f"t={t[k]:.4g} s, with its energy {float(np.max(e[stretches[v]])) - lowest:.3g} J "
                    "above its lowest before",
                )
    return None


def is_stable(traj: Trajectory, *, case: Case | None = None, scale: float | None = None) -> bool:
    """Stable: finished ``ok``, finite, energy that does not grow (:func:`energy_grows`),
    and, given the ``case`` and its energy ``scale``, no :func:`motion_failure`."""
    if traj.status != "ok":
        return False
    if traj.energy is None:
        return True
    if energy_grows(traj.t, traj.energy, scale=scale):
        return False
    return case is None or scale is None or motion_failure(case, traj, scale) is None


@dataclass
class SearchResult:
    """The outcome of one bisection.

    dt_limit : largest step found stable (s); 0 if even ``dt_lo`` was unstable
    dt_unstable : smallest step found unstable (s); inf if even ``dt_hi`` was stable
    runs : simulations made;  note : how to read the limit
    status : ``ok``, or ``solver-failed`` (no limit: the solver failed at some step)
    """

    dt_limit: float
    dt_unstable: float
    runs: int
    note: str
    status: str = "ok"


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
    bracketed: bool = False,
) -> SearchResult:
    """Bisect (geometrically) for the boundary between stable and unstable steps.

    Assumes stability is monotone in dt. Bounded by work alone: it stops when
    ``dt_unstable / dt_limit - 1`` is below ``rel_tol`` or after ``max_runs`` calls of
    ``stable_at``, so the same code gives the same bracket on every machine. ``budget_s``
    is a safety valve, not a bound: a search whose calls have taken longer raises
    :class:`SearchTimeout` instead of reporting the bracket it happened to reach.
    ``bracketed`` says ``dt_lo`` is already known stable and ``dt_hi`` unstable: neither
    is run again (``runs`` counts only the bisection's own runs).
    """
    start = time.perf_counter()

    def stable(dt: float) -> bool:
        if time.perf_counter() - start > budget_s:
            raise SearchTimeout(
                f"still searching after its {budget_s:g} s safety limit "
                f"([stability] budget_s), at {runs} runs: no limit reported"
            )
        return stable_at(dt)

    runs = 0
    if not bracketed:
        runs += 1
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


CONFIRM = 5
"""A limit found is confirmed by a run at it :data:`CONFIRM` times as long as the search's
runs: a mode that grows too slowly to show over the search's horizon (spring-chain's top
mode under RK3 at 0.2 % above the exact limit, unseen over 2000 steps, 1e23-fold over
20 000) shows there. A limit that fails it is searched again over that longer horizon,
and its note says so: from the first of :data:`RESEARCH_FROM` of the failed limit that is
stable over the longer horizon (the failed limit is the bracket's unstable end), or from
the search's own low end where none is."""

RESEARCH_FROM = (0.9, 0.5)
"""Fractions of a limit that failed its confirmation tried, largest first, as the stable
end of the bracket searched again over the longer horizon: the boundary usually lies
just below the failed limit (spring-chain's RK3: 0.2 %), and a run at the search's low
end over that horizon costs as many steps as all the bisection's runs together."""

MONOTONE_PROBES = (0.9, 0.5)
"""After the bisection, steps at these fractions of the limit found are run too: a step
below the limit that is unstable shows a boundary that is not monotone, and the search is
bisected again below it."""


def _confirmed(
    result: SearchResult,
    stable_at: Callable[[float], bool],
    longer: list[int],
    search: Callable[..., SearchResult],
    dt_lo: float,
) -> SearchResult:
    """``result`` confirmed by a run at its limit :data:`CONFIRM` times as long, or, where
    that run is not stable, the search made again over the longer horizon below it
    (bracketed from :data:`RESEARCH_FROM`)."""
    limit = result.dt_limit
    if not limit > dt_lo:
        return result
    longer[0] = CONFIRM
    runs = result.runs + 1
    if stable_at(limit):
        return dataclasses.replace(result, runs=runs)
    unstable = limit
    again = None
    for fraction in RESEARCH_FROM:
        trial = fraction * limit
        if trial <= dt_lo:
            break
        runs += 1
        if stable_at(trial):
            again = search(trial, unstable, 0, bracketed=True)
            break
        unstable = trial
    if again is None:
        again = search(dt_lo, unstable, 0)
    words = (
        f"unstable at {limit:.6g} s over a run {CONFIRM} times as long as the search's: "
        "searched again over that horizon"
    )
    note = "; ".join(n for n in (again.note, words) if n)
    return dataclasses.replace(again, runs=runs + again.runs, note=note)


EXCESS_EFOLDS = 20.0
"""A limit found above a known exact one, by a fraction ``d`` of it, is run again over
``EXCESS_EFOLDS / d`` steps: near an exact limit a mode grows by ``|R| - 1 ~ c d`` a step
(``c`` about 0.75 for RK3 on the imaginary axis, 0.5 for explicit Euler's
``|1 + z| - 1`` on the real axis), so over that run it grows by e^(c x 20): past 10^6 in
energy from a mode that holds 10^-6 of it. Spring-chain's top mode under Drake's RK3 at
0.02 % above its exact limit grows 1.7e-4 a step, unseen over 10 000 steps."""
EXCESS_MAX_STEPS = 400_000
"""The most steps of the run above: a limit within ``EXCESS_EFOLDS / EXCESS_MAX_STEPS``
(5e-5) of the exact one is closer than any search's tolerance, and is said so."""


def _excess_steps(excess: float, horizon_steps: int) -> int:
    """Steps of the run that shows growth ``excess`` (a fraction) above an exact limit:
    :data:`EXCESS_EFOLDS` / ``excess``, at least ``horizon_steps``, at most
    :data:`EXCESS_MAX_STEPS`."""
    return int(min(max(math.ceil(EXCESS_EFOLDS / excess), horizon_steps), EXCESS_MAX_STEPS))


def _not_above_exact(
    result: SearchResult,
    exact: float | None,
    rel_tol: float,
    run_steps: Callable[[float, int], bool],
    horizon_steps: Callable[[float], int],
    research: Callable[[float, int], SearchResult],
) -> SearchResult:
    """``result`` where its limit is not above the ``exact`` one; else the growth its
    horizon was too short to see, looked for over a run as long as the excess needs
    (:func:`_excess_steps`). Where that run grows, the limit becomes ``exact (1 -
    rel_tol)`` if a run there over :func:`_excess_steps` of ``rel_tol`` is stable (the
    bracket then holds the exact limit), or is searched again below that step
    (``research(unstable, runs)``, an engine less stable than its method's theory); a
    limit stable over the longer run stays, and its note says it is above the exact one."""
    limit = result.dt_limit
    if (
        exact is None
        or not (math.isfinite(exact) and exact > 0)
        or not (math.isfinite(limit) and limit > exact)
    ):
        return result
    excess = limit / exact - 1
    steps = _excess_steps(excess, horizon_steps(limit))
    runs = result.runs + 1
    if run_steps(limit, steps):
        note = f"{excess:.2g} above the exact limit {exact:.6g} s, and stable there over {steps} steps"
        return dataclasses.replace(result, runs=runs, note="; ".join(n for n in (result.note, note) if n))
    below = exact * (1 - rel_tol)
    below_steps = _excess_steps(rel_tol, horizon_steps(below))
    runs += 1
    grew = (
        f"unstable at {limit:.6g} s over {steps} steps ({excess:.2g} above the exact limit "
        f"{exact:.6g} s, a growth too slow for the search's runs)"
    )
    if run_steps(below, below_steps):
        note = f"{grew}; stable at {below:.6g} s over {below_steps} steps"
        return SearchResult(below, limit, runs, "; ".join(n for n in (result.note, note) if n))
    again = research(below, runs)
    note = f"{grew}; unstable at {below:.6g} s too, over {below_steps} steps: searched again below it"
    return dataclasses.replace(again, note="; ".join(n for n in (again.note, note) if n))


NUDGE = 4
"""float32 ulps by which a search's start is nudged (positions, or an ODE's state, times
``1 + 4 eps32``, 4.8e-7 of each: a float32 engine's start moves by a few of its ulps, a
float64 one's far below any length of the scene), one run at the limit found and one at
the smallest unstable step, each over the horizon its own verdict was reached over (the
limit's: the confirmation's, :data:`CONFIRM` times the search's; the unstable end's: the
search's, unless it was found over the longer horizon): where the nudged run is unstable
at the limit, or stable at the unstable step, round-off decides the verdict there
(rope-pendulum: the reference's symplectic Euler and Drake's semi-explicit Euler, one
scheme, agree to 2e-15 at 1 s and differ by 0.19 m at 10 s, and their limits 0.0035 and
0.0041 s were each other's noise). The unstable end is not nudged over a longer run than
its verdict: a mode that grows shows more over a longer run, so a longer nudged run would
agree more often and hide the start's say. Cases with an exact limit (linear scenes) are
not nudged."""
ROUNDOFF_DECIDES = "round-off decides:"
"""How the note of a search whose limit round-off decides begins (the report's figure
draws those rows' intervals)."""
DOWN_PROBES = (0.97, 0.9, 0.8, 0.65, 0.5, 0.35, 0.25)
"""Fractions of a limit that round-off decides, tried largest first: the first at which
the run and its nudged copy are both stable is the limit published, the low end of the
interval the boundary lies in."""
UP_PROBES = (1.03, 1.1, 1.2, 1.35, 1.5, 2.0)
"""Multiples of an unstable step that round-off decides, tried smallest first (below the
search's high end): the first at which the run and its nudged copy are both unstable is
the unstable end published."""


def nudged(case: Case, ulps: int) -> Case:
    """``case`` with its initial positions (an ODE's initial state) times ``1 + ulps eps32``
    (float32's ``eps``): the same start to a few float32 ulps."""
    factor = 1.0 + ulps * float(np.finfo(np.float32).eps)
    scene = case.scene
    if isinstance(scene, OdeSpec):
        return dataclasses.replace(case, scene=dataclasses.replace(scene, y0=scene.y0 * factor))
    return dataclasses.replace(case, scene=dataclasses.replace(scene, x0=scene.x0 * factor))


def _roundoff_interval(
    result: SearchResult,
    stable_with: Callable[[float, int, int], bool],
    dt_lo: float,
    dt_hi: float,
    times_of: Callable[[float], int] = lambda dt: 1,
) -> SearchResult:
    """``result`` where the start nudged by :data:`NUDGE` ulps keeps the run stable at its
    limit and unstable at its unstable end (two runs); else the interval round-off decides
    in: from the first of :data:`DOWN_PROBES` of the limit at which the run
    (``stable_with(dt, 0, times)``) and its nudged copy (``stable_with(dt, NUDGE, times)``)
    are both stable, to the first of :data:`UP_PROBES` of the unstable end (below
    ``dt_hi``, else ``dt_hi``) at which both are unstable; the note begins with
    :data:`ROUNDOFF_DECIDES`. ``times``: how many times the search's horizon a run covers,
    at each end and its probes the horizon of that end's own verdict (``times_of(dt)``)."""
    limit, unstable = result.dt_limit, result.dt_unstable
    if not (limit > dt_lo and math.isfinite(unstable)):
        return result
    low, high = times_of(limit), times_of(unstable)
    runs = result.runs + 2
    low_flip, high_flip = not stable_with(limit, NUDGE, low), stable_with(unstable, NUDGE, high)
    if not (low_flip or high_flip):
        return dataclasses.replace(result, runs=runs)

    def both(dt: float, stable: bool) -> bool:
        nonlocal runs
        times = low if stable else high
        for ulps in (0, NUDGE):
            runs += 1
            if stable_with(dt, ulps, times) != stable:
                return False
        return True

    said, ends = [], []
    lo, hi = limit, unstable
    if low_flip:
        said.append(f"unstable at {limit:.6g} s")
        lo = next((t for f in DOWN_PROBES if (t := f * limit) > dt_lo and both(t, True)), dt_lo)
        ends.append(
            "the limit is the largest step tried at which the run and its nudged copy are both stable"
            if lo > dt_lo
            else "no step tried above the search's low end was stable in both: the limit is that low end"
        )
    if high_flip:
        said.append(f"stable at {unstable:.6g} s")
        hi = next((t for f in UP_PROBES if (t := f * unstable) < dt_hi and both(t, False)), dt_hi)
        ends.append(
            "the unstable end is the smallest step tried at which both are unstable"
            if hi < dt_hi
            else "no step tried below the search's high end was unstable in both: the unstable end "
            "is that high end"
        )
    note = (
        f"{ROUNDOFF_DECIDES} its start nudged by {NUDGE} float32 ulps is {' and '.join(said)}, so the "
        f"verdict there depends on the start's last bits (chaotic motion, or a run on the edge of a "
        f"test); the boundary lies between {lo:.6g} and {hi:.6g} s: {'; '.join(ends)}"
    )
    return SearchResult(lo, hi, runs, "; ".join(n for n in (result.note, note) if n))


@dataclass(frozen=True)
class Hint:
    """Where another engine running the same scheme found the boundary: its ``dt_limit``
    and ``dt_unstable`` (s), and its name (``source``), for the search's note."""

    dt_limit: float
    dt_unstable: float
    source: str

    def words(self) -> str:
        """How a search's note says it started here."""
        return f"searched first at {self.source}'s bracket ({self.dt_limit:.6g}, {self.dt_unstable:.6g}) s"

    def usable(self, dt_lo: float, dt_hi: float) -> bool:
        """Whether it is a finite bracket inside ``(dt_lo, dt_hi]``."""
        lo, hi = self.dt_limit, self.dt_unstable
        return math.isfinite(lo) and math.isfinite(hi) and dt_lo < lo < hi <= dt_hi


def _first_bracket(
    hint: Hint | None,
    stable_at: Callable[[float], bool],
    search: Callable[..., SearchResult],
    dt_lo: float,
    dt_hi: float,
    rel_tol: float,
) -> SearchResult:
    """The search's first bisection: over ``(dt_lo, dt_hi)``, or, with a usable ``hint``,
    from the hint's ends run first. Stable at its low end and unstable at its high end:
    the bracket is the hint's (bisected on to the tolerance). Stable at both: steps above
    it, each ratio to the last the square of the one before (from the hint's ratio, at
    least ``1 + rel_tol``), until one is unstable (or ``dt_hi`` is stable); unstable at its
    low end: steps below it, likewise, until one is stable (or ``dt_lo`` is unstable). A
    search of a float32 re-implementation from its float64 original's bracket makes a few
    runs where one over the whole bracket makes 16 to 26 (MuJoCo Warp from MuJoCo)."""
    if hint is None or not hint.usable(dt_lo, dt_hi):
        return search(dt_lo, dt_hi, 0)
    lo, hi = hint.dt_limit, hint.dt_unstable
    said = hint.words()
    ratio = max(hi / lo, 1.0 + rel_tol)
    runs = 1
    if stable_at(lo):
        runs += 1
        while stable_at(hi):
            if hi >= dt_hi:
                found = SearchResult(dt_hi, math.inf, runs, f"stable at every step tried (up to {dt_hi:g} s)")
                return dataclasses.replace(found, note=f"{said}; {found.note}")
            lo, hi, ratio = hi, min(hi * ratio, dt_hi), ratio * ratio
            runs += 1
    else:
        hi = lo
        while True:
            if lo <= dt_lo:
                found = SearchResult(0.0, dt_lo, runs, f"unstable at every step tried (even {dt_lo:g} s)")
                return dataclasses.replace(found, note=f"{said}; {found.note}")
            lo, ratio = max(lo / ratio, dt_lo), ratio * ratio
            runs += 1
            if stable_at(lo):
                break
            hi = lo
    found = search(lo, hi, runs, bracketed=True)
    return dataclasses.replace(found, note="; ".join(n for n in (said, found.note) if n))


class _SolverFailedAt(Exception):
    def __init__(self, dt: float, message: str) -> None:
        super().__init__(message)
        self.dt = dt


def search_case(
    case: Case,
    simulate: Callable[[Case, float], Trajectory],
    *,
    quick: bool = False,
    exact: float | None = None,
    hint: Hint | None = None,
) -> SearchResult:
    """Bisect ``case.stability``'s bracket; ``simulate(case, dt)`` runs one engine and method.

    Each run covers the horizon, and at least :data:`MIN_STEPS` steps, recording every
    step, and is judged by :func:`is_stable` against the case's energy scale. ``quick``
    stops at 1% instead of the case's ``rel_tol`` and runs at least
    :data:`QUICK_MIN_STEPS` steps. The limit found is checked at
    :data:`MONOTONE_PROBES` of itself; an unstable probe starts the bisection again below
    it, and the note says the boundary is not monotone. A limit above the ``exact`` one
    (s, where the method's is known) is run again long enough to show the growth
    (:func:`_not_above_exact`). Without an exact limit, the start is nudged by a few ulps
    at the limit and at the unstable end, and where that flips a verdict the bracket widens
    to where it does not (:func:`_roundoff_interval`). A ``hint`` (another engine's
    bracket for the same scheme) is tried first: where this engine is stable at its low
    end and unstable at its high end, the bisection starts there (:func:`_first_bracket`);
    it only chooses where to look, every verdict is this engine's own run, and the note
    says where the search started also when a later step searched again from elsewhere.
    A run whose solver fails ends the search with status ``solver-failed`` and no limit. A
    run already made (the same step, number of steps and start: a search again below a failed
    probe or confirmation starts from ends already run) is not made again, its verdict is
    reused, and ``runs`` counts the simulations made. A
    search still running after ``budget_s`` seconds raises :class:`SearchTimeout` (a
    safety valve: it never shortens a search).
    """
    from truestep.measures.energy_scale import energy_scale

    spec = case.stability
    if spec is None:
        raise ValueError(f"{case.name}: the case declares no stability search")
    min_steps = min(QUICK_MIN_STEPS, spec.min_steps) if quick else spec.min_steps
    rel_tol = max(spec.rel_tol, 1e-2) if quick else spec.rel_tol
    scale = energy_scale(case)

    made = [0]
    known: dict[tuple[float, int, int], bool] = {}  # (dt, steps, ulps) -> the run's verdict
    longer = [1]  # how many times the search's horizon its runs cover
    judged: dict[float, int] = {}  # dt -> the longest horizon (times the search's) it was run over

    def steps_over(dt: float, times: int) -> int:
        return times * max(min_steps, math.ceil(spec.horizon / dt))

    def horizon_steps(dt: float) -> int:
        return steps_over(dt, longer[0])

    def stable_at(dt: float) -> bool:
        judged[dt] = max(judged.get(dt, 0), longer[0])
        return run_steps(dt, horizon_steps(dt))

    def run_steps(dt: float, n: int, ulps: int = 0) -> bool:
        if (dt, n, ulps) in known:  # the same run again (a search again from its ends)
            return known[dt, n, ulps]
        start = nudged(case, ulps) if ulps else case
        trial = dataclasses.replace(start, duration=n * dt, max_records=n)
        made[0] += 1
        traj = simulate(trial, dt)
        if traj.status == "solver-failed":
            raise _SolverFailedAt(dt, traj.message)
        known[dt, n, ulps] = verdict = is_stable(traj, case=case, scale=scale)
        return verdict

    start = time.perf_counter()

    def search(lo: float, hi: float, runs_before: int, *, bracketed: bool = False) -> SearchResult:
        left = spec.budget_s - (time.perf_counter() - start)
        r = bisect_limit(
            stable_at,
            lo,
            hi,
            rel_tol=rel_tol,
            max_runs=max(spec.max_runs - runs_before, 2),
            budget_s=left,
            bracketed=bracketed,
        )
        return dataclasses.replace(r, runs=r.runs + runs_before)

    try:
        result = _first_bracket(hint, stable_at, search, spec.dt_lo, spec.dt_hi, rel_tol)
        first = result.dt_limit
        for fraction in MONOTONE_PROBES:
            probe = fraction * result.dt_limit
            if result.dt_limit <= 0 or probe <= spec.dt_lo or result.runs >= spec.max_runs:
                break
            result = dataclasses.replace(result, runs=result.runs + 1)
            if not stable_at(probe):
                again = search(spec.dt_lo, probe, result.runs - 1)  # the probe's run counts
                result = dataclasses.replace(
                    again,
                    note="; ".join(
                        n
                        for n in (
                            again.note,
                            f"not monotone: unstable at {probe:.4g} s, below the first "
                            f"boundary found ({first:.4g} s); the limit is the largest step below "
                            "which every step tried was stable",
                        )
                        if n
                    ),
                )
                break
        result = _confirmed(result, stable_at, longer, search, spec.dt_lo)
        result = _not_above_exact(
            result,
            exact,
            rel_tol,
            run_steps,
            horizon_steps,
            lambda unstable, runs: search(spec.dt_lo, unstable, runs),
        )
        if exact is None:  # a linear scene's limit is not decided by round-off
            result = _roundoff_interval(
                result,
                lambda dt, ulps, times: run_steps(dt, steps_over(dt, times), ulps),
                spec.dt_lo,
                spec.dt_hi,
                lambda dt: judged.get(dt, longer[0]),
            )
        said = hint.words() if hint is not None and hint.usable(spec.dt_lo, spec.dt_hi) else ""
        if said and not result.note.startswith(said):  # searched again from elsewhere since
            result = dataclasses.replace(result, note="; ".join(n for n in (said, result.note) if n))
        result = dataclasses.replace(result, runs=made[0])
    except _SolverFailedAt as err:
        return SearchResult(
            float("nan"),
            float("nan"),
            made[0],
            f"the solver failed at dt {err.dt:.4g} s ({str(err)[:160]}): a "
            "solver failure is not a stability limit",
            status="solver-failed",
        )
    return result
