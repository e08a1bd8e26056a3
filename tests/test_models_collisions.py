"""Point-plane collisions, resting contact and friction; the case files that use them."""

from __future__ import annotations

import numpy as np
import pytest

from truestep.adapters.reference import ReferenceAdapter
from truestep.cases.exact_particles import bounce_schedule
from truestep.measures.properties import PROPERTIES
from truestep.reference_impl.collisions import box_planes
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
        kind="particles",
        duration=duration,
        dts=[0.01],
        quick_dts=[0.01],
        tolerances=[1e-6],
        quick_tolerances=[1e-6],
        model=model,
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
