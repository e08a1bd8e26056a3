"""When a finite run counts as unstable by its motion: growth that goes on through the
whole run (a single jump is not growth), a damped scene that gains energy, an orbit that
escapes, a conservative scene whose energy leaves its start for good."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from truestep.adapters import get_adapter
from truestep.execution.runner import Timing, run_one
from truestep.measures.energy_scale import energy_scale
from truestep.measures.metrics import energy_behaviour
from truestep.measures.stability import energy_grows, energy_keeps_growing, is_stable

T = np.linspace(0.0, 10.0, 4001)


@pytest.mark.parametrize("where", [0.1, 0.4, 0.6, 0.9])
def test_a_single_jump_is_not_growth_wherever_it_falls(where):
    """A close encounter taken with too large a step: the energy jumps once (x200) and
    stays. The half-against-half test saw the jump only when it fell in the late half
    (Verlet unstable, Euler ok on close-encounter at 1 ms); the quarter test never does."""
    energy = np.where(T < where * T[-1], -2.375, 525.0)
    assert not energy_keeps_growing(T, energy)
    assert energy_grows(T, energy) == (where > 0.5)  # the old row criterion's blind spot


@pytest.mark.parametrize(
    "energy",
    [np.exp(0.5 * T), 1.0 + 0.2 * T, (1.0 + 0.3 * np.sin(7.3 * T) ** 2) * np.exp(0.3 * T)],
    ids=["exponential", "linear", "growing-oscillation"],
)
def test_growth_through_the_run_is_growth(energy):
    assert energy_keeps_growing(T, energy)


def test_a_bounded_oscillation_does_not_keep_growing():
    assert not energy_keeps_growing(T, 0.5 + 0.4 * np.sin(9.0 * T) ** 2)


def _search_run(case, engine: str, method: str, dt: float):
    """A run as the stability search makes it (the horizon, at least min_steps steps)."""
    spec = case.stability
    n = max(spec.min_steps, math.ceil(spec.horizon / dt))
    trial = dataclasses.replace(case, duration=n * dt, max_records=n)
    return get_adapter(engine).simulate(trial, method, dt)


@pytest.mark.parametrize(("engine", "method"), [("reference", "symplectic-euler"), ("mujoco", "Euler")])
def test_the_damped_cloth_is_unstable_where_its_energy_stays_up(case_named, engine, method):
    """hanging-cloth (damped springs, drag): at 0.9 x the limit published before (4.60 ms,
    4.67 ms) the energy only falls; at 0.95 x it swings to 5-7 times its start: a damped
    scene that gains energy, which the grow-late-against-early test calls stable."""
    case = case_named("hanging-cloth")
    assert energy_behaviour(case) == "dissipative"
    old_limit = {"reference": 4.5995e-3, "mujoco": 4.6662e-3}[engine]
    settled = _search_run(case, engine, method, 0.9 * old_limit)
    pumped = _search_run(case, engine, method, 0.95 * old_limit)
    scale = energy_scale(case)
    assert is_stable(settled, case=case, scale=scale)
    assert settled.energy.max() <= settled.energy[0] * (1 + 1e-9)
    assert is_stable(pumped)  # growth alone, late half against early
    assert pumped.energy.max() > 5 * pumped.energy[0]
    assert not is_stable(pumped, case=case, scale=scale)


def test_conservative_scenes_keep_their_exact_limits(case_named):
    """Symplectic Euler on the undamped oscillator at 0.995 x 2/omega swings its energy up
    to 195 times its start and back, bounded: stable, however wild."""
    case = case_named("harmonic-oscillator")
    assert energy_behaviour(case) == "conservative"
    run = _search_run(case, "reference", "symplectic-euler", 0.995 * 0.2)
    assert run.energy.max() > 100 * run.energy[0]
    assert is_stable(run, case=case, scale=energy_scale(case))


@pytest.mark.parametrize("method", ["euler", "verlet"])
def test_a_close_encounter_that_flings_a_body_free_is_unstable(case_named, method):
    """At 1 ms both blow the bound three-body system apart in one close encounter: the
    energy goes from -2.4 J to positive, the case's escape energy. Neither keeps growing
    (the old rows called both ok); the motion is not a bound orbit's any more."""
    case = case_named("close-encounter")
    row = run_one(case, "reference", method, 1e-3, adaptive=False, timing=Timing(long_run_s=0.0))
    assert row["status"] == "unstable" and "escaped" in row["message"], row["message"]
    assert 0 < row["t_fail"] < case.duration


