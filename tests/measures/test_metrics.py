"""The metrics on hand-made trajectories (mutation testing, tools/campaigns/mutation/README.md).

Each number is worked out here from its definition: the distance to the exact positions
at shared times, the relative energy error, the least-squares slope of log(error)
against log(dt) (exactly ``p`` for errors ``C dt^p``).
"""

from __future__ import annotations

import numpy as np
import pytest

from truestep.adapters.base import EnergyExtremes, Trajectory
from truestep.cases.case import Case, OdeSpec
from truestep.cases.exact import Exact
from truestep.measures import metrics
from truestep.reference_impl.model import Anchors, ParticleModel, Plane, Springs


def particles(n=2, **kw):
    base = dict(
        mass=np.ones(n), x0=np.zeros((n, 3)), v0=np.zeros((n, 3)), radius=np.zeros(n), fixed=np.zeros(n, bool)
    )
    return ParticleModel(**(base | kw))


def case(kind="particles", *, duration=0.3, error_norm="final", conservative=False, model=None, exact=None):
    if kind == "particles" and model is None:
        model = particles()
    scene = (
        model if kind == "particles" else OdeSpec("circle-field", np.array([1.0, 0.0]), second_order=False)
    )
    return Case(
        name="m",
        file="m",
        title="m",
        description="",
        scene=scene,
        duration=duration,
        dts=[0.1],
        quick_dts=[0.1],
        tolerances=[1e-6],
        quick_tolerances=[1e-6],
        exact=exact,
        error_norm=error_norm,
        conservative=conservative,
    )


T = np.array([0.0, 0.1, 0.2, 0.3])


def test_matching_finds_the_shared_times_to_1e9_relative():
    k, j = metrics._matching(T, np.array([0.1 + 1e-12, 0.25, 0.3 - 1e-12, 0.0]))
    np.testing.assert_array_equal(k, [1, 3, 0])
    np.testing.assert_array_equal(j, [0, 2, 3])
    k, j = metrics._matching(T, np.array([0.2 - 1e-12, 0.2 + 1e-12, 5.0, -1.0]))
    np.testing.assert_array_equal(k, [2, 2])
    np.testing.assert_array_equal(j, [0, 1])
    big = np.array([0.0, 1000.0, 2000.0])
    k, _ = metrics._matching(big, np.array([1000.0 + 5e-7, 2000.0 + 5e-6]))
    np.testing.assert_array_equal(k, [1])  # 1e-9 relative to |t|, not absolute
    k, j = metrics._matching(T, np.zeros(0))
    assert len(k) == len(j) == 0 and k.dtype.kind == "i"


def test_position_error_of_particles_is_the_worst_euclidean_distance():
    x = np.zeros((4, 2, 3))
    x[1, 0] = [3.0, 4.0, 0.0]  # 5 at t = 0.1
    x[2, 1] = [1.0, 1.0, 1.0]  # sqrt 3 at t = 0.2
    x[3, 0] = [0.0, 0.0, -2.0]
    x[3, 1] = [1.0, 0.0, 0.0]  # 2 at the end
    traj = Trajectory(t=T, x=x, v=None, energy=None)
    exact = Exact(t=T.copy(), x=np.zeros((4, 2, 3)))
    assert metrics.position_error(case(error_norm="final"), traj, exact) == 2.0
    assert metrics.position_error(case(error_norm="max"), traj, exact) == 5.0
    # the final error needs the end of the run among the shared times
    assert np.isnan(metrics.position_error(case(duration=0.5), traj, exact))
    assert np.isnan(metrics.position_error(case(), traj, Exact(t=np.array([7.0]), x=np.zeros((1, 2, 3)))))
    # only the shared times count
    part = Exact(t=np.array([0.2, 0.3]), x=np.zeros((2, 2, 3)))
    assert metrics.position_error(case(error_norm="max"), traj, part) == pytest.approx(2.0)
    # particles not alive, or not known exactly, are not compared
    alive = np.ones((4, 2), bool)
    alive[1, 0] = False
    traj_a = Trajectory(t=T, x=x, v=None, energy=None, alive=alive)
    assert metrics.position_error(case(error_norm="max"), traj_a, exact) == 2.0
    gone = np.ones((4, 2), bool)
    gone[:, 1] = False  # particle 1 never alive: its error (up to sqrt 3) is not counted
    x1 = np.zeros((4, 2, 3))
    x1[:, 1] = [1.0, 1.0, 1.0]
    x1[3, 0] = [0.0, 0.25, 0.0]
    traj_g = Trajectory(t=T, x=x1, v=None, energy=None, alive=gone)
    assert metrics.position_error(case(error_norm="max"), traj_g, exact) == 0.25
    assert metrics.position_error(case(error_norm="final"), traj_g, exact) == 0.25
    unknown = np.zeros((4, 2, 3))
    unknown[3, 0] = np.nan
    assert metrics.position_error(case(error_norm="final"), traj, Exact(T.copy(), unknown)) == 1.0


