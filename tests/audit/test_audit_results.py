"""The property audit of ``results.csv`` (see :mod:`audit_runs` for what is recomputed,
and how): each row's errors, energy drift, status, evaluations and steps, wall time and
the case's properties, recomputed for every engine from the raw trajectory.
"""

from __future__ import annotations

import dataclasses
import math

import audit_recompute as ar
import numpy as np
import pytest
from audit_runs import (
    _CASES,
    _SCALES,
    COUNT,
    ENERGY_CURVE,
    ERROR_PARAMS,
    EXACT,
    G_FLOOR,
    ROUNDOFF_REL,
    SCALE_GRID,
    Run,
    _check_t_fail,
    _close,
    _energy_of,
    _error_tolerance,
    _measured,
    _my_errors,
    _require_ok,
    _roundoff,
    _run_from,
    _vertex_check,
    case_of,
    every_step,
    methods_for,
    my_scale,
    my_verdict,
    run,
    scale_slack,
    step_of,
    velocity_noise,
)

from truestep.adapters import get_adapter
from truestep.cases.loader import CASE_DIR, load_case


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "particles", "engine", "method", "dt"), ERROR_PARAMS)
def test_error(name, duration, particles, engine, method, dt):
    """``error``, ``error_final``, ``error_v``: per record the worst particle's distance from
    the exact motion (an ODE's largest position component; its velocity half, or none),
    the worst over the records (arenstorf: at the end), at the end, and the velocities'
    worst; recomputed at every record from this file's exact motion."""
    r = _run_from(name, duration, particles, engine, method, dt)
    _require_ok(r)
    (error, final, error_v), (slack_x, slack_v) = _my_errors(r), _error_tolerance(r)
    for column, mine, slack in (
        ("error", error, slack_x),
        ("error_final", final, slack_x),
        ("error_v", error_v, slack_v),
    ):
        published = float(r.row[column])
        assert _close(published, mine, floor=slack), (
            f"{engine}/{method} {column} published {published:.10g}, recomputed {mine:.10g}"
        )


def _my_energy(r: Run) -> tuple[float, float]:
    """``energy_drift`` and ``energy_drift_final`` as this file reads them."""
    case, traj = r.case, r.traj
    scale = my_scale(case)
    e = _energy_of(case, traj)
    if e is None or not np.isfinite(scale):
        return math.nan, math.nan
    if case.conservative:
        _, e_all = every_step(r)
        return float(np.max(np.abs(e_all - e[0]))) / scale, float(abs(e[-1] - e[0])) / scale
    if case.name in ENERGY_CURVE:
        x, v = EXACT[case.name](case, traj.t)
        dev = np.abs(e - ar.energy(case.model, x, v)) / scale
        return float(dev.max()), float(dev[-1])
    return math.nan, math.nan


ENERGY_PARAMS = ERROR_PARAMS
"""Every run above: the bounces have no energy curve (NaN on both sides: a run that finds a
bounce a step late would be charged the whole drop), the rest are conservative or have one."""


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "particles", "engine", "method", "dt"), ENERGY_PARAMS)
def test_energy_drift(name, duration, particles, engine, method, dt):
    """``energy_drift`` and ``energy_drift_final``: the energy summed here, over the energy
    scale read here along the exact (or reference) motion; in conservative scenes against
    its start at every step the engine took (a run of it recorded at every step), in
    dissipative ones against the closed form's energy at the records."""
    r = _run_from(name, duration, particles, engine, method, dt)
    _require_ok(r)
    drift, final = _my_energy(r)
    # the scale of a reference-run case is read along two different reference runs
    rel = ROUNDOFF_REL + scale_slack(r.case)
    # ROUNDOFF_ABS: the drift of a conserved energy is itself round-off for exact schemes
    assert _close(float(r.row["energy_drift"]), drift, rel=rel), (
        f"{engine}/{method} energy_drift published {r.row['energy_drift']:.10g}, recomputed {drift:.10g}"
    )
    assert _close(float(r.row["energy_drift_final"]), final, rel=rel), (
        f"{engine}/{method} energy_drift_final published {r.row['energy_drift_final']:.10g}, "
        f"recomputed {final:.10g}"
    )


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "particles", "engine", "method", "dt"), ERROR_PARAMS)
def test_status_of_the_motion(name, duration, particles, engine, method, dt):
    """``status`` and ``t_fail``: the engine's own blow-up or solver failure, else the
    motion's verdict written here (README, "Unstable rows") on the energies of every step:
    an orbit that reaches its escape energy, a dissipative scene 0.1 of its scale above
    its start, a conservative one 0.5 of it above its start through the late half, or an
    energy that moved by its scale and grows in every quarter, is ``unstable``; a solver
    failure is ``solver-failed``, never ``unstable``."""
    r = _run_from(name, duration, particles, engine, method, dt)
    mine, when = my_verdict(r)
    published = r.row["status"]
    assert published == mine, (
        f"{engine}/{method}: published {published!r} ({r.row.get('message')}), the motion says {mine!r}"
        + (f" at t = {when:.6g} s" if when is not None else "")
    )
    if published == "unstable":
        _check_t_fail(r, when)