def test_an_explosion_keeps_growing_however_fast():
    """Energy x10 per record from 50 J (stiff-spring's midpoint at 2.5 ms): every quarter
    grows 1e5-fold, far below the final size; round-off must be judged against the energy
    so far, or the fastest blow-ups read as not growing."""
    t = np.arange(22.0)
    assert energy_keeps_growing(t, 50.0 * 10.0**t)


def test_a_limit_is_confirmed_over_a_longer_run_and_is_never_above_the_exact_one(case_named):
    """spring-chain with Drake's RK3 (issue 35, finding 2): over the search's 2000 steps its
    top mode has not grown at 0.045214 s, the limit published before; Drake's own run of
    20 000 steps there blows the energy up (checked here, raw). The search confirms its
    limit over a run 5 times as long, searches again, and lands at 0.0451393 s, still
    2.2e-4 above the exact limit, where the top mode grows 1.7e-4 a step: given the exact
    limit, it runs that step over 20 / 2.2e-4 steps, sees the growth, and publishes a
    bracket around the exact limit. Checked against the closed form: Kutta's RK3 has
    ``R(z) = 1 + z + z^2/2 + z^3/6``, and on the chain's fastest mode (omega_max =
    40 sin(9 pi / 22), the case file's) ``|R(i omega dt)|`` is at most 1 at the published
    limit and above 1 at its unstable end."""
    from truestep.adapters.base import facts_of
    from truestep.cases.exact import stability_limit
    from truestep.measures.stability import CONFIRM, search_case

    case = case_named("spring-chain")
    drake = get_adapter("drake")
    exact = stability_limit(case, facts_of(drake, "runge_kutta3"))
    long = drake.simulate(dataclasses.replace(case, duration=20_000 * 0.045214), "runge_kutta3", 0.045214)
    assert long.status == "unstable" or not np.isfinite(long.energy[-1]) or long.energy[-1] > 1e6
    found = search_case(case, lambda c, dt: drake.simulate(c, "runge_kutta3", dt), exact=exact)
    assert f"{CONFIRM} times as long" in found.note and "above the exact limit" in found.note
    assert found.dt_limit <= exact < found.dt_unstable
    assert found.dt_unstable / found.dt_limit - 1 <= 2 * case.stability.rel_tol

    def gain(dt: float) -> float:
        z = 1j * 40 * np.sin(9 * np.pi / 22) * dt
        return abs(1 + z + z**2 / 2 + z**3 / 6)

    assert gain(found.dt_limit) <= 1 < gain(found.dt_unstable)


def test_a_limit_above_the_exact_one_is_run_long_enough_to_show_its_growth():
    """The rule of :func:`truestep.measures.stability._not_above_exact` on a system whose
    answer is known by hand: a mode multiplied by ``1 + excess`` each step above the exact
    limit ``E`` (and by 1 below it) holds 1e-6 of the energy. A run of the search's 2000
    steps cannot see a 2e-4 excess; the long run of 20 / 2e-4 = 100 000 steps does, and
    ``E (1 - 1e-3)`` is stable, so the bracket holds ``E``. A limit below ``E`` is kept
    as it is, with no extra run."""
    from truestep.measures.stability import SearchResult, _not_above_exact

    exact = 0.05
    runs = []

    def run_steps(dt: float, n: int) -> bool:
        runs.append((dt, n))
        growth = max(dt / exact - 1, 0.0)
        return 1e-6 * (1 + growth) ** (2 * n) < 1e-3  # the mode's energy stays small

    found = SearchResult(exact * 1.0002, exact * 1.0012, 20, "")
    assert run_steps(found.dt_limit, 2000)
    out = _not_above_exact(found, exact, 1e-3, run_steps, lambda dt: 2000, lambda hi, n: None)
    (at, steps), (below_at, below_steps) = runs[1:]
    assert at == found.dt_limit and abs(steps - 100_000) <= 1  # 20 / 2e-4, to its rounding
    assert below_at == exact * 0.999 and abs(below_steps - 20_000) <= 1
    assert out.dt_limit == exact * 0.999 and out.dt_unstable == found.dt_limit and out.runs == 22
    below = SearchResult(exact * 0.9995, exact * 1.0005, 20, "")
    assert _not_above_exact(below, exact, 1e-3, run_steps, lambda dt: 2000, lambda hi, n: None) is below


