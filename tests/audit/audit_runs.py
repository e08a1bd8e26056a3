"""A property audit: every quantity of ``results.csv``, ``stability.csv`` and
``restitution.csv``, recomputed for every engine from the raw trajectory by a route of its
own, and compared with what the harness would publish.

The published side is computed by the harness's own code on a real, short run, as a full
run makes it: ``runner.simulate_timed`` (the measured run, watched at every step with
``simulate(..., monitor=True)``, then a timed run) and ``runner.row_from`` (a row of
``results.csv``: status, errors, energy drift, nfev, steps, wall time and the case's
properties), ``analyses.stability_table`` (searches run in this process instead of a
child) and ``analyses._bounce_rows`` (the restitution table's rows). The other side uses
none of the code under test (``tests/audit_recompute.py``):

- errors (``error``, ``error_final``, ``error_v``): closed forms written here (free flight,
  drag, the damped oscillator by complex roots, Kepler by bisection on Kepler's equation,
  normal modes of spring chains, the bounce schedule, Coulomb sliding) at every record;
  for the cases without one, ``solve_ivp`` (DOP853, rtol = atol = 1e-12) on a right-hand
  side written here, read at every record through its own continuous extension;
- the energy scale ``S = max(KE_max, PE_max - PE_min)``: from the same closed forms or
  reference runs, on the case's grid of 2001 times;
- energy drift: the energy summed here from the state of every step the engine took
  (a run of the engine recorded at every step, made here), against its start, or at the
  records against the closed form's energy;
- statuses: the motion's verdicts (escape, gain, left for good, growth) written here
  from the README and applied to the energies of every step; a solver failure only
  where backward Euler's step has no solution (a gravitating pair below the least
  separation its step equation can reach, in closed form);
- nfev and steps: the derivative (the particle system's acceleration, an ODE's right-hand
  side, MuJoCo's passive-force callback), the engines' step calls (``space.step``,
  ``stepSimulation``) and the adaptive solvers' accepted steps (the reference's
  Dormand-Prince ``step``, scipy's ``OdeSolver.step``) wrapped and counted during the
  measured run, MuJoCo's own clock;
- properties: contacts and flights detected here from the samples (free-fall kicks), the
  heights each flight reached and each contact's lowest sample, momenta, spring lengths,
  volumes, lives of emitted particles counted here, the population's spread by Monte
  Carlo;
- stability limits: the spectral radius of each engine's documented step on one
  oscillator, the fastest normal mode of a chain, and this file's verdicts on that
  step's own energies at the steps a search publishes;
- restitution: rebound over impact speed across each contact found here, apexes the
  highest samples of the flights found here.

Tolerances sit beside each comparison with their reason (STYLE point 9). A failing test
names the engine whose published number disagrees with the physics. The audit found three
harness bugs (an energy scale that moved with the potential's zero for a scene without a
reference, an escape dated from the records rather than its step, a search ended by a
solver failure that published no runs); they are fixed, and their tests stand.

This module holds what the audit's test modules share: the runs (one real trajectory per
case, engine, method and step, counted and cached), the closed forms and the motion's
verdicts. The tests: ``test_audit_results.py`` (``results.csv``),
``test_audit_stability.py`` (``stability.csv`` and the order fits) and
``test_audit_restitution.py`` (``restitution.csv``); the counting wrappers are
``conftest.py``'s.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import audit_recompute as ar
import numpy as np
import pytest

from truestep.adapters import EngineNotInstalled, get_adapter
from truestep.adapters.base import Trajectory
from truestep.cases.loader import CASE_DIR, load_case

ENGINES = ("reference", "scipy", "pymunk", "pybullet", "mujoco", "drake", "mujoco-warp", "newton")
G_FLOOR = 9.81  # m/s^2: gravity of every floor scene here (bouncing-ball, restitution drops)

ROUNDOFF_REL = 1e-9
"""Relative agreement of two computations of the same number from the same samples (or
of two closed forms of one solution, e.g. Kepler by bisection against Newton's method):
both are exact to ~1e-15; 1e-9 leaves room for sums in another order over thousands of
records and is still far below any physical effect measured here."""
ROUNDOFF_ABS = 1e-12
"""Absolute floor (in units of the case's error scale, or of the quantity) under
ROUNDOFF_REL, for numbers that are round-off themselves (the lecture's free-flight error,
a conserved momentum): double precision at metre scale is 1e-16 per operation."""
SCALE_GRID = 2001
"""The energy scale is read along the exact (or reference) motion at this many evenly
spread times of the run, then each of its extremes where it lies (README, "Energy drift";
``truestep/measures/energy_scale.py``): here by bounded Brent search between the grid
neighbours of the largest local extremes (:func:`_peak`), a route of its own."""
PEAKS = 8
"""How many of the largest local extremes on the grid this file refines."""


FLOAT32_REL = 1e-5
"""The same agreement for an engine whose samples are float32 (MuJoCo Warp): two readings
of one float32 trajectory that are exact for the motion a float64 step makes (a parabolic
flight's vertex from its samples) differ by its rounding, 1e-7 relative measured."""


def _roundoff(engine: str) -> float:
    """The relative agreement two readings of ``engine``'s samples reach."""
    return FLOAT32_REL if getattr(get_adapter(engine), "precision", "float64") == "float32" else ROUNDOFF_REL


def _close(published: float, mine: float, rel: float = ROUNDOFF_REL, floor: float = ROUNDOFF_ABS) -> bool:
    if np.isnan(published) or np.isnan(mine):
        return bool(np.isnan(published) and np.isnan(mine))
    if np.isinf(published) or np.isinf(mine):
        return published == mine
    return abs(published - mine) <= rel * max(abs(published), abs(mine)) + floor


# -- runs: one real trajectory per (case, engine, method, step), counted and cached -----------

COUNT = {"calls": 0, "steps": 0}


def _counting(fn, what="calls"):
    def wrapper(*args, **kwargs):
        COUNT[what] += 1
        return fn(*args, **kwargs)

    return wrapper


def _counted_twin(method):
    """``compiled_derivative`` whose twin is counted as the derivative is: Drake and
    scipy call it in place of the Python one."""

    def twin(self):
        fast = method(self)
        return None if fast is None else _counting(fast)

    return twin


@dataclass
class Call:
    """One ``simulate`` call seen while the harness made a row: whether it was the
    measured (monitored) run, the evaluations and adaptive steps counted during it, the
    seconds around it, and what it returned."""

    monitor: bool
    counted: int
    steps: int
    wall: float
    traj: Trajectory


class Watched:
    """The real adapter, its ``simulate`` calls counted and kept."""

    def __init__(self, adapter):
        self.adapter, self.calls = adapter, []

    def simulate(self, case, method, dt, *, monitor=False):
        COUNT["calls"] = COUNT["steps"] = 0
        start = time.perf_counter()
        if monitor:
            traj = self.adapter.simulate(case, method, dt, monitor=True)
        else:
            traj = self.adapter.simulate(case, method, dt)
        wall = time.perf_counter() - start
        self.calls.append(Call(monitor, COUNT["calls"], COUNT["steps"], wall, traj))
        return traj

    def __getattr__(self, attribute):
        return getattr(self.adapter, attribute)


@dataclass
class Run:
    """The measured run (``traj``, the trajectory the row is made from), what the
    wrappers counted while it ran, the timed run (its seconds measured here around the
    whole ``simulate`` call, and its counts), and the row of ``results.csv`` the harness
    makes of it."""

    case: object
    engine: str
    method: str
    dt: float
    adaptive: bool
    traj: Trajectory
    counted: int
    counted_steps: int
    timed: Call
    wall: float
    row: dict
    engine_status: str = "ok"
    timed_run: bool = True
    """Whether a timed run followed the measured one (:func:`run`); ``timed`` is then that
    run, else the measured run."""
    cache: dict = field(default_factory=dict)


_RUNS: dict[tuple, Run] = {}
_CASES: dict[tuple, object] = {}


def adapter_of(engine: str):
    try:
        return get_adapter(engine)
    except EngineNotInstalled as err:
        pytest.skip(str(err))


def case_of(
    name: str, duration: float | None = None, particles: int | None = None, records: int | None = None
):
    """A case of the library, shortened to ``duration`` s and, for a block of particles,
    cut to its first ``particles`` (the runs must stay short); ``records``: its
    ``max_records``."""
    key = (name, duration, particles, records)
    if key not in _CASES:
        case = load_case(CASE_DIR / f"{name}.toml")
        if duration is not None:
            case = dataclasses.replace(case, duration=duration)
        if records is not None:
            case = dataclasses.replace(case, max_records=records)
        if particles is not None:
            m = case.model
            keep = slice(0, particles)
            case = dataclasses.replace(
                case,
                scene=dataclasses.replace(
                    m,
                    mass=m.mass[keep],
                    x0=m.x0[keep],
                    v0=m.v0[keep],
                    radius=m.radius[keep],
                    fixed=m.fixed[keep],
                ),
            )
        _CASES[key] = case
    return _CASES[key]


ONE_TIMED_RUN = None
"""``runner.Timing`` that times one run (the measured run is made first, untimed)."""
_TIMED: set[tuple[str, str]] = set()
"""The engines and methods whose first run here was timed (:func:`run`)."""


def run(case, engine: str, method: str, dt: float) -> Run:
    """The row a full run publishes for one step: ``simulate_timed`` (the measured run
    watched at every step, then one timed run, checked to end alike) and ``row_from``.
    The first run of each engine and method here is timed so; the others are measured
    only (``timing.UNTIMED``: what the timed run adds is checked once for each, and a
    second stepping of every run would double the audit's time)."""
    from truestep.execution import runner, timing

    global ONE_TIMED_RUN
    if ONE_TIMED_RUN is None:
        ONE_TIMED_RUN = runner.Timing(min_total_s=0.0, min_repeats=1, max_repeats=1, long_run_s=0.0)
    key = (id(case), engine, method, dt)
    if key not in _RUNS:
        watched = Watched(adapter_of(engine))
        adaptive = method in watched.adaptive_methods
        timed_here = (engine, method) not in _TIMED
        _TIMED.add((engine, method))
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(timing, "get_adapter", lambda name: watched)
            # a light watch's long row of long steps is timed from its watched run: whether
            # a row is one is read from the clock, so this audit never takes that path (it
            # checks one measured and one timed run; tests/execution/test_timed_from_watched.py
            # checks the other)
            patch.setattr(timing, "watched_step_s", lambda adapter, method: math.inf)
            traj = runner.simulate_timed(
                engine, case, method, dt, ONE_TIMED_RUN if timed_here else timing.UNTIMED, warm_up=False
            )
        measured = [c for c in watched.calls if c.monitor]
        timed = [c for c in watched.calls if not c.monitor]
        assert len(measured) == 1 and measured[0].traj is traj, "one measured run, watched at every step"
        assert len(timed) == (1 if timed_here else 0)
        engine_status = traj.status  # before row_from judges the motion
        row = runner.row_from(case, engine, method, dt, adaptive=adaptive, outcome=traj)
        call = timed[0] if timed else measured[0]
        _RUNS[key] = Run(
            case,
            engine,
            method,
            dt,
            adaptive,
            traj,
            measured[0].counted,
            measured[0].steps,
            call,
            call.wall,
            row,
            engine_status,
            timed_here,
        )
    return _RUNS[key]


NOT_AUDITED = {
    ("drake", "bogacki_shampine3"),
    ("drake", "radau3-ec"),
    ("mujoco-warp", "implicit"),
    ("mujoco-warp", "implicitfast"),
}
"""Drake's error-controlled methods that creep on the orbits (up to the adapter's bound of
300 000 evaluations, ten seconds a run): audited through ``runge_kutta5``, the same code
path (the monitor's records, the counts, the bound) at a fraction of the time. MuJoCo
Warp's implicit integrators: the adapter's path (graph, read-back, counts) is the one its
``Euler`` and ``RK4`` take, and their physics is held to MuJoCo C's, audited, by
``tests/adapters/test_mujoco_warp_adapter.py``."""


DRAKE_DENSE = ("implicit_euler", "radau1", "radau3")
"""Drake's implicit methods factor a dense Newton matrix (6 n)^2 each step: on the cloths
(64 and 100 particles) a run of the audit takes 5-12 s. They are audited on the scenes of
up to 20 particles, through the same adapter code."""


def methods_for(case, engines=ENGINES, *, adaptive: bool = True, only=None):
    """(engine, method) pairs that can run ``case`` and are not skipped by its file
    (nor in :data:`NOT_AUDITED`)."""
    out = []
    for engine in engines:
        try:
            adapter = get_adapter(engine)
        except EngineNotInstalled:
            continue
        for method in adapter.methods:
            if adapter.missing(case, method):
                continue
            if method in adapter.adaptive_methods and not adaptive:
                continue
            if only is not None and method not in only and (engine, method) not in only:
                continue
            if any(e == engine and m in (method, "*") for e, m, _ in case.skip):
                continue
            if (engine, method) in NOT_AUDITED or (
                engine == "drake" and method in DRAKE_DENSE and case.model is not None and case.model.n > 20
            ):
                continue
            out.append((engine, method))
    return out


def step_of(case, engine: str, method: str, dt: float) -> float:
    """``dt`` for a fixed-step method; the case's first quick tolerance for an adaptive one."""
    return case.quick_tolerances[0] if method in get_adapter(engine).adaptive_methods else dt


# -- error and energy: the closed forms -------------------------------------------------------


def _on_axis(case, t):
    """One particle on one anchored spring-damper, along the spring's line."""
    m, a = case.model, case.model.anchors
    d0 = m.x0[0] - a.point[0]
    length = float(np.linalg.norm(d0))
    axis = d0 / length
    u, du = ar.oscillator(
        float(m.mass[0]),
        float(a.stiffness[0]),
        float(a.damping[0]),
        length - float(a.rest[0]),
        float(m.v0[0] @ axis),
        t,
    )
    return (a.point[0] + (a.rest[0] + u)[:, None] * axis)[:, None, :], (du[:, None] * axis)[:, None, :]


def _spring_pair(case, t):
    """Two free masses on one spring: uniform centre of mass, reduced-mass oscillator."""
    m, s = case.model, case.model.springs
    m1, m2 = m.mass
    total, reduced = m1 + m2, m1 * m2 / (m1 + m2)
    sep = m.x0[1] - m.x0[0]
    length = float(np.linalg.norm(sep))
    axis = sep / length
    u, du = ar.oscillator(
        reduced,
        float(s.stiffness[0]),
        float(s.damping[0]),
        length - float(s.rest[0]),
        float((m.v0[1] - m.v0[0]) @ axis),
        t,
    )
    cm_v = (m1 * m.v0[0] + m2 * m.v0[1]) / total
    cm = (m1 * m.x0[0] + m2 * m.x0[1]) / total + np.outer(t, cm_v)
    rel = (s.rest[0] + u)[:, None] * axis
    x = np.stack([cm - m2 / total * rel, cm + m1 / total * rel], axis=1)
    w = du[:, None] * axis
    return x, np.stack([cm_v - m2 / total * w, cm_v + m1 / total * w], axis=1)


def _two_body(case, t):
    """Earth and satellite: the relative coordinate on its Kepler orbit, the centre of mass
    uniform."""
    m = case.model
    total = float(m.mass.sum())
    r, w = ar.kepler_orbit(m.gravitation.G * total, (m.x0[1] - m.x0[0])[:2], (m.v0[1] - m.v0[0])[:2], t)
    r, w = np.pad(r, ((0, 0), (0, 1))), np.pad(w, ((0, 0), (0, 1)))
    cm_v = (m.mass[0] * m.v0[0] + m.mass[1] * m.v0[1]) / total
    cm = (m.mass[0] * m.x0[0] + m.mass[1] * m.x0[1]) / total + np.outer(t, cm_v)
    f0, f1 = m.mass[1] / total, m.mass[0] / total
    return (np.stack([cm - f0 * r, cm + f1 * r], axis=1), np.stack([cm_v - f0 * w, cm_v + f1 * w], axis=1))


def _floor_ball(model, t):
    """Balls dropped from rest onto plane 0 (normal +y): each its own bounce chain."""
    e = model.planes[0].restitution
    x = np.repeat(model.x0[None], len(t), axis=0)
    v = np.zeros_like(x)
    for i in range(len(model.mass)):
        u, w = ar.bounce_height(float(model.x0[i, 1] - model.radius[i]), G_FLOOR, e, t)
        x[:, i, 1], v[:, i, 1] = u + model.radius[i], w
    return x, v


def _sliding(case, t):
    """A puck pushed along the floor: ``s = v0 t - mu g t^2 / 2`` until it stops."""
    m = case.model
    mu, v0 = m.planes[0].friction, float(m.v0[0, 0])
    stop = v0 / (mu * G_FLOOR)
    tc = np.minimum(t, stop)
    x = np.repeat(m.x0[None], len(t), axis=0)
    v = np.zeros_like(x)
    x[:, 0, 0] += v0 * tc - 0.5 * mu * G_FLOOR * tc**2
    v[:, 0, 0] = v0 - mu * G_FLOOR * tc
    return x, v


def _kepler(case, t):
    y0, mu = case.ode.y0, case.ode.params.get("mu", 1.0)
    r, w = ar.kepler_orbit(mu, y0[:2], y0[2:], t)
    return np.concatenate([r, w], axis=1)[:, None, :], None


def _circle(case, t):
    y0 = case.ode.y0
    c, s = np.cos(t), np.sin(t)
    return np.stack([c * y0[0] - s * y0[1], s * y0[0] + c * y0[1]], axis=1)[:, None, :], None


_REFERENCES: dict[tuple, object] = {}


def _my_reference(case, tol: float = 1e-12):
    """This file's reference run of a case without a closed form (DOP853 on this file's
    right-hand side), ``t -> (x, v)``, made once per case and tolerance."""
    key = (id(case), tol)
    if key not in _REFERENCES:
        _REFERENCES[key] = ar.particle_reference(case.model, case.duration, tol)
    return _REFERENCES[key]


EXACT = {
    "free-fall": lambda c, t: ar.free_flight(c.model.x0, c.model.v0, c.model.gravity, t),
    "projectile-drag": lambda c, t: ar.drag_flight(
        c.model.x0, c.model.v0, c.model.gravity, c.model.drag, c.model.mass, t
    ),
    "harmonic-oscillator": _on_axis,
    "damped-oscillator": _on_axis,
    "stiff-spring": _on_axis,
    "spring-chain": lambda c, t: ar.linear_springs(c.model, t),
    "mass-ratio-chain": lambda c, t: ar.linear_springs(c.model, t),
    "spring-damper-pair": _spring_pair,
    "earth-orbit": _two_body,
    "bouncing-ball": lambda c, t: _floor_ball(c.model, t),
    "particle-rain": lambda c, t: _floor_ball(c.model, t),
    "sliding-contact": _sliding,
    "kepler-orbit": _kepler,
    "circle-field": _circle,
    "close-encounter": lambda c, t: _my_reference(c)(t),
    "rope-pendulum": lambda c, t: _my_reference(c)(t),
    "hanging-cloth": lambda c, t: _my_reference(c)(t),
    "stiff-cloth": lambda c, t: _my_reference(c)(t),
}
"""Case -> ``f(case, t) -> (x, v)`` (T, n, 3) each; an ODE's whole state as (T, 1, dim).
The cases without a closed form (``[reference] exact = "reference-run"``: the
three-body encounter, the rope, the cloths) get this file's DOP853 run."""

ODE_HALVES = {"kepler-orbit": True, "arenstorf-orbit": True, "circle-field": False}
"""Whether an ODE case's state is positions then velocities (Kepler's ``(q, w)``,
Arenstorf's ``(x, y, x', y')``), or all position (the circle field's first-order
``(x, y)``, which has no velocity)."""

ENERGY_CURVE = {"damped-oscillator", "projectile-drag", "spring-damper-pair", "sliding-contact"}
"""Dissipative cases whose energy drift is measured against the closed form's energy."""

ERROR_RUNS = [
    # (case, shortened duration (s) or None, particles kept or None, step (s))
    ("free-fall", None, None, 0.05),
    ("harmonic-oscillator", 0.5, None, 2e-3),
    ("damped-oscillator", 0.5, None, 2e-3),
    ("projectile-drag", None, None, 0.1),
    ("spring-damper-pair", None, None, 0.02),
    ("earth-orbit", None, None, 60.0),
    ("spring-chain", 0.5, None, 2e-3),
    ("mass-ratio-chain", None, None, 1e-2),
    ("stiff-spring", 0.01, None, 1e-4),
    ("bouncing-ball", None, None, 0.004),
    ("particle-rain", None, 100, 1 / 240),
    ("sliding-contact", None, None, 0.01),
    ("kepler-orbit", 6.285, None, 0.005),
    ("circle-field", None, None, 0.0125),
    ("close-encounter", None, None, 1e-3),
    ("close-encounter", None, None, 5e-4),
    ("rope-pendulum", 0.5, None, 2e-3),
    ("hanging-cloth", 0.5, None, 4e-3),
    ("stiff-cloth", 0.05, None, 2.5e-4),
    ("arenstorf-orbit", None, None, None),
]
"""The runs of the results.csv audit, each step dividing its (shortened) duration: the
row's step is the step taken. ``close-encounter`` at 0.5 ms too (fixed steps): symplectic
Euler's energy spikes from -2.37 J to +8.1 J through the encounter and comes back (no
escape), and 6000 steps are recorded at 2000 records. ``kepler-orbit`` runs one period
and a little (1257 steps of 5 ms); ``rope-pendulum`` and the cloths (no closed form) are measured against this
file's DOP853 run; the damped cloth at 4 ms is where heun and midpoint gain energy;
``arenstorf-orbit`` with its adaptive methods only (its exact solution is known at whole
periods; 17 000 fixed steps per method would not fit the time budget)."""


def _error_params():
    out, seen = [], set()
    for name, duration, particles, dt in ERROR_RUNS:
        case = case_of(name, duration, particles)
        again = (name, duration, particles) in seen  # another step of a case: fixed steps only
        seen.add((name, duration, particles))
        if dt is not None:
            steps = case.duration / dt
            assert abs(steps - round(steps)) <= 1e-9 * steps, f"{name}: {dt} s does not divide the run"
        for engine, method in methods_for(case, adaptive=not again):
            if dt is None and method not in get_adapter(engine).adaptive_methods:
                continue
            if engine == "drake" and name == "close-encounter" and method != "semi_explicit_euler":
                continue  # its derivative is the reference's: one method through the encounter
            out.append(
                pytest.param(
                    name,
                    duration,
                    particles,
                    engine,
                    method,
                    dt,
                    id=f"{name}-{engine}-{method}" + (f"-{dt:g}" if again else ""),
                )
            )
    return out


ERROR_PARAMS = _error_params()


def _run_from(name, duration, particles, engine, method, dt) -> Run:
    case = case_of(name, duration, particles)
    return run(case, engine, method, step_of(case, engine, method, dt))


def _split(case, x_run, x_exact, part: str):
    """Positions (``part = "x"``) or velocities (``"v"``) of an ODE's states (T, 1, dim):
    a second-order state's halves, a first-order state's whole as its position (no
    velocity: None)."""
    half = x_run.shape[-1] // 2
    if ODE_HALVES[case.name]:
        cut = slice(0, half) if part == "x" else slice(half, None)
        return x_run[..., cut], x_exact[..., cut]
    return (x_run, x_exact) if part == "x" else None


def _per_record(case, traj, part: str):
    """Per record, the largest distance from the exact motion (m or m/s; an ODE's largest
    component) of the run's positions or velocities, and the record times; None where
    the exact motion has no such part."""
    t = traj.t
    if case.name == "arenstorf-orbit":  # periodic: known at its start and after one period
        period = float(case.exact_params["period"])
        keep = np.abs(t - np.round(t / period) * period) <= 1e-9 * max(1.0, period)
        exact = np.repeat(case.ode.y0[None, None, :], int(keep.sum()), axis=0)
        pair = _split(case, traj.x[keep], exact, part)
        return None if pair is None else (np.max(np.abs(pair[0] - pair[1]), axis=(1, 2)), t[keep])
    x, v = EXACT[case.name](case, t)
    if case.kind == "ode":
        pair = _split(case, traj.x, x, part)
        return None if pair is None else (np.max(np.abs(pair[0] - pair[1]), axis=(1, 2)), t)
    mine, theirs = (traj.x, x) if part == "x" else (traj.v, v)
    return np.max(np.linalg.norm(mine - theirs, axis=2), axis=1), t


def _my_errors(r: Run) -> tuple[float, float, float]:
    """``error`` (worst over the records, or at the end for ``error = "final"``),
    ``error_final`` (at the last record, which must be the end) and ``error_v``."""
    case = r.case
    if "errors" not in r.cache:
        px, t = _per_record(case, r.traj, "x")
        at_end = abs(t[-1] - case.duration) <= 1e-9 * max(1.0, case.duration)
        final = float(px[-1]) if at_end else math.nan
        pv = _per_record(case, r.traj, "v")
        worst = final if case.error_norm == "final" else float(px.max())
        r.cache["errors"] = (worst, final, math.nan if pv is None else float(pv[0].max()))
    return r.cache["errors"]


def _documented_reference(case):
    """This file's own run of the reference a case names (``[reference] method``), read
    as the README says the harness reads its own, ``t -> (x, v)``: RK4 at the case's
    ``dt`` (written here, on this file's right-hand side), known at its steps and between
    them by cubic Hermite interpolation of the positions (the velocities as slopes) and
    linear interpolation of the velocities; Dormand-Prince at ``rtol`` stood in for by
    this file's DOP853 100 times looser (1e-10), which errs ~50 times more than either
    run at 1e-12. Its distance from this file's DOP853 at 1e-12 bounds how far the
    harness's reference lies from the motion, twice over."""
    method = case.exact_params.get("method", "dopri5")
    if method == "dopri5":
        return _my_reference(case, 100 * float(case.exact_params.get("rtol", 1e-12)))
    assert method == "rk4", f"{case.name}: no route here to a {method} reference run"
    key = ("rk4", id(case))
    if key not in _REFERENCES:
        h = float(case.exact_params["dt"])
        steps = round(case.duration / h)
        m, n = case.model, case.model.n
        y0 = np.concatenate([m.x0.ravel(), m.v0.ravel()])
        states = ar.rk4_states(ar.particle_rhs(m), y0, h, steps)

        def at(t):
            t = np.asarray(t, float)
            j = np.clip(np.floor(t / h + 1e-9).astype(int), 0, len(states) - 2)
            s = np.clip(t / h - j, 0.0, 1.0)[:, None]
            a, b = states[j], states[j + 1]
            xa, va, xb, vb = a[:, : 3 * n], a[:, 3 * n :], b[:, : 3 * n], b[:, 3 * n :]
            x = (
                (2 * s**3 - 3 * s**2 + 1) * xa
                + (s**3 - 2 * s**2 + s) * h * va
                + (-2 * s**3 + 3 * s**2) * xb
                + (s**3 - s**2) * h * vb
            )
            return x.reshape(-1, n, 3), ((1 - s) * va + s * vb).reshape(-1, n, 3)

        _REFERENCES[key] = at
    return _REFERENCES[key]


def _error_tolerance(r: Run) -> tuple[float, float]:
    """Absolute slack on top of ROUNDOFF_REL for positions (m; state units for an ODE)
    and for velocities (m/s): round-off of two closed forms of one motion; for a case
    without one, twice the distance of this file's run of its documented reference from
    this file's DOP853 at 1e-12, at the records (``_documented_reference``)."""
    case = r.case
    if case.exact == "reference-run":
        t = r.traj.t
        x12, v12 = _my_reference(case)(t)
        xr, vr = _documented_reference(case)(t)
        return (
            2.0 * float(np.max(np.linalg.norm(xr - x12, axis=2))) + 1e-12,
            2.0 * float(np.max(np.linalg.norm(vr - v12, axis=2))) + 1e-12,
        )
    floor = ROUNDOFF_ABS * max(1.0, float(case.error_scale))
    return floor, floor


# -- the motion's energy: scale, every step, verdicts -------------------------------------------


def _ode_energy(case, states: np.ndarray) -> np.ndarray | None:
    """An ODE case's energy at states (T, dim): Kepler's ``|w|^2 / 2 - mu / |q|``, the
    circle field's ``|y|^2 / 2``; Arenstorf's system declares none."""
    if case.name == "kepler-orbit":
        mu = case.ode.params.get("mu", 1.0)
        return 0.5 * np.sum(states[:, 2:] ** 2, axis=1) - mu / np.linalg.norm(states[:, :2], axis=1)
    if case.name == "circle-field":
        return 0.5 * np.sum(states**2, axis=1)
    return None


def _energy_of(case, traj) -> np.ndarray | None:
    """The energy (J) of every record of a run, summed here."""
    if case.kind == "ode":
        return _ode_energy(case, traj.x[:, 0])
    with np.errstate(all="ignore"):
        return ar.energy(case.model, traj.x, traj.v, traj.alive)


_SCALES: dict[int, float] = {}


def _peak(f, t: np.ndarray) -> float:
    """The largest value of ``f`` (times (k,) -> values (k,)) over the run: read at the grid
    ``t``, then refined by scipy's bounded Brent search between the neighbours of each of
    the :data:`PEAKS` largest local maxima of the grid."""
    from scipy.optimize import minimize_scalar

    g = np.asarray(f(t), float)
    g = np.where(np.isfinite(g), g, -np.inf)
    inner = (g[1:-1] >= g[:-2]) & (g[1:-1] >= g[2:])
    local = np.concatenate(([0], np.flatnonzero(inner) + 1, [len(g) - 1]))
    best = float(np.max(g))
    for i in local[np.argsort(-g[local], kind="stable")][:PEAKS]:
        lo, hi = t[max(i - 1, 0)], t[min(i + 1, len(t) - 1)]
        found = minimize_scalar(
            lambda s: -float(np.asarray(f(np.array([s])), float)[0]),
            bounds=(lo, hi),
            method="bounded",
            options={"xatol": 1e-13 * (t[-1] - t[0])},
        )
        if np.isfinite(found.fun):
            best = max(best, -float(found.fun))
    return best


def _exchanged(kinetic, potential, t: np.ndarray) -> float:
    """``max(KE_max, PE_max - PE_min)`` with each extreme read where it lies (:func:`_peak`);
    ``kinetic`` and ``potential``: times -> energies (J)."""
    return max(_peak(kinetic, t), _peak(potential, t) + _peak(lambda s: -np.asarray(potential(s)), t))


def _exchanged_along(case, motion, t: np.ndarray) -> float:
    """The scale along a particle motion ``t -> (x, v)``."""

    def kinetic(s):
        return ar.kinetic_energy(case.model, motion(s)[1])

    def potential(s):
        x, v = motion(s)
        return ar.energy(case.model, x, v) - ar.kinetic_energy(case.model, v)

    return _exchanged(kinetic, potential, t)


def my_scale(case) -> float:
    """``S = max(KE_max, PE_max - PE_min)`` along this file's exact (or reference) motion
    at :data:`SCALE_GRID` times, ``PE = E - KE``; a first-order ODE (no kinetic part):
    ``max |E|``; NaN without an energy or where nothing reads it (a scene with an energy
    source: no verdict, no drift). A scene with no closed form or reference whose forces
    have no potential (no gravity, springs or gravitation: a body thrown at walls) keeps
    its start's kinetic energy as its largest (walls and planes only keep or take it)."""
    if id(case) not in _SCALES:
        t = np.linspace(0.0, case.duration, SCALE_GRID)
        m = case.model
        if case.kind == "ode":
            if case.name != "kepler-orbit" and case.name != "circle-field":
                scale = math.nan
            else:

                def states(s):
                    return EXACT[case.name](case, np.asarray(s, float))[0][:, 0]

                def ode_kinetic(s):
                    return 0.5 * np.sum(states(s)[:, 2:] ** 2, axis=1)

                def ode_potential(s):
                    return _ode_energy(case, states(s)) - ode_kinetic(s)

                if ODE_HALVES[case.name]:
                    scale = _exchanged(ode_kinetic, ode_potential, t)
                else:
                    scale = _peak(lambda s: np.abs(_ode_energy(case, states(s))), t)
        elif case.name in EXACT:
            scale = _exchanged_along(case, lambda s: EXACT[case.name](case, np.asarray(s, float)), t)
        elif ar.energy_behaviour(m) == "source":
            scale = math.nan
        elif not (np.any(m.gravity) or len(m.springs.i) or len(m.anchors.i) or m.gravitation):
            scale = float(ar.kinetic_energy(m, m.v0[None])[0])
        else:
            pytest.fail(f"{case.name}: no route here to its energy scale")
        _SCALES[id(case)] = scale
    return _SCALES[id(case)]


def scale_slack(case) -> float:
    """Relative slack of this file's energy scale against the harness's: round-off where
    both read closed forms; where both read a reference run, twice the relative distance
    of the scale read along this file's run of the documented reference (RK4 at its
    ``dt``, Hermite between its steps, as the harness reads its own) from the scale along
    this file's DOP853 at 1e-12."""
    if case.exact != "reference-run":
        return 0.0
    t = np.linspace(0.0, case.duration, SCALE_GRID)
    documented = _exchanged_along(case, _documented_reference(case), t)
    return 2.0 * abs(documented - my_scale(case)) / my_scale(case)


def every_step(r: Run) -> tuple[np.ndarray, np.ndarray] | None:
    """Times and energies (summed here) of every step the engine took in this run and of
    every record: from a run of the engine recorded at every step, made here (a
    fixed-step engine with ``max_records`` = its steps; the reference's Dormand-Prince
    with its records cut to its step ends; scipy and Drake with none thinned), or the run's own
    records where they already hold every step (scipy on a scene with planes: its records
    are the case's grid, which is all its run watches; its step ends fall at the impacts
    it locates, where the velocity is two-valued). None for a run with no energy."""
    if "every" in r.cache:
        return r.cache["every"]
    case, traj = r.case, r.traj
    e_rec = _energy_of(case, traj)
    if e_rec is None:
        r.cache["every"] = None
        return None
    adapter = get_adapter(r.engine)
    n_steps = case.steps_for(r.dt)[0]
    every = None
    if not r.adaptive and len(traj.t) < n_steps + 1 and r.engine_status == "ok":
        every = adapter.simulate(dataclasses.replace(case, max_records=n_steps), r.method, r.dt)
        assert len(every.t) == n_steps + 1
    elif r.adaptive and r.engine == "reference":
        every = adapter.simulate(dataclasses.replace(case, max_records=1), r.method, r.dt)
    elif r.adaptive and r.engine == "scipy" and not (case.model is not None and case.model.planes):
        every = adapter.simulate(dataclasses.replace(case, max_records=10**9), r.method, r.dt)
    elif r.adaptive and r.engine == "drake":
        every = adapter.simulate(dataclasses.replace(case, max_records=10**9), r.method, r.dt)
    if every is None:
        out = (traj.t, e_rec)
    else:
        e_all = _energy_of(case, every)
        t_all = np.concatenate([traj.t, every.t])
        order = np.argsort(t_all, kind="stable")
        out = (t_all[order], np.concatenate([e_rec, e_all])[order])
    r.cache["every"] = out
    return out


def my_verdict(r: Run) -> tuple[str, float | None]:
    """The status this file gives the run: non-finite or runaway states (beyond 1e12) are
    ``unstable``, as is a run the engine stopped short of its end as such; a solver the
    engine says failed on finite states is ``solver-failed``; a finished run is judged by
    its motion (``ar.motion_verdict``) on its energies at the records and at every step."""
    traj, case = r.traj, r.case
    with np.errstate(invalid="ignore"):
        states = [traj.x] if traj.v is None else [traj.x, traj.v]
        finite = all(bool(np.all(np.isfinite(s)) and np.max(np.abs(s)) < 1e12) for s in states)
    stopped = traj.t[-1] < case.duration * (1 - 1e-9)
    if not finite or (r.engine_status == "unstable" and stopped):
        return "unstable", None
    if r.engine_status == "solver-failed":
        return "solver-failed", None
    behaviour = "conservative" if case.kind == "ode" else ar.energy_behaviour(case.model)
    if behaviour == "source" and case.escape_energy is None:
        return "ok", None  # an energy source: nothing the motion cannot do
    e = _energy_of(case, traj)
    scale = my_scale(case)
    if e is None or len(e) < 2 or not np.isfinite(scale):
        return "ok", None
    at_records = ar.motion_verdict(traj.t, e, scale, behaviour, case.escape_energy)
    t_all, e_all = every_step(r)
    verdict = ar.motion_verdict(traj.t, e, scale, behaviour, case.escape_energy, t_all, e_all)
    r.cache["at_records"] = at_records[1]
    return verdict


def _check_t_fail(r: Run, when: float | None) -> None:
    """``t_fail`` of a run the motion failed: no earlier than the step that shows the
    failure (``when``) or the record that does (an escape is dated from the records: the
    first record after the last one below the escape energy, and a dip below it between
    records puts the step later), and no later than that record; a failure seen only
    between records is published at the energy's peak over every step
    (``Trajectory.extremes``), at or after ``when``."""
    if when is None:
        return
    t_fail = float(r.row["t_fail"])
    first_record = r.cache.get("at_records")
    latest = r.case.duration if first_record is None else first_record
    earliest = when if first_record is None else min(when, first_record)
    assert earliest * (1 - 1e-12) <= t_fail <= latest * (1 + 1e-12), (
        f"{r.engine}/{r.method}: t_fail {t_fail:.6g} s, the motion failed at {when:.6g} s"
        + ("" if first_record is None else f" and a record shows it at {first_record:.6g} s")
    )


def _require_ok(r: Run) -> None:
    """Quantities are only published for runs that finished: a run the harness does not
    call ``ok`` must be one this file judges so too (test_status_of_the_motion), and
    nothing else is checked for it."""
    if r.row["status"] == "ok":
        return
    mine, _ = my_verdict(r)
    assert mine == r.row["status"], (
        f"published status {r.row['status']!r} ({r.row.get('message')}), the motion says {mine!r}"
    )
    pytest.skip(f"run {r.row['status']}: nothing else is published for it")


def _measured(t, u, w, engine: str = "reference"):
    """The heights each flight reached and the contacts between them, found here
    (``ar.arcs``), and the largest sample spacing of the run (s)."""
    drop, found = ar.arcs(t, u, w, G_FLOOR, velocity_noise(engine, t, u, w))
    return drop, found, float(np.max(np.diff(t)))


def velocity_noise(engine: str, t, u, w) -> float:
    """How far rounding alone moves a sampled velocity change (m/s): 0 for a float64
    engine (the 1e-6 of a kick covers it); for a float32 one, four float32 roundings of
    a velocity, and of a position over the shortest spacing (an engine whose velocities
    are position differences over a step: XPBD)."""
    if getattr(get_adapter(engine), "precision", "float64") != "float32":
        return 0.0
    eps = float(np.finfo(np.float32).eps)
    return 4 * eps * (float(np.max(np.abs(u))) / float(np.min(np.diff(t))) + float(np.max(np.abs(w))))


def _vertex_check(t, u, w, found, upto: int, label: str, noise: float = 0.0) -> None:
    """The physics behind "the highest sample": where a flight's positions lie on a
    parabola of curvature -g (every exact flight, and first-order ones too, whose
    positions are a parabola offset in slope), its highest sample is within ``g h^2 / 8``
    below the parabola's vertex (``h`` the spacing of the samples around it) and never
    above it: the apex is the height the flight reached, not an extrapolation."""
    runs = ar.flights(t, u, w, G_FLOOR, noise)
    for k, contact in enumerate(found[:upto], start=1):
        if contact["after"] is None or np.isnan(contact["apex"]):
            continue
        run = next(r for r in runs if r[0] == contact["after"])
        if len(run) < 3:
            continue
        fit = ar.ballistic_fit(t, u, run, G_FLOOR)
        if fit["residual"] > 1e-9:
            continue  # not a parabola (a soft contact still acting, a drag): nothing to compare
        top = int(run[np.argmax(u[run])])
        near = np.diff(t[max(top - 1, 0) : top + 2]).max()
        # round-off of a least-squares vertex over ~100 samples of metre-scale heights: 1e-9
        assert fit["apex"] - G_FLOOR * near**2 / 8 - 1e-9 <= contact["apex"] <= fit["apex"] + 1e-9, (
            f"{label} flight {k}: highest sample {contact['apex']:.9f} m, the flight's vertex "
            f"{fit['apex']:.9f} m (spacing {near:.3g} s)"
        )


def _installed(engine: str) -> bool:
    try:
        get_adapter(engine)
    except EngineNotInstalled:
        return False
    return True
