"""Particles and force objects: the lecture's update, drag, springs, gravitation, Jacobian."""

from __future__ import annotations

import numpy as np
import pytest

from truestep.cases.case import Case
from truestep.cases.exact import EXACT
from truestep.reference_impl import forces
from truestep.reference_impl.integrate import integrate
from truestep.reference_impl.model import Anchors, Gravitation, ParticleModel, Springs
from truestep.reference_impl.particles import ParticleSystem
from truestep.reference_impl.solvers import RK4, LectureUpdate, get_solver

G = np.array([0.0, -9.81, 0.0])


def free_model(n: int = 3, drag: float = 0.0, seed: int = 0) -> ParticleModel:
    rng = np.random.default_rng(seed)
    return ParticleModel(
        mass=rng.uniform(0.5, 2.0, n),
        x0=rng.normal(0, 1, (n, 3)),
        v0=rng.normal(0, 3, (n, 3)),
        radius=np.zeros(n),
        fixed=np.zeros(n, bool),
        gravity=G,
        drag=drag,
    )


def case_of(model: ParticleModel, exact: str, duration: float) -> Case:
    return Case(
        name="t",
        file="t",
        title="t",
        description="",
        kind="particles",
        duration=duration,
        dts=[0.1],
        quick_dts=[0.1],
        tolerances=[1e-6],
        quick_tolerances=[1e-6],
        model=model,
        exact=exact,
    )


def run(model: ParticleModel, method: str, t_end: float, dt: float) -> np.ndarray:
    system = ParticleSystem(model)
    integrate(get_solver(method)(system), t_end, dt)
    return system.get_state()


@pytest.mark.parametrize("dt", [0.1, 0.03, 0.007])
def test_lecture_update_is_exact_under_constant_gravity(dt):
    model = free_model()
    state = run(model, "lecture", 1.0, dt)
    steps = round(1.0 / dt)
    exact = EXACT["uniform-gravity"](case_of(model, "uniform-gravity", 1.0), np.array([steps * dt]))
    # p' = p + v dt + g dt^2 / 2 is the exact solution: only round-off (positions ~10 m,
    # at most 143 steps) separates them.
    assert np.max(np.abs(state[:9].reshape(3, 3) - exact.x[0])) < 1e-12
    assert np.max(np.abs(state[9:].reshape(3, 3) - exact.v[0])) < 1e-12


def test_drag_solution_rk4_converges_to_the_exponential():
    model = free_model(drag=0.7)
    exact = EXACT["linear-drag"](case_of(model, "linear-drag", 2.0), np.array([2.0]))
    errors = [np.max(np.abs(run(model, "rk4", 2.0, dt)[:9].reshape(3, 3) - exact.x[0])) for dt in (0.1, 0.05)]
    # RK4 on a linear ODE with |lambda dt| <= 0.14: error ~ (lambda dt)^5 per unit time,
    # well below 1e-5 m; halving dt divides it by 2^4 = 16 (accept 13..19).
    assert errors[0] < 1e-5
    assert 13 < errors[0] / errors[1] < 19


def test_drag_slows_to_terminal_velocity():
    model = free_model(n=1, drag=2.0)
    v = run(model, "lecture", 20.0, 0.01)[3:]
    terminal = model.mass[0] * G / model.drag
    # 20 s is 20 / (m/k) >= 20 time constants: e^-20 of the start is left (plus the
    # lecture update's O(dt) bias, which vanishes at the fixed point v = m g / k).
    assert np.allclose(v, terminal, atol=1e-6)


def test_spring_force_follows_the_lecture_formula():
    dx = np.array([[1.5, 0.0, 0.0]])  # x1 - x2: stretched by 0.5 beyond rest 1
    dv = np.array([[0.2, 0.0, 0.0]])  # separating at 0.2 m/s
    f1 = forces.spring_forces(dx, dv, np.array([10.0]), np.array([3.0]), np.array([1.0]))
    # f1 = -[k_s (|dx| - r) + k_d (dv . dx) / |dx|] dx / |dx| = -(5 + 0.6) x-hat
    assert np.allclose(f1, [[-5.6, 0.0, 0.0]], rtol=0, atol=1e-15)
    zero = forces.spring_forces(np.zeros((1, 3)), dv, np.array([10.0]), np.array([3.0]), np.array([1.0]))
    assert np.all(zero == 0.0)


def test_compiled_spring_loop_equals_the_vectorised_formula():
    """add_springs / add_anchors (one compiled pass) against spring_forces scattered with
    np.add.at, on random springs sharing particles, including a zero-length one."""
    rng = np.random.default_rng(3)
    n, m = 50, 200
    i, j = rng.integers(0, n, m), rng.integers(0, n, m)
    j = np.where(i == j, (j + 1) % n, j)
    x, v = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    x[j[0]] = x[i[0]]  # a zero-length spring: no force
    k, c, r = rng.uniform(1, 10, m), rng.uniform(0, 2, m), rng.uniform(0, 1, m)
    f1 = forces.spring_forces(x[i] - x[j], v[i] - v[j], k, c, r)
    expected = np.zeros((n, 3))
    np.add.at(expected, i, f1)
    np.subtract.at(expected, j, f1)
    got = np.zeros((n, 3))
    forces.add_springs(got, x, v, Springs(i, j, k, c, r))
    assert np.allclose(got, expected, rtol=0, atol=1e-12)

    point = rng.normal(size=(m, 3))
    fa = forces.spring_forces(x[i] - point, v[i], k, c, r)
    expected = np.zeros((n, 3))
    np.add.at(expected, i, fa)
    got = np.zeros((n, 3))
    forces.add_anchors(got, x, v, Anchors(i, point, k, c, r))
    assert np.allclose(got, expected, rtol=0, atol=1e-12)