def _stretch_peaks(case, traj, windows: int = 30) -> np.ndarray:
    """The largest kinetic energy (J) of each of ``windows`` equal stretches of a run,
    summed here from its velocities."""
    mass = np.where(case.particles.fixed, 0.0, case.particles.mass)
    kinetic = 0.5 * np.sum(mass * np.sum(traj.v**2, axis=-1), axis=-1)
    return np.array([k.max() for k in np.array_split(kinetic, windows)])


def test_a_cloth_that_settles_and_then_flaps_is_unstable(case_named):
    """Newton's VBD on the hanging cloth (issue 35, finding 1), 30 s: at 0.02 s the raw run's
    kinetic energy falls below 1e-3 of its first peak by 3 s, then grows over 100-fold into
    a flapping that lasts, with its total energy still far below its start; the motion test
    calls it self-excited. At 0.014 s the cloth settles for good, and is stable."""
    from truestep.measures.stability import motion_failure

    case = case_named("hanging-cloth")
    newton = get_adapter("newton")
    scale = energy_scale(case)
    verdicts = {}
    for dt in (0.02, 0.014):
        n = round(30.0 / dt)
        traj = newton.simulate(dataclasses.replace(case, duration=n * dt, max_records=n), "vbd", dt)
        peaks = _stretch_peaks(case, traj)
        verdicts[dt] = (peaks, motion_failure(case, traj, scale), traj)
    peaks, failed, traj = verdicts[0.02]
    settled = int(np.argmax(peaks < 1e-3 * peaks[0]))
    assert settled > 0 and peaks[settled:].max() > 100 * peaks[settled] and traj.energy[-1] < traj.energy[0]
    assert failed is not None and failed.reason.startswith("self-excited")
    peaks, failed, _ = verdicts[0.014]
    assert peaks[-1] < 1e-6 * peaks[0] and failed is None


def test_a_ball_that_falls_again_from_its_apex_is_not_self_excited(case_named):
    """The bouncing ball's kinetic energy comes back from its height after every apex: no
    energy is put in, and the motion test says nothing (the reference's rk4 over 20 s)."""
    from truestep.measures.stability import self_excited

    case = case_named("bouncing-ball")
    n = round(20.0 / 1e-3)
    traj = get_adapter("reference").simulate(
        dataclasses.replace(case, duration=n * 1e-3, max_records=n), "rk4", 1e-3
    )
    assert traj.status == "ok" and self_excited(case, traj, energy_scale(case)) is None


def test_an_adaptive_run_with_empty_stretches_is_judged(case_named):
    """scipy's Radau on the hanging cloth at tol 1e-4 records where its steps fall, leaving
    some thirtieths of the run without a record: the self-excitation test reads the
    stretches it has (its row once crashed on an empty one)."""
    case = case_named("hanging-cloth")
    row = run_one(case, "scipy", "Radau", 1e-4, adaptive=True, timing=Timing(min_total_s=0.0, max_repeats=1))
    assert row["status"] == "ok", row.get("message")