@pytest.mark.engine
@pytest.mark.parametrize(
    ("name", "duration", "particles", "engine", "method", "dt"),
    [p for p in ERROR_PARAMS if p.values[4] == "implicit-euler"],
)
def test_solver_failed_where_backward_euler_has_no_solution(name, duration, particles, engine, method, dt):
    """``solver-failed`` (implicit Euler's damped Newton finding no solution) only where
    backward Euler's equation itself has none: at the state the failing step started from
    (the run's last record, at ``t_fail``), for gravitating bodies, the closest pair's
    separation cannot reach the least value ``s + h^2 mu / s^2`` takes
    (``ar.backward_euler_has_no_solution``)."""
    r = _run_from(name, duration, particles, engine, method, dt)
    if r.row["status"] != "solver-failed":
        return
    m = r.case.model
    if (
        m is None
        or m.gravitation is None
        or m.gravitation.softening
        or np.any(m.gravity)
        or len(m.springs.i)
        or len(m.anchors.i)
        or m.planes
    ):
        pytest.skip("no route here to whether backward Euler has a solution in this scene")
    traj = r.traj
    assert traj.t[-1] == pytest.approx(float(r.row["t_fail"]), rel=1e-12), (
        "the failing step's start is recorded"
    )
    x, v = traj.x[-1], traj.v[-1]
    h = r.case.steps_for(r.dt)[1]
    gap = np.linalg.norm(x[:, None] - x[None, :], axis=2) + np.diag(np.full(len(x), np.inf))
    # the half-distance bound on the other bodies: each moves h |v| << its distance
    others = float(np.min(gap[gap > 2 * gap.min()], initial=np.inf))
    assert h * float(np.max(np.linalg.norm(v, axis=1))) < 0.1 * others
    none, numbers = ar.backward_euler_has_no_solution(m, x, v, h)
    assert none, (
        f"{engine}/{method}: published solver-failed at t = {r.row['t_fail']}, but a "
        f"solution exists ({numbers})"
    )


@pytest.mark.engine
@pytest.mark.parametrize(
    ("name", "duration", "particles", "engine", "method", "dt"),
    [
        p
        for p in ERROR_PARAMS
        if p.values[4] == "implicit-euler"
        and p.values[0] in ("harmonic-oscillator", "damped-oscillator", "stiff-spring")
    ],
)
def test_implicit_euler_solves_its_step(name, duration, particles, engine, method, dt):
    """The damped Newton solve of implicit Euler lands on backward Euler's own step: on a
    linear oscillator the step is one linear solve (``ar.step_matrix``), iterated here from
    the start; the recorded positions and velocities agree with it to Newton's tolerance
    (1e-10 of the state's size per step, at most ~1e-7 of the amplitude over these 100-250
    steps)."""
    r = _run_from(name, duration, particles, engine, method, dt)
    assert r.row["status"] == "ok"
    m, a = r.case.model, r.case.model.anchors
    d0 = m.x0[0] - a.point[0]
    axis = d0 / np.linalg.norm(d0)
    n, h = r.case.steps_for(dt)
    u, w = ar.oscillator_run(
        "implicit-euler",
        float(m.mass[0]),
        float(a.stiffness[0]),
        float(a.damping[0]),
        h,
        float(np.linalg.norm(d0) - a.rest[0]),
        float(m.v0[0] @ axis),
        n,
    )
    k = np.rint(r.traj.t / h).astype(int)
    amplitude = float(np.linalg.norm(d0))
    np.testing.assert_allclose(
        (r.traj.x[:, 0] - a.point[0]) @ axis, u[k] + a.rest[0], rtol=0, atol=1e-11 * amplitude
    )
    speed = amplitude * math.sqrt(float(a.stiffness[0] / m.mass[0]))
    np.testing.assert_allclose(r.traj.v[:, 0] @ axis, w[k], rtol=0, atol=1e-11 * speed)


THINNED_RUNS = [
    # (case, shortened duration (s), max_records, step (s), or None: the adaptive methods
    # at the case's first quick tolerance): records far apart
    ("harmonic-oscillator", 0.5, 7, 2e-3),
    ("damped-oscillator", None, 4, 0.125),
    ("kepler-orbit", 6.285, 5, None),
]
"""Runs recorded far more sparsely than they step (250 and 16 steps, 7 and 4 records):
between records a symplectic method's energy swings through most of its band, and on the
damped oscillator at 0.125 s (omega h = 1.25) the staggered energy of symplectic Euler's
family rises up to 0.88 of the scale above its start at steps that are none of them a
record (it is at or below its start at steps 4, 8, 12, 16); the adaptive methods on one
Kepler period (tens of accepted steps, 5 records: scipy thins its step ends to them).
Their drift and status must still be read over every step."""