def test_position_error_of_an_ode_is_the_largest_component():
    y = np.zeros((4, 3))
    y[3] = [0.3, -0.4, 0.1]
    y[1] = [0.0, 0.0, 0.5]
    traj = Trajectory.of_ode(T, y, alive=np.zeros((4, 1), bool))
    exact = Exact.of_ode(T.copy(), np.zeros((4, 3)))
    c = case("ode", model=None)
    assert metrics.position_error(c, traj, exact) == pytest.approx(0.4)  # alive ignored for an ODE
    c_max = case("ode", model=None, error_norm="max")
    assert metrics.position_error(c_max, traj, exact) == pytest.approx(0.5)


def test_an_ode_run_in_the_old_layout_is_still_measured_with_a_deprecation_warning():
    """Adapters and exact solutions written before ``y`` put an ODE's states in ``x`` as
    (T, 1, dim): they are read the same, and told where the states belong now."""
    y = np.zeros((4, 2))
    y[3] = [0.3, -0.4]
    new = metrics.position_error(
        case("ode"), Trajectory.of_ode(T, y), Exact.of_ode(T.copy(), np.zeros((4, 2)))
    )
    with pytest.warns(DeprecationWarning, match=r"Trajectory.of_ode"):
        old = metrics.position_error(
            case("ode"),
            Trajectory(t=T, x=y[:, None, :], v=None, energy=None),
            Exact(T.copy(), np.zeros((4, 1, 2))),
        )
    assert old == new == pytest.approx(0.4)


def test_energy_drift_is_over_the_energy_scale_and_every_step():
    traj = Trajectory(t=T, x=np.zeros((4, 1, 3)), v=None, energy=np.array([-2.0, -2.2, -1.9, -2.1]))
    mx, end = metrics.energy_drift(case(conservative=True), traj, None, scale=2.0)
    assert mx == pytest.approx(0.1) and end == pytest.approx(0.05)
    # a spike between records, seen by a run watched at every step
    traj.extremes = EnergyExtremes(0.15, -2.3, 0.25, -1.5)
    mx, end = metrics.energy_drift(case(conservative=True), traj, None, scale=2.0)
    assert mx == pytest.approx(0.25) and end == pytest.approx(0.05)
    flat = Trajectory(t=T, x=traj.x, v=None, energy=np.zeros(4))
    assert metrics.energy_drift(case(conservative=True), flat, None, scale=1.0) == (0.0, 0.0)
    # damped: against the exact energy at the shared times, over the scale
    exact = Exact(t=np.array([0.0, 0.2, 0.3]), x=np.zeros((3, 1, 3)), energy=np.array([4.0, 3.0, 1.0]))
    mine = Trajectory(t=T, x=traj.x, v=None, energy=np.array([4.0, 9.0, 3.5, 2.0]))
    mx, end = metrics.energy_drift(case(), mine, exact, scale=4.0)
    assert mx == pytest.approx(0.25) and end == pytest.approx(0.25)
    # no energy, nothing to compare with, or no scale: NaN
    for traj_, exact_, scale in [
        (Trajectory(T, traj.x, None, None), exact, 1.0),
        (Trajectory(T, traj.x, None, np.zeros(0)), exact, 1.0),
        (mine, None, 1.0),
        (mine, Exact(t=exact.t, x=exact.x), 1.0),
        (mine, Exact(t=exact.t, x=exact.x, energy=np.ones(2)), 1.0),
        (mine, Exact(t=np.array([9.0]), x=exact.x[:1], energy=np.ones(1)), 1.0),
        (mine, exact, float("nan")),
    ]:
        assert all(np.isnan(metrics.energy_drift(case(), traj_, exact_, scale=scale)))