def test_a_limit_round_off_decides_is_published_as_the_interval_it_lies_in():
    """:func:`truestep.measures.stability._roundoff_interval` on verdicts known by hand:
    stable below 1.0, unstable above 1.2, and between them a verdict set by the start, as
    chaotic motion gives (the run as it is: stable up to 1.1; nudged: stable above it).
    The search stopped at 1.1 (stable) / 1.11 (unstable); nudging flips both, and the
    interval becomes the largest probe below 1.0 at which the run and its nudged copy are
    stable up to the smallest probe above 1.2 at which both are unstable. Verdicts that no
    nudge changes leave the result as it was, two runs more."""
    from truestep.measures.stability import DOWN_PROBES, UP_PROBES, SearchResult, _roundoff_interval

    def chaotic(dt: float, ulps: int, times: int) -> bool:
        return dt < 1.0 or (dt <= 1.2 and (ulps == 0) == (dt <= 1.1))

    found = SearchResult(1.1, 1.11, 20, "")
    out = _roundoff_interval(found, chaotic, 0.1, 5.0)
    lo = next(f * 1.1 for f in DOWN_PROBES if f * 1.1 < 1.0)
    hi = next(f * 1.11 for f in UP_PROBES if f * 1.11 > 1.2)
    assert (out.dt_limit, out.dt_unstable) == (lo, hi) and out.note.startswith("round-off decides: ")
    assert "the limit is the largest step tried" in out.note and "smallest step tried" in out.note
    edge = _roundoff_interval(
        found, lambda dt, ulps, times: dt < 1.0 or (dt <= 6 and (ulps == 0) == (dt <= 1.1)), 0.1, 5.0
    )
    assert edge.dt_unstable == 5.0 and "the unstable end is that high end" in edge.note
    steady = _roundoff_interval(found, lambda dt, ulps, times: dt <= 1.1, 0.1, 5.0)
    assert (steady.dt_limit, steady.dt_unstable, steady.runs, steady.note) == (1.1, 1.11, 22, "")


def test_each_end_is_nudged_over_the_horizon_its_own_verdict_came_from(case_named):
    """The limit's verdict is the confirmation's (5 times the search's horizon), the
    unstable end's the search's own: each nudged run, and each probe about that end, is
    as long as the verdict it checks. Made-up runs on harmonic-oscillator: unstable above
    0.1 s, where a run grows over its last half whatever its length, and, nudged, also
    stable up to 0.11 s over the search's horizon but not over 5 times it (a start whose
    last bits hold the growth back for a while). Nudged over 5 times the horizon, as the
    unstable end was before, that start's say went unseen; over the unstable end's own
    horizon the search finds that round-off decides there, and the unstable end it
    publishes is a step at which both starts are unstable over that horizon."""
    from truestep.adapters.base import Trajectory
    from truestep.measures.stability import CONFIRM, NUDGE, UP_PROBES, nudged, search_case

    case = case_named("harmonic-oscillator")
    spec = case.stability
    shifted = np.asarray(nudged(case, NUDGE).scene.x0).tobytes()
    made: list[tuple[float, int, bool]] = []

    def times(dt: float, n: int) -> float:
        """How many times the search's horizon ``n`` steps of ``dt`` cover."""
        return n / max(spec.min_steps, np.ceil(spec.horizon / dt))

    def simulate(c, dt):
        n = round(c.duration / dt)
        is_nudged = np.asarray(c.scene.x0).tobytes() == shifted
        made.append((dt, n, is_nudged))
        held_back = is_nudged and dt <= 0.11 and times(dt, n) < 2
        grows = dt > 0.1 and not held_back
        t = np.arange(n + 1) * dt
        energy = 0.5 + (np.expm1(30 * t / t[-1]) if grows else np.zeros(n + 1))
        return Trajectory.of_ode(t, np.zeros((n + 1, 2)), energy, status="ok", steps=n, nfev=n, wall_s=0.0)

    found = search_case(case, simulate)

    plain = {dt: times(dt, n) for dt, n, is_nudged in made if not is_nudged}
    nudges = [(dt, times(dt, n)) for dt, n, is_nudged in made if is_nudged]
    first_unstable = min(dt for dt, n, is_nudged in made[: len(made) - len(nudges) - 1] if dt > 0.1)
    assert nudges[0][1] == CONFIRM  # at the limit: the confirmation's horizon
    assert nudges[1] == (first_unstable, 1)  # at the unstable end: the search's own
    assert found.note.startswith("round-off decides: ") and "stable at" in found.note
    assert found.dt_unstable == next(f * first_unstable for f in UP_PROBES if f * first_unstable > 0.11)
    assert all(t == 1 for dt, t in nudges[1:]) and plain[found.dt_unstable] == 1
    assert found.runs == len(made) == len(set(made))