def _thinned_params():
    out = []
    for name, duration, records, dt in THINNED_RUNS:
        case = case_of(name, duration, None, records)
        for engine, method in methods_for(case, adaptive=dt is None):
            adaptive = method in get_adapter(engine).adaptive_methods
            if adaptive != (dt is None):
                continue
            out.append(
                pytest.param(
                    name,
                    duration,
                    records,
                    engine,
                    method,
                    dt,
                    id=f"{name}-{records}-records-{engine}-{method}",
                )
            )
    return out


THINNED_PARAMS = _thinned_params()


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "records", "engine", "method", "dt"), THINNED_PARAMS)
def test_energy_and_status_between_records(name, duration, records, engine, method, dt):
    """``status``, ``energy_drift`` and ``energy_drift_final`` of runs whose records are far
    apart: as test_status_of_the_motion and test_energy_drift, from every step of a run of
    the engine made here (the records alone would miss what happens between them)."""
    case = case_of(name, duration, None, records)
    r = run(case, engine, method, step_of(case, engine, method, dt))
    if engine == "scipy":
        assert r.counted_steps > records, "scipy's steps outnumber the records here"
    if not r.adaptive:
        assert r.engine_status != "ok" or len(r.traj.t) == records + 1
    mine, when = my_verdict(r)
    assert r.row["status"] == mine, (
        f"{engine}/{method}: published {r.row['status']!r} ({r.row.get('message')}), the motion "
        f"says {mine!r}" + (f" at t = {when:.6g} s" if when is not None else "")
    )
    if mine != "ok":
        _check_t_fail(r, when)
        return
    drift, final = _my_energy(r)
    rel = ROUNDOFF_REL + scale_slack(r.case)
    assert _close(float(r.row["energy_drift"]), drift, rel=rel), (
        f"{engine}/{method} energy_drift published {r.row['energy_drift']:.10g}, recomputed {drift:.10g}"
    )
    assert _close(float(r.row["energy_drift_final"]), final, rel=rel)


# -- verdicts that may depend neither on the origin nor on how far apart the records are ------


@pytest.mark.engine
@pytest.mark.parametrize("lift", [0.0, -1.0, 15.0])
def test_a_scene_without_reference_is_judged_wherever_it_lies(lift):
    """hanging-cloth with no exact solution or reference run (as a user's case may come),
    lifted by ``lift`` m (anchors and all; -1 m puts the potential's zero at the
    anchors, E(0) = 0): its energy scale is the energy the motion exchanges, read here
    along this file's DOP853 run (the same at every lift), so that heun at 4 ms, which
    gains energy on the damped cloth, is ``unstable`` at the same first record, wherever
    the cloth hangs."""
    base = case_of("hanging-cloth", 1.0)
    m = base.model
    shift = np.array([0.0, lift, 0.0])
    model = dataclasses.replace(
        m, x0=m.x0 + shift, anchors=dataclasses.replace(m.anchors, point=m.anchors.point + shift)
    )
    key = ("no-reference", lift)
    if key not in _CASES:
        _CASES[key] = dataclasses.replace(base, scene=model, exact=None)
        # this file's scale needs a motion to read: the same cloth's DOP853 run (lifted
        # or not, the exchange is the same)
        t = np.linspace(0.0, base.duration, SCALE_GRID)
        x, v = ar.particle_reference(model, base.duration, 1e-9)(t)
        kinetic = ar.kinetic_energy(model, v)
        _SCALES[id(_CASES[key])] = ar.exchanged(kinetic, ar.energy(model, x, v) - kinetic)
    case = _CASES[key]
    r = run(case, "reference", "heun", 4e-3)
    mine, when = my_verdict(r)
    assert mine == "unstable" and r.row["status"] == mine, (
        f"lift {lift} m: published {r.row['status']!r} ({r.row.get('message')}), the motion says {mine!r}"
    )
    assert float(r.row["t_fail"]) == pytest.approx(when, rel=1e-12), (
        f"lift {lift} m: t_fail {r.row['t_fail']} s, the first step past 0.1 of the scale is at {when} s"
    )


@pytest.mark.engine
def test_an_escape_is_dated_at_its_step():
    """``t_fail`` of an escape ("an escape or a jump is unstable with its time"): the run
    is watched at every step, so its time is the first step at or above the escape
    energy, however far apart the records are: a Kepler orbit at dt 1 s escapes at its
    first step (energy -0.5 J to +1.28 J), recorded only at 0, 10 and 20 s."""
    case = case_of("kepler-orbit", 20.0, None, 2)
    r = run(case, "reference", "rk4", 1.0)
    mine, when = my_verdict(r)
    assert r.row["status"] == mine == "unstable"
    assert float(r.row["t_fail"]) == pytest.approx(when, rel=1e-12), (
        f"t_fail {r.row['t_fail']} s, the energy reached the escape energy at the step ending {when} s"
    )


MUJOCO_EVALUATIONS = {"Euler": 1, "implicit": 1, "implicitfast": 1, "RK4": 4}
"""Force evaluations per MuJoCo step, as counted by test_nfev on the cases with applied
forces (the passive callback runs once per evaluation: RK4 four times per step)."""