def test_earth_gravity_is_about_9_8():
    # G m_e / r_e^2 with the lecture's G and the mean Earth radius.
    assert abs(forces.earth_gravity() - 9.8193) < 1e-3


def test_gravitation_conserves_momentum_and_matches_inverse_square():
    x = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 3.0, 1.0]])
    mass = np.array([5.0, 1.0, 2.0])
    f = np.zeros((3, 3))
    forces.add_gravitation(f, x, mass, Gravitation(G=1.0))
    assert np.allclose(f.sum(axis=0), 0.0, atol=1e-15)  # Newton's third law, pairwise
    f01 = 1.0 * 5.0 * 1.0 / 2.0**2  # G m_0 m_1 / r^2 along +x on particle 0
    f02 = 1.0 * 5.0 * 2.0 / 10.0 * np.array([0.0, 3.0, 1.0]) / np.sqrt(10.0)
    assert np.allclose(f[0], np.array([f01, 0, 0]) + f02, rtol=1e-14)


def test_analytic_jacobian_matches_finite_differences():
    rng = np.random.default_rng(5)
    n = 4
    model = ParticleModel(
        mass=rng.uniform(0.5, 2, n),
        x0=rng.normal(0, 1, (n, 3)),
        v0=rng.normal(0, 1, (n, 3)),
        radius=np.zeros(n),
        fixed=np.array([False, False, True, False]),
        gravity=G,
        drag=0.3,
        springs=Springs(
            np.array([0, 1, 2]),
            np.array([1, 2, 3]),
            np.array([50.0, 80.0, 20.0]),
            np.array([0.5, 0.0, 1.0]),
            np.array([0.7, 1.0, 1.3]),
        ),
        anchors=Anchors(np.array([0]), np.zeros((1, 3)), np.array([30.0]), np.array([0.2]), np.array([0.5])),
        gravitation=Gravitation(G=2.0, softening=0.1),
    )
    system = ParticleSystem(model)
    x = system.get_state()
    jac = np.asarray(system.jacobian(x, 0.0))
    h = 1e-6
    fd = np.array(
        [
            (system.derivative(x + h * e, 0.0) - system.derivative(x - h * e, 0.0)) / (2 * h)
            for e in np.eye(len(x))
        ]
    ).T
    # Central differences: error ~ h^2 * third derivatives (~1e3 here) plus round-off
    # ~ 1e-16 * |f| / h ~ 1e-8.
    assert np.max(np.abs(jac - fd)) < 1e-6 * np.max(np.abs(fd))


def test_a_pinned_particle_feels_no_force():
    model = free_model(n=2)
    model.fixed[1] = True
    model.v0[1] = 0.0
    state = run(model, "rk4", 1.0, 0.01)
    assert np.array_equal(state[3:6], model.x0[1])  # at rest it stays put, gravity or not
    model.v0[1] = [0.1, 0.0, 0.0]  # given a velocity it moves as a kinematic point
    state = run(model, "rk4", 1.0, 0.01)
    assert np.allclose(state[3:6], model.x0[1] + [0.1, 0.0, 0.0], rtol=0, atol=1e-15)


def test_impulse_on_the_triangle_gives_f_dt_with_the_lecture_update():
    from truestep.reference_impl import meshes

    mesh = meshes.triangle(1.0)
    mass, springs = meshes.mass_spring(mesh, 3.0, 100.0, 0.5)
    model = ParticleModel(
        mass=mass,
        x0=mesh.vertices,
        v0=np.zeros((3, 3)),
        radius=np.zeros(3),
        fixed=np.zeros(3, bool),
        springs=springs,
        impulses=[(1, np.array([20.0, 0.0, 0.0]), 0.0, 0.0099)],
    )
    system = ParticleSystem(model)
    solver = LectureUpdate(system)
    solver.step(0.01)
    v = system.velocities
    # One step of the lecture's example: v_2' = a_2 dt = (20 / 1) 0.01, the others at rest.
    assert np.allclose(v[1], [0.2, 0.0, 0.0], rtol=0, atol=1e-15)
    assert np.all(v[[0, 2]] == 0.0)
    assert np.allclose(
        system.positions[1] - mesh.vertices[1], [0.5 * 20.0 * 0.01**2, 0, 0], rtol=0, atol=1e-16
    )
    rk = RK4(ParticleSystem(model))
    for _ in range(100):
        rk.step(0.01)
    p = (model.mass[:, None] * rk.system.velocities).sum(axis=0)
    # After the impulse only springs act: momentum stays what the impulse gave
    # (RK4 skips the stage at t = 0.01 >= end, so it delivers 5/6 of F dt).
    assert np.allclose(p, [20.0 * 0.01 * 5 / 6, 0, 0], rtol=1e-13, atol=1e-15)