def test_the_rope_s_limit_is_an_interval_because_its_motion_is_chaotic(case_named):
    """rope-pendulum (issue 35, finding 3): two starts 4.8e-7 apart (4 float32 ulps of
    each position), stepped by the reference's symplectic Euler at 3.5 ms, part by more
    than a centimetre within the search's 60 s: the motion is chaotic, so whether a step
    near the limit is stable is a matter of round-off. The search says so, and publishes
    an interval that holds the published limits of the other engines running the same
    scheme (Drake's semi-explicit Euler 0.00414 s, pymunk 0.00414 s: 0.00353 s alone
    before)."""
    from truestep.measures.stability import nudged, search_case

    case = case_named("rope-pendulum")
    reference = get_adapter("reference")
    dt = 0.0035
    n = round(60.0 / dt)
    runs = [
        reference.simulate(dataclasses.replace(c, duration=n * dt, max_records=600), "symplectic-euler", dt)
        for c in (case, nudged(case, 4))
    ]
    apart = np.max(np.abs(runs[0].x - runs[1].x), axis=(1, 2))
    assert apart[0] < 1e-6 and apart.max() > 1e-2
    found = search_case(case, lambda c, h: reference.simulate(c, "symplectic-euler", h))
    assert "round-off decides" in found.note
    assert found.dt_limit <= 0.00414 <= found.dt_unstable


@pytest.mark.parametrize(
    ("hint_ends", "boundary"),
    [
        ((0.0500, 0.0510), 0.0505),  # the boundary inside the hint
        ((0.0500, 0.0510), 0.0620),  # above it: steps up from its high end
        ((0.0500, 0.0510), 0.0210),  # below it: steps down from its low end
        ((0.0500, 0.0510), 0.5),  # stable at every step up to dt_hi
        ((0.0500, 0.0510), 1e-4),  # unstable at every step down to dt_lo
    ],
    ids=["inside", "above", "below", "stable-everywhere", "unstable-everywhere"],
)
def test_a_search_from_another_engines_bracket_finds_the_boundary_of_its_own_runs(hint_ends, boundary):
    """A hint only chooses where to look: wherever the engine's own boundary lies (a run
    is stable below ``boundary``), the bracket found holds it to the tolerance, as the
    search over the whole bracket does, and every run it counts was made. A hint that
    holds the boundary saves most runs; one that misses it costs a few more."""
    from truestep.measures.stability import Hint, _first_bracket, bisect_limit

    dt_lo, dt_hi, rel_tol = 1e-3, 0.2, 1e-2
    made: list[float] = []

    def stable_at(dt: float) -> bool:
        made.append(dt)
        return dt < boundary

    def search(lo: float, hi: float, runs_before: int, *, bracketed: bool = False):
        r = bisect_limit(stable_at, lo, hi, rel_tol=rel_tol, bracketed=bracketed)
        return dataclasses.replace(r, runs=r.runs + runs_before)

    found = _first_bracket(Hint(*hint_ends, "peer"), stable_at, search, dt_lo, dt_hi, rel_tol)
    assert found.runs == len(made)
    assert found.note.startswith("searched first at peer's bracket (0.05, 0.051) s")
    if boundary > dt_hi:
        assert (found.dt_limit, found.dt_unstable) == (dt_hi, math.inf)
    elif boundary <= dt_lo:
        assert (found.dt_limit, found.dt_unstable) == (0.0, dt_lo)
    else:
        assert found.dt_limit < boundary <= found.dt_unstable
        assert found.dt_unstable / found.dt_limit - 1 <= rel_tol
    made.clear()
    whole = bisect_limit(stable_at, dt_lo, dt_hi, rel_tol=rel_tol)
    if boundary == 0.0505:  # a hint that holds the boundary saves most of the runs
        assert found.runs <= 4 < whole.runs
    else:  # one that misses it costs a few runs more (each step out squares its ratio)
        assert found.runs <= whole.runs + (3 if dt_lo < boundary <= dt_hi else 8)