NEWTON_SWEEPS = {"semi-implicit": 1, "xpbd": 2, "vbd": 10}
"""Evaluations per Newton step: one force evaluation, or Newton's default iteration count
of XPBD (2) and VBD (10), each sweep counted as one (``SolverXPBD(iterations=2)``,
``SolverVBD(iterations=10)``, written in the adapter)."""


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "particles", "engine", "method", "dt"), ERROR_PARAMS)
def test_nfev_and_steps(name, duration, particles, engine, method, dt):
    """``nfev`` is the derivative evaluations (or evaluations per step times steps where
    the engine hides them) and ``steps`` the steps taken, both of the measured run:
    counted by the wrappers during that run (an adaptive solver's accepted steps, scipy's
    summed over the pieces between impacts), MuJoCo's own clock; the timed run repeats
    the same work."""
    r = _run_from(name, duration, particles, engine, method, dt)
    traj, row = r.traj, r.row
    if traj.t[-1] < r.case.duration * (1 - 1e-9):
        pytest.skip("the run stopped early: its counts cover what it did, nothing to compare")
    n_steps = max(1, round(r.case.duration / r.dt))
    h = r.case.duration / n_steps
    assert row["dt_kind"] == ("tolerance" if r.adaptive else "step")
    if r.adaptive and engine == "drake":
        pass  # counted by its monitor, below
    elif r.adaptive:
        assert row["steps"] == r.counted_steps, (
            f"{engine}/{method}: {row['steps']} steps published, {r.counted_steps} accepted steps counted"
        )
        if r.timed_run:
            assert r.timed.steps == r.counted_steps, "the timed run takes the same steps"
    else:
        assert row["steps"] == n_steps, f"{engine}/{method}: {row['steps']} steps published, {n_steps} taken"
        # the row's step is the step taken: the duration is a whole number of them
        assert abs(n_steps * r.dt - r.case.duration) <= 1e-9 * r.case.duration
    if engine in ("reference", "scipy"):
        if traj.path == "compiled":
            # the compiled loop calls no Python derivative: count the numpy path's calls
            # on the same run with the wrappers instead
            from truestep.adapters.reference import ReferenceAdapter

            COUNT["calls"] = 0
            ReferenceAdapter(compiled=False).simulate(r.case, method, r.dt)
            assert row["nfev"] == COUNT["calls"], f"{method}: nfev {row['nfev']}, counted {COUNT['calls']}"
        else:
            assert row["nfev"] == r.counted, f"{engine}/{method}: nfev {row['nfev']}, counted {r.counted}"
            if r.timed_run:
                assert r.timed.counted == r.counted, "the timed run makes the same evaluations"
    elif engine == "drake":
        # its derivative is the reference system's, counted by the same wrappers; the
        # monitor counted every step and the Simulator's initialisation
        assert row["nfev"] == r.counted, f"drake/{method}: nfev {row['nfev']}, counted {r.counted}"
        assert row["steps"] == r.counted_steps - 1, (
            f"drake/{method}: {row['steps']} steps, monitor saw {r.counted_steps - 1}"
        )
    elif engine in ("pymunk", "pybullet"):
        # one space.step / stepSimulation per step, one force evaluation in each
        assert r.counted == n_steps, f"{engine}: {r.counted} step calls counted for {n_steps} steps"
        assert row["nfev"] == r.counted
    elif engine == "mujoco":
        clock = round(float(traj.t[-1]) / h)  # MuJoCo's own d.time at the last record
        assert clock == n_steps
        if r.counted:
            assert row["nfev"] == r.counted, f"mujoco/{method}: nfev {row['nfev']}, counted {r.counted}"
        assert row["nfev"] == MUJOCO_EVALUATIONS[method] * clock
    elif engine == "mujoco-warp":
        # one captured MuJoCo step per step; MuJoCo's evaluations per step (its model)
        assert row["nfev"] == MUJOCO_EVALUATIONS[method] * n_steps
    elif engine == "newton":
        # one captured step per step; one force evaluation, or one per XPBD/VBD sweep
        assert row["nfev"] == NEWTON_SWEEPS[method] * n_steps