def test_energy_behaviour_reads_the_scene():
    assert metrics.energy_behaviour(case()) == "conservative"
    assert metrics.energy_behaviour(case("ode", model=None)) == "conservative"
    assert metrics.energy_behaviour(case(model=particles(drag=0.1))) == "dissipative"
    sp = Springs(np.array([0]), np.array([1]), np.ones(1), np.array([0.2]), np.ones(1))
    assert metrics.energy_behaviour(case(model=particles(springs=sp))) == "dissipative"
    sp0 = Springs(np.array([0]), np.array([1]), np.ones(1), np.zeros(1), np.ones(1))
    assert metrics.energy_behaviour(case(model=particles(springs=sp0))) == "conservative"
    an = Anchors(np.array([0]), np.zeros((1, 3)), np.ones(1), np.array([0.3]), np.ones(1))
    assert metrics.energy_behaviour(case(model=particles(anchors=an))) == "dissipative"
    up = np.array([0.0, 1.0, 0.0])
    for plane, kind in [
        (Plane(np.zeros(3), up, 0.9), "dissipative"),
        (Plane(np.zeros(3), up, 1.0, 0.2), "dissipative"),
        (Plane(np.zeros(3), up, 1.0, 0.0), "conservative"),
    ]:
        assert metrics.energy_behaviour(case(model=particles(planes=[plane]))) == kind
    kick = particles(drag=0.1, impulses=[(0, np.ones(3), 0.0, 1.0)])
    assert metrics.energy_behaviour(case(model=kick)) == "source"


def test_motion_failures_read_the_energy_against_its_scale():
    """Scale 1 J. Growth through every quarter, once 1 J from the start; a dissipative
    scene above its start by more than 0.1; a conservative one that jumps by more than 0.5
    and stays; an escape energy reached; none of it for a scene with energy sources."""
    from truestep.measures.stability import motion_failure

    t = np.linspace(0.0, 4.0, 81)
    x = np.zeros((81, 2, 3))
    grow = Trajectory(t=t, x=x, v=None, energy=np.exp(t))
    first = t[np.argmax(np.exp(t) - 1.0 > 1.0)]
    assert motion_failure(case(conservative=True), grow, 1.0).t == first
    jump = Trajectory(t=t, x=x, v=None, energy=np.where(t < 1.0, 1.0, 5.0))
    left = motion_failure(case(conservative=True), jump, 1.0)
    assert left.t == 1.0 and "left its start for good" in left.reason
    # a bounded swing that comes back to its start is none of these
    swing = Trajectory(t=t, x=x, v=None, energy=1.0 + 40 * np.sin(3 * t) ** 2)
    assert motion_failure(case(conservative=True), swing, 1.0) is None
    damped = case(model=particles(drag=0.5))
    small = Trajectory(t=t, x=x, v=None, energy=1.0 + 0.09 * np.sin(t) ** 2)
    assert motion_failure(damped, small, 1.0) is None
    gain = motion_failure(damped, swing, 1.0)
    assert gain.t == t[np.argmax(swing.energy - 1.0 > 0.1)] and "gained" in gain.reason
    # an overshoot that a stable method then gives off is no gain
    overshoot = Trajectory(t=t, x=x, v=None, energy=np.where(t < 0.5, 30.0, 0.01))
    assert motion_failure(damped, overshoot, 1.0) is None
    # ... and a gain kept between the records, seen at every step
    fine = np.linspace(0.0, 4.0, 801)
    seen = Trajectory(
        t=t,
        x=x,
        v=None,
        energy=np.ones(81),
        step_t=fine,
        step_energy=np.where((fine > 2.5) & (np.round(fine * 200) % 2 == 1), 1.5, 1.0),
    )
    assert motion_failure(damped, seen, 1.0) is None  # half the steps up: the median is not
    seen.step_energy = np.where(fine > 2.0125, 1.5, 1.0)
    assert motion_failure(damped, seen, 1.0).t == fine[np.argmax(fine > 2.0125)]
    bound = case(conservative=True)
    bound.escape_energy = 0.0
    orbit = Trajectory(t=t, x=x, v=None, energy=np.where(t < 2.0, -0.5, 0.02))
    escaped = motion_failure(bound, orbit, 4.0)
    assert escaped.t == 2.0 and "escaped" in escaped.reason
    assert motion_failure(case(conservative=True), orbit, 4.0) is None  # 0.52 of 4 J: no jump
    spike = Trajectory(t=t, x=x, v=None, energy=np.where((t > 1.0) & (t < 1.2), 0.3, -0.5))
    assert motion_failure(bound, spike, 4.0) is None  # through a close encounter and back
    src = case(model=particles(impulses=[(0, np.ones(3), 0.0, 1.0)]))
    assert motion_failure(src, grow, 1.0) is None
    assert motion_failure(case(), Trajectory(t[:1], x[:1], None, np.ones(1)), 1.0) is None
    assert motion_failure(case(), Trajectory(t, x, None, None), 1.0) is None