def test_mujoco_warp_s_search_from_mujoco_s_bracket_is_the_same_made_here_or_handed_over(case_named):
    """MuJoCo Warp's search starts from MuJoCo's bracket (the same integrator in float64):
    handed over when MuJoCo's search is done, else MuJoCo's search made first in the same
    process. Both give the same result, bit for bit, and a bracket of MuJoCo Warp's own
    runs: stable at its limit, unstable at its unstable end over the search's horizon."""
    from truestep.execution.analyses import _peer_of, _search
    from truestep.measures.stability import Hint

    case = case_named("harmonic-oscillator")
    peer = _peer_of(get_adapter("mujoco-warp"), case, "RK4")
    assert peer is not None and peer.engine == "mujoco"
    made_here, _ = _search("mujoco-warp", case, "RK4", True, None, peer)
    theirs, _ = _search("mujoco", case, "RK4", True, peer.exact)
    handed, _ = _search(
        "mujoco-warp", case, "RK4", True, None, Hint(theirs.dt_limit, theirs.dt_unstable, "mujoco")
    )
    assert made_here == handed
    assert "mujoco's bracket" in handed.note and handed.runs < 15
    scale = energy_scale(case)
    assert is_stable(_search_run(case, "mujoco-warp", "RK4", handed.dt_limit), case=case, scale=scale)
    assert not is_stable(_search_run(case, "mujoco-warp", "RK4", handed.dt_unstable), case=case, scale=scale)


def test_a_search_that_started_at_a_hint_says_so_after_searching_again(case_named):
    """A search from another engine's bracket whose limit then fails its longer
    confirmation run is searched again from below that limit: its note still says where it
    started (the hint chose where to look), then why it searched again. The runs here are
    made up: stable below 0.0505 s over the search's horizon, below 0.0500 s over the
    confirmation's five times longer one."""
    from truestep.adapters.base import Trajectory
    from truestep.measures.stability import CONFIRM, Hint, search_case

    case = case_named("harmonic-oscillator")
    spec = case.stability

    def simulate(c, dt):
        n = round(c.duration / dt)
        t = np.arange(n + 1) * dt
        longer = n >= CONFIRM * max(spec.min_steps, math.ceil(spec.horizon / dt))
        grows = dt > (0.0500 if longer else 0.0505)
        energy = 0.5 + (np.expm1(30 * t / t[-1]) if grows else np.zeros(n + 1))
        return Trajectory.of_ode(t, np.zeros((n + 1, 2)), energy, status="ok", steps=n, nfev=n, wall_s=0.0)

    found = search_case(case, simulate, hint=Hint(0.0504, 0.0506, "peer"))
    assert found.dt_limit < 0.0500 <= found.dt_unstable
    assert found.note.startswith("searched first at peer's bracket (0.0504, 0.0506) s; ")
    assert "searched again over that horizon" in found.note


def test_a_search_again_below_a_failed_probe_makes_no_run_twice(case_named):
    """A monotone probe found unstable starts the bisection again from ``dt_lo`` up to the
    probe: both ends were run already, with the same step, length and start, and are not
    run again; ``runs`` counts the simulations made. The runs are made up: unstable above
    0.1 s and in a narrow band about 0.9 of the limit the first bisection finds (a band
    that bisection stepped over), stable elsewhere."""
    from truestep.adapters.base import Trajectory
    from truestep.measures.stability import MONOTONE_PROBES, search_case

    case = case_named("harmonic-oscillator")
    made: list[tuple[float, int, bytes]] = []

    def simulate_with(band):
        def simulate(c, dt):
            n = round(c.duration / dt)
            made.append((dt, n, np.asarray(c.scene.x0).tobytes()))
            t = np.arange(n + 1) * dt
            grows = dt > 0.1 or band[0] < dt < band[1]
            energy = 0.5 + (np.expm1(30 * t / t[-1]) if grows else np.zeros(n + 1))
            return Trajectory.of_ode(
                t, np.zeros((n + 1, 2)), energy, status="ok", steps=n, nfev=n, wall_s=0.0
            )

        return simulate

    first = search_case(case, simulate_with((0.0, 0.0)))
    band = (0.895 * first.dt_limit, 0.905 * first.dt_limit)
    probe = MONOTONE_PROBES[0] * first.dt_limit
    assert not any(band[0] < dt < band[1] for dt, _, _ in made if dt != probe)  # stepped over
    made.clear()
    found = search_case(case, simulate_with(band))
    assert "not monotone" in found.note and found.dt_limit < band[0]
    assert len(set(made)) == len(made) and found.runs == len(made)