@pytest.mark.engine
@pytest.mark.parametrize(
    ("name", "duration", "particles", "engine", "method", "dt"),
    [p for p in ERROR_PARAMS if p.values[4] in ("dopri5", "RK45", "DOP853", "Radau")],
)
def test_adaptive_records(name, duration, particles, engine, method, dt):
    """Where an adaptive run is recorded (README "Contact and adaptive steps"): the
    reference's Dormand-Prince on the case's grid of ``max_records + 1`` evenly spaced
    times (its continuous extension) besides its step ends; scipy on that grid when the
    scene has planes (impacts located by its events), else at its step ends (every one,
    or evenly thinned to ``max_records``). Records increase strictly, from 0 to the end."""
    r = _run_from(name, duration, particles, engine, method, dt)
    if r.engine_status != "ok":
        pytest.skip(f"run {r.engine_status}")
    t, case = r.traj.t, r.case
    assert t[0] == 0.0 and np.all(np.diff(t) > 0)
    assert t[-1] == pytest.approx(case.duration, rel=1e-12)
    grid = np.linspace(0.0, case.duration, case.max_records + 1)
    on_grid = np.min(np.abs(t[:, None] - grid[None, :]), axis=0) <= 1e-12 * max(1.0, case.duration)
    planes = case.model is not None and bool(case.model.planes)
    if engine == "reference":
        assert on_grid.all(), f"{np.sum(~on_grid)} of the grid's times are not recorded"
        assert len(t) <= len(grid) + r.counted_steps
    elif planes:
        assert on_grid.all() and len(t) == len(grid), "scipy with planes: the grid alone"
    else:
        assert len(t) == min(r.counted_steps, case.max_records) + 1, "scipy: its step ends"


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "particles", "engine", "method", "dt"), ERROR_PARAMS)
def test_wall_time(name, duration, particles, engine, method, dt):
    """``wall_s`` times the stepping of the timed run only (of the measured run where none
    was timed): positive, and within the seconds measured here around that whole
    ``simulate`` call (scene building included)."""
    r = _run_from(name, duration, particles, engine, method, dt)
    assert 0.0 < float(r.row["wall_s"]) <= r.wall
    if r.engine_status == "ok":
        # this file's timing asks for one timed run (the first of each engine and method,
        # :func:`run`; none for the others): one repeat or none, no spread from one run
        assert r.row["repeats"] == (1 if r.timed_run else 0)
        assert np.isnan(float(r.row["wall_s_spread"]))


@pytest.mark.parametrize("path", sorted(CASE_DIR.glob("*.toml")), ids=lambda p: p.stem)
def test_every_swept_step_is_the_step_taken(path):
    """Every ``dt`` a case sweeps (full and quick; a case that names step counts, their
    ``duration / steps``) is a whole number of steps into its duration, so that a row's
    ``dt`` is the step its run took (README "Writing a case"): the steps a run takes,
    ``round(duration / dt)``, times ``dt`` is the duration to round-off."""
    case = load_case(path)
    for dt in list(case.dts) + list(case.quick_dts):
        n, h = case.steps_for(dt)
        assert abs(n * dt - case.duration) <= 1e-9 * case.duration, (
            f"{path.stem}: dt {dt!r} s is {case.duration / dt:.6f} steps of its {case.duration} s"
        )
        assert h == pytest.approx(dt, rel=1e-9)


# -- the case's properties --------------------------------------------------------------------


def _prop_params(name, duration=None, dt=None, *, adaptive=True, only=None):
    case = case_of(name, duration)
    dt = case.quick_dts[0] if dt is None else dt
    return [
        pytest.param(name, duration, engine, method, dt, id=f"{name}-{engine}-{method}-{dt:g}")
        for engine, method in methods_for(case, adaptive=adaptive, only=only)
    ]


def _prop_run(name, duration, engine, method, dt) -> Run:
    case = case_of(name, duration)
    r = run(case, engine, method, step_of(case, engine, method, dt))
    _require_ok(r)
    return r


BOUNCE_PARAMS = _prop_params("bouncing-ball")


def _every_step_recorded(r) -> bool:
    """Whether the run holds a record at every step it took (apexes and bounce times are
    published only then, README "Contact and adaptive steps")."""
    return not r.traj.steps or len(r.traj.t) >= r.traj.steps + 1


def _drop(name: str, duration: float, engine: str, method: str, dt: float) -> tuple:
    """A bounce case's run and what its bounces are read from: (run, trajectory, the
    sphere's lowest point above the floor u (m), its vertical velocity w (m/s), the
    floor's restitution e, the drop height h0 (m), the number of bounces checked)."""
    r = _prop_run(name, duration, engine, method, dt)
    case, traj = r.case, r.traj
    u, w = traj.x[:, 0, 1] - case.model.radius[0], traj.v[:, 0, 1]
    e, h0 = case.model.planes[0].restitution, float(u[0])
    return r, traj, u, w, e, h0, int(case.exact_params.get("bounces", 3))


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "engine", "method", "dt"), BOUNCE_PARAMS)
def test_apex_height_error(name, duration, engine, method, dt):
    """``apex_height_error``: the largest relative error of the first three apexes against
    ``e^(2n) h0``; each apex here is the highest sample of the flight after a contact,
    flights found from the samples (free-fall kicks above the plane), the drop's
    ``e^(2n) h0`` from the bounce schedule's launch speeds."""
    r, traj, u, w, e, h0, bounces = _drop(name, duration, engine, method, dt)
    published = float(r.row["apex_height_error"])
    if not _every_step_recorded(r):
        assert np.isnan(published), f"a run recorded more sparsely than its steps publishes {published}"
        return
    _, launches = ar.bounce_times(h0, G_FLOOR, e, bounces)
    exact = launches**2 / (2 * G_FLOOR)
    _, found, _ = _measured(traj.t, u, w, engine)
    apexes = [c["apex"] for c in found if c["after"] is not None]
    if len(apexes) < bounces:
        assert published == math.inf, f"{len(apexes)} flights seen here, published {published}"
        return
    _vertex_check(traj.t, u, w, found, bounces, f"{engine}/{method}", velocity_noise(engine, traj.t, u, w))
    mine = max(abs(a / hk - 1.0) for a, hk in zip(apexes, exact, strict=False))
    # the same samples, read by two detectors: round-off
    assert _close(published, mine, _roundoff(engine)), (
        f"{engine}/{method}: apex_height_error published {published:.6g}, the heights reached "
        f"give {mine:.6g} (apexes {np.round(apexes[:bounces], 5).tolist()} m against "
        f"{np.round(exact, 5).tolist()} m)"
    )


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "engine", "method", "dt"), BOUNCE_PARAMS)
def test_bounce_time_error(name, duration, engine, method, dt):
    """``bounce_time_error``: the largest error of the first three bounce times (each
    contact's lowest sample, contacts being what lies between the flights found here)
    against the rigid schedule ``T_1 = sqrt(2 h0 / g)``, ``T_(k+1) = T_k + 2 e^k V / g``."""
    r, traj, u, w, e, h0, bounces = _drop(name, duration, engine, method, dt)
    published = float(r.row["bounce_time_error"])
    if not _every_step_recorded(r):
        assert np.isnan(published)
        return
    times, _ = ar.bounce_times(h0, G_FLOOR, e, bounces)
    _, found, _ = _measured(traj.t, u, w, engine)
    lows = [float(traj.t[c["low"]]) for c in found if c["after"] is not None]
    if len(lows) < bounces:
        assert published == math.inf
        return
    mine = max(abs(a - tk) for a, tk in zip(lows, times, strict=False))
    assert _close(published, mine, _roundoff(engine)), (
        f"{engine}/{method}: bounce_time_error published {published:.6g} s, the contacts' lowest "
        f"samples give {mine:.6g} s (at {np.round(lows[:bounces], 5).tolist()} against "
        f"{np.round(times, 5).tolist()})"
    )