def test_fit_order_is_the_slope_over_the_asymptotic_range():
    dts = np.array([0.1, 0.05, 0.02, 0.01, 0.005])
    assert metrics.fit_order(dts, 3.0 * dts**2) == pytest.approx(2.0, rel=1e-12)
    # points outside [1e-11, 0.5] x scale are left out
    err = 0.5 * dts**3
    err[0] = 0.6  # not converging
    assert metrics.fit_order(dts, err) == pytest.approx(3.0, rel=1e-12)
    low = 1e-2 * dts**4
    low[-1] = 1e-12  # round-off
    assert metrics.fit_order(dts, low) == pytest.approx(4.0, rel=1e-12)
    assert np.isnan(metrics.fit_order(dts, np.array([1.0, 1.0, 1.0, 1.0, 1e-3])))
    edge = 0.5 * dts**3
    edge[0] = 0.5  # exactly at the bound: left out
    assert metrics.fit_order(dts, edge) == pytest.approx(3.0, rel=1e-12)
    # within the bound at a larger scale, the point still disagrees with the finer ones'
    # local orders, and is left out of the range
    assert metrics.fit_order(dts, edge, scale=10.0) == pytest.approx(3.0, rel=1e-12)
    assert np.isnan(metrics.fit_order(dts[:2], np.array([0.05, np.nan])))
    assert metrics.fit_order(dts[2:], 2.0 * dts[2:]) == pytest.approx(1.0, rel=1e-12)
    assert metrics.fit_order(list(dts[3:]), list(0.01 * dts[3:] ** 2)) == pytest.approx(2.0)
    assert metrics.fit_order(dts[::-1], 3.0 * dts[::-1] ** 2) == pytest.approx(2.0)  # any order


def test_fit_order_reads_the_range_where_the_local_orders_agree():
    """Second order at large steps turning first order at small ones (a symplectic method
    whose dt^2 term dominates until a dt^1 term takes over): the fit is the finest steps'
    order, 1, not a blend. An error that falls as dt^1 while a method declares 4 still
    reads 1."""
    dts = 0.02 / 2.0 ** np.arange(9)
    err = 10.0 * dts**2 + 2e-3 * dts
    local = metrics.local_orders(dts, err)
    assert local[0] > 1.9 and local[-1] < 1.4
    whole = np.polyfit(np.log(dts), np.log(err), 1)[0]
    fitted = metrics.fit_order(dts, err)
    assert abs(fitted - local[-1]) <= metrics.AGREE and fitted < whole - 0.2
    assert metrics.fit_order(dts, 0.3 * dts) == pytest.approx(1.0, rel=1e-12)


def test_exact_for_evaluates_and_keeps_the_last_solutions():
    m = particles(1, v0=np.array([[1.0, 2.0, 0.0]]), gravity=np.array([0.0, -10.0, 0.0]))
    c = case(model=m, exact="uniform-gravity")
    t = np.array([0.0, 0.5, 1.0])
    ex = metrics.exact_for(c, t)
    np.testing.assert_allclose(ex.x[:, 0], [[0, 0, 0], [0.5, 1.0 - 1.25, 0], [1.0, 2.0 - 5.0, 0]])
    assert metrics.exact_for(c, t.copy()) is ex  # the same times: kept
    assert metrics.exact_for(c, t[:2]) is not ex
    other = case(model=m, exact="uniform-gravity")
    assert metrics.exact_for(other, t) is not ex  # another case object
    assert metrics.exact_for(case(), t) is None
    for k in range(40):  # older entries fall out, the size stays bounded
        metrics.exact_for(c, np.array([float(k)]))
    assert len(metrics._EXACT_CACHE) <= metrics._EXACT_CACHE_SIZE == 32
    assert metrics.exact_for(c, t) is not ex
    assert metrics.exact_for(c, np.array([39.0])) is metrics.exact_for(c, np.array([39.0]))


def test_the_exact_paths_kept_are_bounded_in_bytes_and_the_newest_is_always_kept(case_named, monkeypatch):
    """A million balls' exact path at 21 records is 1 GB: the cache of exact paths is
    bounded in bytes as well as in count, and the path just asked for stays."""
    from truestep.measures import metrics

    case = case_named("particle-rain")
    monkeypatch.setattr(metrics, "_EXACT_CACHE", {})
    first = metrics.exact_for(case, np.linspace(0.0, 1.0, 11))
    size = metrics._bytes(first)
    assert size >= 2 * 11 * case.particles.n * 3 * 8
    monkeypatch.setattr(metrics, "_EXACT_CACHE_BYTES", size + 1)
    second = metrics.exact_for(case, np.linspace(0.0, 1.0, 12))
    assert [e for _, e in metrics._EXACT_CACHE.values()] == [second]
    monkeypatch.setattr(metrics, "_EXACT_CACHE_BYTES", 0)
    third = metrics.exact_for(case, np.linspace(0.0, 1.0, 13))
    assert [e for _, e in metrics._EXACT_CACHE.values()] == [third]
    assert metrics.exact_for(case, np.linspace(0.0, 1.0, 13)) is third
