"""Point-plane collisions, resting contact and friction; the case files that use them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from truestep.adapters.reference import ReferenceAdapter
from truestep.cases.exact_particles import bounce_schedule
from truestep.measures.properties import PROPERTIES
from truestep.reference_impl.collisions import (
    EPS_DISTANCE,
    EPS_SPEED,
    PlaneCollisions,
    add_contact_forces,
    box_planes,
    contact_projection,
    signed_distances,
)
from truestep.reference_impl.integrate import integrate
from truestep.reference_impl.model import ParticleModel, Plane
from truestep.reference_impl.particles import ParticleSystem
from truestep.reference_impl.passes import passes_for
from truestep.reference_impl.solvers import get_solver

UP = np.array([0.0, 1.0, 0.0])
G = 9.81


def ball(h0: float, r: float, e: float, *, v0=(0.0, 0.0, 0.0), friction: float = 0.0):
    model = ParticleModel(
        mass=np.array([1.0]),
        x0=np.array([[0.0, r + h0, 0.0]]),
        v0=np.array([v0], float),
        radius=np.array([r]),
        fixed=np.zeros(1, bool),
        gravity=-G * UP,
        planes=[Plane(np.zeros(3), UP, e, friction)],
        dimension=2,
    )
    return model, ParticleSystem(model, passes_for(model))


def test_bounce_heights_follow_e_to_the_2n():
    e, h0, r = 0.8, 1.0, 0.05
    _, system = ball(h0, r, e)
    run = integrate(get_solver("lecture")(system), 2.5, 1e-3, max_records=3000)
    y, vy = run.x[:, 1] - r, run.x[:, 4]
    up = np.flatnonzero((vy[1:] > 0) & (vy[:-1] <= 0)) + 1
    apex = y[up] + vy[up] ** 2 / (2 * G)  # the apex of the flight through each record
    n = np.arange(1, 4)
    # Between bounces the lecture's update is exact under gravity, and the penetration
    # add-on keeps the energy fraction e^2 at each bounce: round-off only (1e-12 of h0).
    assert np.allclose(apex[:3], e ** (2 * n) * h0, rtol=1e-12, atol=0)


def test_bounce_times_converge_at_first_order():
    e, h0, r = 0.8, 1.0, 0.05
    times, _ = bounce_schedule(h0, 0.0, G, e, 2.0)
    errors = []
    for dt in (2e-3, 1e-3):
        model, _ = ball(h0, r, e)
        traj = ReferenceAdapter().simulate(_case(model, 2.0), "lecture", dt)
        errors.append(PROPERTIES["bounce_time_error"](_case(model, 2.0), traj))
    # Each impact is found at the end of the step that crosses the plane: late by less
    # than one step per bounce, so the first 3 bounce times are off by at most 3 dt.
    assert errors[0] <= 3 * 2e-3 and errors[1] <= 3 * 1e-3
    assert errors[1] < 0.75 * errors[0]
    assert times[0] == pytest.approx(np.sqrt(2 * h0 / G), rel=1e-15)


def _case(model: ParticleModel, duration: float):
    from truestep.cases.case import Case

    return Case(
        name="t",
        file="t",
        title="t",
        description="",
        duration=duration,
        dts=[0.01],
        quick_dts=[0.01],
        tolerances=[1e-6],
        quick_tolerances=[1e-6],
        scene=model,
        exact="bouncing-ball",
        max_records=10000,
        exact_params={"bounces": 3},
    )


@pytest.mark.parametrize("method", ["lecture", "rk4", "verlet", "euler"])
def test_contact_keeps_a_resting_particle_on_the_plane(method):
    _, system = ball(0.0, 0.1, 0.5)
    assert system.contact[0, 0]  # on the wall, at rest, pushing: in contact from the start
    integrate(get_solver(method)(system), 1.0, 0.01)
    # The contact force cancels gravity exactly (F' = F_T): the particle neither sinks
    # nor lifts off, and its normal velocity stays zero.
    assert system.positions[0, 1] == 0.1
    assert system.velocities[0, 1] == 0.0


def test_a_dropped_ball_comes_to_rest_after_its_bounces():
    _, system = ball(0.2, 0.05, 0.5)
    # All bounces are over by t_1 (1 + 2 e / (1 - e)) = 0.6 s.
    integrate(get_solver("lecture")(system), 1.5, 1e-3)
    assert system.contact[0, 0]
    assert abs(system.positions[0, 1] - 0.05) < 1e-12 and system.velocities[0, 1] == 0.0


def test_friction_stops_a_sliding_particle_at_v0_squared_over_2_mu_g():
    v0, mu = 3.0, 0.3
    _, system = ball(0.0, 0.05, 0.5, v0=(v0, 0.0, 0.0), friction=mu)
    integrate(get_solver("lecture")(system), 1.5, 0.01)
    exact = v0**2 / (2 * mu * G)
    # The lecture's update is exact under the constant friction deceleration; the stop
    # is found within one step: error at most mu g dt^2 / 2 = 1.5e-4 m.
    assert abs(system.positions[0, 0] - exact) <= 0.5 * mu * G * 0.01**2
    assert np.all(system.velocities == 0.0)


def test_static_friction_holds_a_particle_on_a_gentle_slope():
    angle = np.radians(10.0)  # tan 10 deg = 0.18 < mu = 0.3: it must stay
    n = np.array([-np.sin(angle), np.cos(angle), 0.0])
    model = ParticleModel(
        mass=np.array([1.0]),
        x0=np.array([[0.0, 0.0, 0.0]]),
        v0=np.zeros((1, 3)),
        radius=np.zeros(1),
        fixed=np.zeros(1, bool),
        gravity=-G * UP,
        planes=[Plane(np.zeros(3), n, 0.0, 0.3)],
    )
    system = ParticleSystem(model, passes_for(model))
    integrate(get_solver("lecture")(system), 1.0, 0.01)
    assert np.allclose(system.positions, 0.0, atol=1e-15)


def test_particles_stay_inside_a_box():
    rng = np.random.default_rng(2)
    n = 200
    model = ParticleModel(
        mass=np.ones(n),
        x0=rng.uniform(0.1, 0.9, (n, 3)),
        v0=rng.normal(0, 5, (n, 3)),
        radius=np.full(n, 0.02),
        fixed=np.zeros(n, bool),
        gravity=-G * UP,
        planes=box_planes(np.zeros(3), np.ones(3), restitution=0.9),
    )
    system = ParticleSystem(model, passes_for(model))
    integrate(get_solver("lecture")(system), 1.0, 0.005)
    x = system.positions
    # Penetrations are projected back after every step: every ball inside, radius included.
    assert np.all(x >= 0.02 - 1e-12) and np.all(x <= 0.98 + 1e-12)


@pytest.mark.parametrize("name", ["bouncing-ball", "sliding-contact"])
def test_contact_case_gates_hold_for_the_lecture_update(case_named, name):
    case = case_named(name)
    for gate in case.gates:
        if gate.kind != "property" or gate.method != "lecture":
            continue
        traj = ReferenceAdapter().simulate(case, "lecture", gate.dt)
        value = PROPERTIES[gate.params["name"]](case, traj)
        assert value <= gate.params.get("max", np.inf), (gate.where, value)
        assert value >= gate.params.get("min", -np.inf), (gate.where, value)


# --------------------------------------------------------------------------------------
# The numpy collision pass against closed forms (mutation testing, tools/campaigns/mutation/README.md).
#
# One pass at a time on a hand-made state: a bounce gives ``V_N' = -e V_N`` exactly with
# ``V_T`` kept; a penetrating particle is lifted onto the plane with the normal speed it
# had there, ``V_N^2 - 2 a_N d``; resting contact zeroes the normal speed and the contact
# force cancels the normal component of the applied force; Coulomb friction is
# ``mu |F_N|`` against sliding and holds up to it.


def scene(
    x,
    v,
    *,
    g=0.0,
    r=0.0,
    e=1.0,
    mu=0.0,
    thickness=0.0,
    fixed=None,
    mass=None,
    normal=UP,
    point=(0.0, 0.0, 0.0),
):
    x, v = np.atleast_2d(np.asarray(x, float)), np.atleast_2d(np.asarray(v, float))
    n = len(x)
    model = ParticleModel(
        mass=np.ones(n) if mass is None else np.asarray(mass, float),
        x0=x,
        v0=v,
        radius=np.full(n, r),
        fixed=np.zeros(n, bool) if fixed is None else np.asarray(fixed),
        gravity=g * np.asarray(normal, float),
        planes=[Plane(np.asarray(point, float), np.asarray(normal, float), e, mu, thickness)],
    )
    system = ParticleSystem(model)
    return system, PlaneCollisions(model.planes, model.radius, model.fixed, model.mass)


def test_box_planes_are_six_inward_walls():
    lo, hi = np.array([-1.0, 0.0, 2.0]), np.array([1.0, 3.0, 5.0])
    planes = box_planes(lo, hi, restitution=0.4, friction=0.2)
    assert len(planes) == 6
    for axis in range(3):
        a, b = planes[2 * axis], planes[2 * axis + 1]
        np.testing.assert_array_equal(a.normal, np.eye(3)[axis])
        np.testing.assert_array_equal(b.normal, -np.eye(3)[axis])
        np.testing.assert_array_equal(a.point, lo)
        np.testing.assert_array_equal(b.point, hi)
        assert (a.restitution, a.friction, b.restitution, b.friction) == (0.4, 0.2, 0.4, 0.2)
    inside = np.array([[0.0, 1.0, 3.0]])
    assert all(signed_distances(inside, np.zeros(1), p)[0] > 0 for p in planes)
    assert box_planes(lo, hi)[0].restitution == 1.0 and box_planes(lo, hi)[0].friction == 0.0


def test_signed_distance_is_the_contact_points_height():
    p = Plane(np.array([0.0, 2.0, 0.0]), np.array([0.0, 0.6, 0.8]))
    x = np.array([[1.0, 3.0, 1.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(
        signed_distances(x, np.array([0.1, 0.5]), p), [0.6 + 0.8 - 0.1, -1.2 - 0.5], rtol=1e-15
    )


@pytest.mark.parametrize("e", [1.0, 0.7, 0.0])
def test_a_single_bounce_reverses_the_normal_speed_times_e(e):
    system, cr = scene([0.3, 0.05, -0.2], [1.5, -2.0, 0.5], r=0.05, e=e)
    cr(system, 0.01)
    np.testing.assert_array_equal(system.velocities[0], [1.5, 2.0 * e, 0.5])
    np.testing.assert_array_equal(system.positions[0], [0.3, 0.05, -0.2])  # on it: not moved
    assert cr.collisions == 1 and not system.contact.any()
    cr(system, 0.01)  # heading out now: nothing more
    assert cr.collisions == 1
    # the same on a slanted plane: V' = V_T - e V_N
    n = np.array([0.6, 0.8, 0.0])
    v = np.array([-1.0, -0.5, 2.0])
    system, cr = scene(np.zeros(3), v, e=e, normal=n)
    cr(system, 0.01)
    vn = v @ n
    np.testing.assert_allclose(system.velocities[0], v - vn * n - e * vn * n, rtol=1e-14, atol=1e-15)


def test_a_particle_above_the_tolerance_or_leaving_is_left_alone():
    system, cr = scene([[0.0, 3 * EPS_DISTANCE, 0.0], [1.0, 0.0, 0.0]], [[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    cr(system, 0.01)
    np.testing.assert_array_equal(system.velocities, [[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    assert cr.collisions == 0
    fixed, cr = scene([0.0, -0.1, 0.0], [0.0, -1.0, 0.0], fixed=[True])
    cr(fixed, 0.01)
    np.testing.assert_array_equal(fixed.positions[0], [0.0, -0.1, 0.0])
    np.testing.assert_array_equal(fixed.velocities[0], [0.0, -1.0, 0.0])


@pytest.mark.parametrize("e", [1.0, 0.6])
def test_a_penetrating_particle_is_lifted_with_the_speed_it_had_at_the_plane(e):
    g, d, v = 9.81, -0.02, -3.0  # found 2 cm below the plane, falling at 3 m/s
    system, cr = scene([0.0, 0.1 + d, 0.0], [0.4, v, 0.0], g=-g, r=0.1, e=e, mass=[2.0])
    cr(system, 0.01)
    vn_at_plane = -math.sqrt(v * v - 2 * (-g) * d)  # V_N^2 - 2 a_N d, a_N = -g
    assert system.positions[0, 1] == pytest.approx(0.1, abs=1e-15)
    assert system.velocities[0, 1] == pytest.approx(-e * vn_at_plane, rel=1e-14)
    assert system.velocities[0, 0] == 0.4
    # moving up while below (after a bounce the step did not finish): lifted, not reversed
    system, cr = scene([0.0, -0.01, 0.0], [0.0, 2.0, 0.0], g=-g, mass=[2.0])
    cr(system, 0.01)
    assert system.positions[0, 1] == pytest.approx(0.0, abs=1e-15)
    assert system.velocities[0, 1] == pytest.approx(math.sqrt(4.0 - 2 * g * 0.01), rel=1e-14)
    assert cr.collisions == 0
    # too slow to have come from above: the normal speed is zero, not imaginary
    system, cr = scene([0.0, -0.5, 0.0], [0.0, -0.1, 0.0], g=-g)
    cr(system, 0.01)
    assert system.velocities[0, 1] == 0.0 and system.positions[0, 1] == pytest.approx(0.0, abs=1e-15)


def test_a_thick_wall_is_crossed_by_a_particle_found_behind_it():
    w, r = 0.1, 0.05
    deep, cr = scene([0.0, -(w + 2 * r) - 0.01, 0.0], [0.0, -5.0, 0.0], r=r, thickness=w)
    cr(deep, 0.01)
    np.testing.assert_array_equal(deep.velocities[0], [0.0, -5.0, 0.0])  # tunnelled
    inside, cr = scene([0.0, -(w + 2 * r) + 0.01 + r, 0.0], [0.0, -5.0, 0.0], r=r, thickness=w)
    cr(inside, 0.01)
    assert inside.velocities[0, 1] > 0 and inside.positions[0, 1] == pytest.approx(r, abs=1e-15)


def test_resting_contact_and_the_contact_force():
    g, dt = -9.81, 0.01
    system, cr = scene([0.0, 0.0, 0.0], [1.0, 0.5 * EPS_SPEED, 0.0], g=g)
    cr(system, dt)
    assert system.contact[0, 0]
    assert system.velocities[0, 1] == 0.0 and system.velocities[0, 0] == 1.0
    a = system.acceleration(system.get_state()[:3], system.get_state()[3:], 0.0)
    np.testing.assert_allclose(a, [0.0, 0.0, 0.0], atol=1e-15)  # the wall cancels gravity
    # the speed tolerance grows by |a_N| dt: a small bounce ends in contact ...
    system, cr = scene([0.0, 0.0, 0.0], [0.0, -0.5 * 9.81 * dt, 0.0], g=g, e=0.9)
    cr(system, dt)
    assert system.contact[0, 0] and system.velocities[0, 1] == 0.0
    # ... a larger one bounces
    system, cr = scene([0.0, 0.0, 0.0], [0.0, -3 * 9.81 * dt, 0.0], g=g, e=0.9)
    cr(system, dt)
    assert not system.contact[0, 0]
    assert system.velocities[0, 1] == pytest.approx(0.9 * 3 * 9.81 * dt, rel=1e-14)
    # not pushing (no gravity): no contact, however slow
    system, cr = scene([0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    cr(system, dt)
    assert not system.contact.any()
    # start() runs the pass on the initial state
    system, cr = scene([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], g=g)
    cr.start(system)
    assert system.contact[0, 0]
    assert cr.eps_distance == EPS_DISTANCE and cr.eps_speed == EPS_SPEED


def test_friction_stops_a_slow_slider_and_lets_a_fast_one_slide():
    g, dt, mu = -9.81, 0.01, 0.5
    slow = mu * 9.81 * dt * 0.9  # friction takes it within the step
    system, cr = scene([0.0, 0.0, 0.0], [slow, 0.0, 0.0], g=g, mu=mu)
    cr(system, dt)
    assert system.contact[0, 0]
    np.testing.assert_array_equal(system.velocities[0], 0.0)
    fast = mu * 9.81 * dt * 1.1
    system, cr = scene([0.0, 0.0, 0.0], [fast, 0.0, 0.0], g=g, mu=mu)
    cr(system, dt)
    assert system.contact[0, 0] and system.velocities[0, 0] == fast
    # a sliding particle decelerates at mu g
    a = system.acceleration(system.get_state()[:3], system.get_state()[3:], 0.0)
    np.testing.assert_allclose(a, [-mu * 9.81, 0.0, 0.0], rtol=1e-14, atol=1e-15)
    # a tilted push that static friction cannot hold is not stopped
    system, cr = scene([0.0, 0.0, 0.0], [slow, 0.0, 0.0], g=g, mu=mu)
    system.model.fields.append(_push(np.array([0.6 * 9.81, 0.0, 0.0])))
    cr(system, dt)
    assert system.velocities[0, 0] == slow


def _push(force):
    from truestep.reference_impl.model import ForceField

    # a constant force as a wind on a particle at rest with k = 1: f = w - v
    return ForceField(
        "wind",
        {"direction": list(force / np.linalg.norm(force)), "speed": float(np.linalg.norm(force)), "k": 1.0},
    )


def test_add_contact_forces_cancels_the_push_and_adds_coulomb_friction():
    n = UP
    f = np.array(
        [[3.0, -10.0, 4.0], [3.0, -10.0, 0.0], [1.0, -10.0, 0.0], [2.0, 5.0, 0.0], [8.0, -10.0, 0.0]]
    )
    v = np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    contact = np.array([[True, True, True, True, False]])
    out = f.copy()
    add_contact_forces(out, v, contact, [Plane(np.zeros(3), n, 1.0, 0.4)])
    limit = 0.4 * 10.0
    np.testing.assert_allclose(out[0], [3.0, 0.0, 4.0 - limit], rtol=1e-14)  # kinetic, along -v_T
    np.testing.assert_allclose(out[1], [3.0 - limit, 0.0, 0.0], rtol=1e-14)
    np.testing.assert_allclose(out[2], [0.0, 0.0, 0.0], atol=1e-15)  # held: |F_T| = 1 <= 4
    np.testing.assert_allclose(out[3], [2.0, 5.0, 0.0])  # pulling away: no normal force, mu 0
    np.testing.assert_array_equal(out[4], f[4])  # not in contact
    # at rest under a push static friction cannot hold: F_T - mu |F_N| F_T / |F_T|
    g = np.array([[0.0, -10.0, 6.0]])
    add_contact_forces(g, np.zeros((1, 3)), np.array([[True]]), [Plane(np.zeros(3), n, 1.0, 0.4)])
    np.testing.assert_allclose(g, [[0.0, 0.0, 6.0 - limit]], rtol=1e-14)
    # frictionless: only the normal component goes
    h = f.copy()
    add_contact_forces(h, v, contact, [Plane(np.zeros(3), n)])
    np.testing.assert_allclose(h[:3, 1], 0.0)
    np.testing.assert_array_equal(h[:3, [0, 2]], f[:3, [0, 2]])
    np.testing.assert_array_equal(h[3:], f[3:])
    untouched = f.copy()
    add_contact_forces(untouched, v, np.zeros((1, 5), bool), [Plane(np.zeros(3), n, 1.0, 0.4)])
    np.testing.assert_array_equal(untouched, f)


def test_contact_projection_is_i_minus_nn_for_pushers_only():
    n1, n2 = np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])
    planes = [Plane(np.zeros(3), n1), Plane(np.zeros(3), n2)]
    f = np.array([[1.0, -2.0, 0.0], [1.0, 2.0, 0.0], [-1.0, -1.0, 0.0]])
    contact = np.array([[True, True, True], [False, False, True]])
    p = contact_projection(f, contact, planes)
    p1, p2 = np.eye(3) - np.outer(n1, n1), np.eye(3) - np.outer(n2, n2)
    np.testing.assert_array_equal(p[0], p1)
    np.testing.assert_array_equal(p[1], np.eye(3))  # pulling away
    np.testing.assert_array_equal(p[2], p2 @ p1)