SPARSE_BOUNCE_PARAMS = [
    pytest.param(engine, method, id=f"bouncing-ball-100-records-{engine}-{method}")
    for engine, method in methods_for(
        case_of("bouncing-ball", None, None, 100),
        adaptive=False,
        only=(("reference", "lecture"), ("pymunk", "default"), ("pybullet", "default"), ("mujoco", "Euler")),
    )
]


@pytest.mark.engine
@pytest.mark.parametrize(("engine", "method"), SPARSE_BOUNCE_PARAMS)
def test_apexes_need_every_step(engine, method):
    """``apex_height_error`` and ``bounce_time_error`` of a bouncing-ball run recorded at 100
    of its 625 steps: NaN (a flight's highest sample and a contact's lowest are read from
    a run recorded at every step, never guessed between records), while its error and
    status are still published."""
    case = case_of("bouncing-ball", None, None, 100)
    r = run(case, engine, method, case.quick_dts[0])
    assert len(r.traj.t) == 101 and r.traj.steps == 625
    assert np.isnan(float(r.row["apex_height_error"])) and np.isnan(float(r.row["bounce_time_error"]))
    assert r.row["status"] == "ok" and np.isfinite(float(r.row["error"]))


PENETRATION_PARAMS = (
    BOUNCE_PARAMS
    + _prop_params("sliding-contact")
    + _prop_params("particle-fountain", only=("lecture", "symplectic-euler"))
)


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "engine", "method", "dt"), PENETRATION_PARAMS)
def test_max_penetration(name, duration, engine, method, dt):
    """``max_penetration``: the deepest any live particle's lowest point went below a plane
    over the records (0 if none did)."""
    r = _prop_run(name, duration, engine, method, dt)
    m, traj = r.case.model, r.traj
    alive = np.ones(traj.x.shape[:2], bool) if traj.alive is None else traj.alive
    alive = alive & ~m.fixed[None, :]
    deepest = 0.0
    for plane in m.planes:
        below = m.radius[None, :] - (traj.x - plane.point) @ plane.normal
        deepest = max(deepest, float(np.max(below[alive], initial=0.0)))
    assert _close(float(r.row["max_penetration"]), deepest)


SLIDE_PARAMS = _prop_params("sliding-contact")


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "engine", "method", "dt"), SLIDE_PARAMS)
def test_stopping_distance_error(name, duration, engine, method, dt):
    """``stopping_distance_error``: ``|s - v0^2 / (2 mu g)|`` with ``s`` the distance slid
    along the floor by the last record (Coulomb friction's closed form)."""
    r = _prop_run(name, duration, engine, method, dt)
    m, traj = r.case.model, r.traj
    v0, mu = float(np.linalg.norm(m.v0[0])), m.planes[0].friction
    slid = float(np.hypot(traj.x[-1, 0, 0] - m.x0[0, 0], traj.x[-1, 0, 2] - m.x0[0, 2]))
    mine = abs(slid - v0**2 / (2 * mu * G_FLOOR))
    assert _close(float(r.row["stopping_distance_error"]), mine)


FINAL_SPEED_PARAMS = SLIDE_PARAMS + _prop_params("hanging-cloth", 0.5, adaptive=False)


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "engine", "method", "dt"), FINAL_SPEED_PARAMS)
def test_final_speed(name, duration, engine, method, dt):
    """``final_speed``: the fastest live particle at the last record."""
    r = _prop_run(name, duration, engine, method, dt)
    speed = np.sqrt(np.sum(r.traj.v[-1] ** 2, axis=1))[~r.case.model.fixed]
    assert _close(float(r.row["final_speed"]), float(speed.max()))


STRAIN_PARAMS = (
    _prop_params("triangle-impulse")
    + _prop_params("cube-inside-out")
    + _prop_params("cube-braced")
    + _prop_params("rope-pendulum", 0.5, adaptive=False)
    + _prop_params("hanging-cloth", 0.5, adaptive=False)
    + _prop_params("stiff-cloth", 0.05, 2.5e-4, adaptive=False)
)


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "engine", "method", "dt"), STRAIN_PARAMS)
def test_max_strain(name, duration, engine, method, dt):
    """``max_strain``: the largest ``| L / r - 1 |`` of any spring over the run, with the
    rest length ``r`` the mesh's edge at the start (every mesh is built at rest)."""
    r = _prop_run(name, duration, engine, method, dt)
    m, x = r.case.model, r.traj.x
    s = m.springs
    rest = np.linalg.norm(m.x0[s.i] - m.x0[s.j], axis=1)
    length = np.linalg.norm(x[:, s.i] - x[:, s.j], axis=2)
    assert _close(float(r.row["max_strain"]), float(np.max(np.abs(length / rest - 1.0))))


VOLUME_PARAMS = _prop_params("cube-inside-out") + _prop_params("cube-braced")


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "engine", "method", "dt"), VOLUME_PARAMS)
def test_min_signed_volume(name, duration, engine, method, dt):
    """``min_signed_volume``: the smallest enclosed volume over the run relative to the
    start, from cones on the surface's own centroid; the surface is closed and outward
    and encloses the cube's ``size^3`` at the start."""
    r = _prop_run(name, duration, engine, method, dt)
    faces = r.case.model.surfaces[0]
    assert ar.closed_and_outward(faces)
    volume = ar.enclosed_volume(r.traj.x, faces)
    assert volume[0] == pytest.approx(1.0, rel=1e-12)  # the 1 m cube of both case files
    assert _close(float(r.row["min_signed_volume"]), float(np.min(volume / volume[0])))


MOMENTUM_PARAMS = (
    _prop_params("spring-damper-pair")
    + _prop_params("earth-orbit")
    + _prop_params("triangle-impulse")
    + _prop_params("triangle-impulse", dt=0.0025)
)


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "engine", "method", "dt"), MOMENTUM_PARAMS)
def test_momentum_drift(name, duration, engine, method, dt):
    """``momentum_drift``: internal forces conserve ``P = sum m v``, so after the last
    impulse it must be ``P(0)`` plus every impulse's ``F (t_off - t_on)`` (delivered and
    kept); the largest distance from that over the records after the impulses, relative
    to the larger of ``|P_expected|`` and ``sum m |v|`` there."""
    r = _prop_run(name, duration, engine, method, dt)
    m, traj = r.case.model, r.traj
    p = np.einsum("n,tni->ti", m.mass, traj.v)
    expected = m.mass @ m.v0
    t_end = 0.0
    for _, force, t_on, t_off in m.impulses:
        expected = expected + np.asarray(force) * (t_off - t_on)
        t_end = max(t_end, t_off)
    after = traj.t >= t_end - 1e-9 * max(1.0, t_end)
    k0 = int(np.argmax(after))
    scale = max(float(np.linalg.norm(expected)), float(m.mass @ np.linalg.norm(traj.v[k0], axis=1)))
    mine = float(np.max(np.linalg.norm(p[after] - expected, axis=1))) / scale
    published = float(r.row["momentum_drift"])
    # The drift is relative to a scale that is a convention (|P| or sum m |v|: 1% apart for
    # the triangle); a published number that misses an undelivered impulse is off by
    # orders of magnitude. Round-off of a conserved sum: 1e-12 (of the scale).
    assert abs(published - mine) <= 0.05 * mine + 1e-12, (
        f"{engine}/{method}: momentum_drift published {published:.3g}, recomputed {mine:.3g} "
        f"(P after the impulses {p[-1][:2].round(6).tolist()}, expected {expected[:2].round(6).tolist()})"
    )


TUNNEL_PARAMS = _prop_params("high-speed-impact", dt=1e-3) + _prop_params("high-speed-impact", dt=5e-5)


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "engine", "method", "dt"), TUNNEL_PARAMS)
def test_tunnelled(name, duration, engine, method, dt):
    """``tunnelled``: particles that end behind the wall's back face having started in
    front of its front face (the wall: 1 cm thick, front face at x = 1 m, facing -x)."""
    r = _prop_run(name, duration, engine, method, dt)
    m, x = r.case.model, r.traj.x
    count = 0
    for plane in m.planes:
        if plane.thickness > 0:
            front = (x[0] - plane.point) @ plane.normal
            back = (x[-1] - plane.point) @ plane.normal
            count += int(np.sum((front > 0) & (back < -plane.thickness)))
    assert float(r.row["tunnelled"]) == count


def _pool(case, traj):
    spec = case.model.emitters[0]
    first = case.model.n - spec.capacity
    return spec, traj.alive[:, first:], first


EMITTER_PARAMS = _prop_params("hair-strands", only=("lecture", "euler", "rk4")) + _prop_params(
    "particle-fountain", only=("lecture", "symplectic-euler")
)


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "engine", "method", "dt"), EMITTER_PARAMS)
def test_spawn_rate_z(name, duration, engine, method, dt):
    """``spawn_rate_z``: lives counted here (runs of records a slot is alive) against the
    frames begun, with the count's moments integrated here."""
    r = _prop_run(name, duration, engine, method, dt)
    spec, alive, _ = _pool(r.case, r.traj)
    spawned = len(ar.lives(alive))
    frames = math.floor(float(r.traj.t[-1]) / spec.frame_dt + 1e-9) + 1
    mean, var = ar.spawn_moments(spec.rate_n, spec.rate_r)
    mine = (spawned - frames * mean) / math.sqrt(frames * var)
    # the midpoint rule over 4e5 points integrates the rounding variance to ~1e-10
    assert _close(float(r.row["spawn_rate_z"]), mine, rel=1e-6)


@pytest.mark.engine
@pytest.mark.parametrize(
    ("name", "duration", "engine", "method", "dt"),
    [p for p in EMITTER_PARAMS if p.values[0] == "particle-fountain"],
)
def test_population_z(name, duration, engine, method, dt):
    """``population_z``: the summed live population at the last record of every frame from
    ``lifetime + jitter`` on, against its distribution under the emitter's law, by Monte
    Carlo (4000 replays of spawn counts and lifetimes)."""
    r = _prop_run(name, duration, engine, method, dt)
    spec, alive, _ = _pool(r.case, r.traj)
    t = r.traj.t
    frame = np.floor(t / spec.frame_dt + 1e-9).astype(int)
    last = np.flatnonzero(np.r_[frame[1:] != frame[:-1], True])
    lifetimes = np.arange(spec.lifetime - spec.lifetime_jitter, spec.lifetime + spec.lifetime_jitter + 1)
    sampled = last[frame[last] >= lifetimes.max()]
    observed = float(alive[sampled].sum())
    null = ar.population_null(frame[sampled], spec.rate_n, spec.rate_r, lifetimes, 4000, seed=1)
    mine = (observed - null.mean()) / null.std()
    # Monte Carlo error of 4000 replays: the mean to sd / 63, the sd to 1.1%; four of each
    published = float(r.row["population_z"])
    assert abs(published - mine) <= 4 * (1 / math.sqrt(4000) + abs(mine) / math.sqrt(2 * 4000)), (
        f"population_z published {published:.3f}, Monte Carlo {mine:.3f}"
    )


HAIR_PARAMS = [p for p in EMITTER_PARAMS if p.values[0] == "hair-strands"]


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "engine", "method", "dt"), HAIR_PARAMS)
def test_strand_count(name, duration, engine, method, dt):
    """``strand_count``: every life is one strand; a complete life spans ``lifetime``
    frames of records exactly (two lives merged in one slot would span more)."""
    r = _prop_run(name, duration, engine, method, dt)
    spec, alive, _ = _pool(r.case, r.traj)
    lives = ar.lives(alive)
    per_frame = round(spec.frame_dt / (r.traj.t[1] - r.traj.t[0]))
    last = len(r.traj.t) - 1
    assert all(b - a + 1 == spec.lifetime * per_frame for _, a, b in lives if b < last)
    assert float(r.row["strand_count"]) == len(lives)


@pytest.mark.engine
@pytest.mark.parametrize(("name", "duration", "engine", "method", "dt"), HAIR_PARAMS)
def test_strand_error(name, duration, engine, method, dt):
    """``strand_error``: the farthest strand point from the free flight (no drag here) fixed
    by its root's position and velocity; for explicit Euler also its closed form
    ``g h s / 2`` (positions lag the exact parabola by ``g h s / 2`` after ``s`` seconds)."""
    r = _prop_run(name, duration, engine, method, dt)
    _, alive, first = _pool(r.case, r.traj)
    t, x, v, g = r.traj.t, r.traj.x, r.traj.v, r.case.model.gravity
    assert r.case.model.drag == 0
    worst, longest = 0.0, 0.0
    for slot, a, b in ar.lives(alive):
        s = t[a : b + 1] - t[a]
        path = x[a, first + slot] + np.outer(s, v[a, first + slot]) + 0.5 * np.outer(s**2, g)
        worst = max(worst, float(np.max(np.linalg.norm(x[a : b + 1, first + slot] - path, axis=1))))
        longest = max(longest, float(s[-1]))
    published = float(r.row["strand_error"])
    assert _close(published, worst, floor=1e-12)
    if method == "euler":
        h = float(t[1] - t[0])
        assert published == pytest.approx(float(np.linalg.norm(g)) * h * longest / 2, rel=1e-9)
