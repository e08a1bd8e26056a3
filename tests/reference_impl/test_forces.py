"""Particles and force objects: the lecture's update, drag, springs, gravitation, Jacobian."""

from __future__ import annotations

import math

import numpy as np
import pytest

from truestep.cases.case import Case
from truestep.cases.exact import EXACT
from truestep.reference_impl import forces
from truestep.reference_impl.integrate import integrate
from truestep.reference_impl.model import Anchors, ForceField, Gravitation, ParticleModel, Springs
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
        duration=duration,
        dts=[0.1],
        quick_dts=[0.1],
        tolerances=[1e-6],
        quick_tolerances=[1e-6],
        scene=model,
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


# --------------------------------------------------------------------------------------
# The numpy force objects against closed forms (mutation testing, tools/campaigns/mutation/README.md).
#
# Springs: ``f_1 = -k (|d| - L) d^ - c (v . d^) d^`` at chosen points, ``f_2 = -f_1``;
# their Jacobians against central differences of the forces; energies ``k (|d| - L)^2 / 2``
# and ``-G m_1 m_2 / sqrt(r^2 + eps^2)``, whose negative gradients are the forces; fields
# and impulses by their formulas.
RNG = np.random.default_rng(7)


def closed_spring(d, v, k, c, rest):
    """-k (|d| - L) d^ - c (v . d^) d^ for one spring (d = x_1 - x_2, v = v_1 - v_2)."""
    length = np.linalg.norm(d)
    u = d / length
    return -k * (length - rest) * u - c * (v @ u) * u


def test_earth_gravity_is_g_m_over_r_squared():
    assert forces.earth_gravity() == pytest.approx(6.67384e-11 * 5.972e24 / 6.371e6**2, rel=1e-15)
    assert forces.earth_gravity(1.0) == pytest.approx(5.972e24 / 6.371e6**2, rel=1e-15)
    assert 9.81 < forces.earth_gravity() < 9.83


def test_gravity_and_drag_add_into_the_accumulator():
    f = np.ones((2, 3))
    forces.add_gravity(f, np.array([2.0, 3.0]), np.array([0.0, -9.8, 1.0]))
    np.testing.assert_allclose(f, [[1, 1 - 19.6, 3], [1, 1 - 29.4, 4]])
    v = np.array([[1.0, -2.0, 0.5], [0.0, 3.0, -1.0]])
    forces.add_drag(f, v, 0.5)
    np.testing.assert_allclose(f, [[0.5, 1 - 19.6 + 1.0, 2.75], [1, 1 - 29.4 - 1.5, 4.5]])


def test_spring_forces_are_the_closed_form_at_chosen_points():
    d = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, -2.0], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0]])
    v = np.array([[1.0, -1.0, 2.0], [0.5, 0.0, 1.0], [-1.0, 2.0, 0.0], [1.0, 1.0, 1.0]])
    k, c, rest = (
        np.array([10.0, 5.0, 2.0, 9.0]),
        np.array([0.3, 1.5, 0.0, 1.0]),
        np.array([4.0, 3.0, 1.0, 1.0]),
    )
    f = forces.spring_forces(d, v, k, c, rest)
    for s in range(3):
        np.testing.assert_allclose(f[s], closed_spring(d[s], v[s], k[s], c[s], rest[s]), rtol=1e-14)
    np.testing.assert_array_equal(f[3], 0.0)  # zero length: no force
    # by hand: |d| = 5, u = (0.6, 0.8, 0), v.u = -0.2: -(10 * 1 + 0.3 * -0.2) u
    np.testing.assert_allclose(f[0], -(10.0 - 0.06) * np.array([0.6, 0.8, 0.0]), rtol=1e-14)


def test_the_compiled_spring_loop_adds_equal_and_opposite_forces():
    x = RNG.normal(size=(4, 3))
    v = RNG.normal(size=(4, 3))
    s = Springs(
        np.array([0, 1, 3]),
        np.array([1, 2, 0]),
        np.array([10.0, 4.0, 7.0]),
        np.array([0.5, 0.0, 1.2]),
        np.array([0.3, 2.0, 1.0]),
    )
    f = np.full((4, 3), 0.25)
    forces.add_springs(f, x, v, s)
    expected = np.full((4, 3), 0.25)
    for a, b, k, c, r in zip(s.i, s.j, s.stiffness, s.damping, s.rest, strict=True):
        fs = closed_spring(x[a] - x[b], v[a] - v[b], k, c, r)
        expected[a] += fs
        expected[b] -= fs
    np.testing.assert_allclose(f, expected, rtol=1e-13, atol=1e-14)
    # coincident ends exert nothing; a spring on itself neither
    f = np.zeros((4, 3))
    same = x.copy()
    same[1] = same[0]
    forces.add_springs(f, same, v, Springs(np.array([0]), np.array([1]), np.ones(1), np.ones(1), np.ones(1)))
    np.testing.assert_array_equal(f, 0.0)
    f = np.zeros((4, 3))
    forces.add_springs(f, x, v, Springs.empty())
    np.testing.assert_array_equal(f, 0.0)


def test_anchored_springs_pull_toward_their_fixed_points():
    x = RNG.normal(size=(3, 3))
    v = RNG.normal(size=(3, 3))
    a = Anchors(
        np.array([2, 0]),
        np.array([[1.0, 2.0, 3.0], [-1.0, 0.0, 0.5]]),
        np.array([6.0, 2.0]),
        np.array([0.7, 0.2]),
        np.array([0.5, 0.1]),
    )
    f = np.zeros((3, 3))
    forces.add_anchors(f, x, v, a)
    expected = np.zeros((3, 3))
    for i, p, k, c, r in zip(a.i, a.point, a.stiffness, a.damping, a.rest, strict=True):
        expected[i] += closed_spring(x[i] - p, v[i], k, c, r)
    np.testing.assert_allclose(f, expected, rtol=1e-13, atol=1e-14)
    f = np.zeros((3, 3))
    on_point = x.copy()
    on_point[2] = a.point[0]
    on_point[0] = a.point[1]
    forces.add_anchors(f, on_point, v, a)
    np.testing.assert_array_equal(f, 0.0)
    forces.compile_springs()  # loads the compiled loop for both forms; changes nothing here


def central_jacobian(fun, z, eps=1e-6):
    cols = []
    for k in range(z.size):
        dz = np.zeros_like(z)
        dz.flat[k] = eps
        cols.append((fun(z + dz) - fun(z - dz)) / (2 * eps))
    return np.stack(cols, axis=-1)


def test_spring_jacobians_are_the_derivatives_of_the_forces():
    d = np.array([[0.9, -0.4, 0.3], [0.0, 2.0, 0.0], [0.0, 0.0, 0.0]])
    v = np.array([[0.5, 1.0, -0.7], [1.0, 0.3, -2.0], [1.0, 1.0, 1.0]])
    k, c, rest = np.array([8.0, 3.0, 1.0]), np.array([1.3, 0.6, 2.0]), np.array([0.5, 1.0, 1.0])
    jx, jv = forces.spring_jacobians(d, v, k, c, rest)
    for s in range(2):

        def fx(z, s=s):
            return forces.spring_forces(z[None], v[s : s + 1], k[s : s + 1], c[s : s + 1], rest[s : s + 1])[0]

        def fv(z, s=s):
            return forces.spring_forces(d[s : s + 1], z[None], k[s : s + 1], c[s : s + 1], rest[s : s + 1])[0]

        np.testing.assert_allclose(jx[s], central_jacobian(fx, d[s]), rtol=1e-7, atol=1e-8)
        np.testing.assert_allclose(jv[s], central_jacobian(fv, v[s]), rtol=1e-7, atol=1e-8)
    np.testing.assert_array_equal(jx[2], 0.0)
    np.testing.assert_array_equal(jv[2], 0.0)


def test_spring_and_anchor_energies_are_half_k_stretch_squared():
    x = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [0.0, 0.0, 2.0]])
    s = Springs(np.array([0, 1]), np.array([1, 2]), np.array([2.0, 4.0]), np.zeros(2), np.array([4.0, 1.0]))
    d12 = math.sqrt(9 + 16 + 4)
    e = 0.5 * 2.0 * (5 - 4) ** 2 + 0.5 * 4.0 * (d12 - 1) ** 2
    assert forces.spring_energy(x, s) == pytest.approx(e, rel=1e-14)
    np.testing.assert_allclose(
        forces.spring_energy(np.stack([x, 2 * x]), s),
        [e, 0.5 * 2.0 * 6**2 + 0.5 * 4.0 * (2 * d12 - 1) ** 2],
        rtol=1e-14,
    )
    a = Anchors(np.array([1]), np.array([[0.0, 1.0, 0.0]]), np.array([3.0]), np.zeros(1), np.array([2.0]))
    ea = 0.5 * 3.0 * (math.sqrt(9 + 9) - 2.0) ** 2
    assert forces.anchor_energy(x, a) == pytest.approx(ea, rel=1e-14)
    x2 = x.copy()
    x2[1] = [0.0, 1.0, 0.0]  # on its anchor point: stretch -2
    np.testing.assert_allclose(
        forces.anchor_energy(np.stack([x, x2, x]), a), [ea, 0.5 * 3.0 * 4.0, ea], rtol=1e-14
    )
    assert forces.spring_energy(x, Springs.empty()) == 0.0
    assert forces.anchor_energy(x, Anchors.empty()) == 0.0
    # the energy's negative gradient is the (undamped) spring force
    grad = central_jacobian(lambda z: np.array([forces.spring_energy(z.reshape(3, 3), s)]), x.ravel())
    f = np.zeros((3, 3))
    forces.add_springs(f, x, np.zeros((3, 3)), s)
    np.testing.assert_allclose(-grad.reshape(3, 3), f, rtol=1e-7, atol=1e-7)


def test_gravitation_is_newtons_law_softened():
    g = Gravitation(G=2.0, softening=0.5)
    x = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [1.0, -2.0, 2.0]])
    m = np.array([1.5, 2.0, 0.7])
    f = np.full((3, 3), 0.1)
    forces.add_gravitation(f, x, m, g)
    expected = np.full((3, 3), 0.1)
    for i in range(3):
        for j in range(3):
            if i != j:
                d = x[j] - x[i]
                expected[i] += g.G * m[i] * m[j] * d / (d @ d + g.softening**2) ** 1.5
    np.testing.assert_allclose(f, expected, rtol=1e-13)
    # two bodies, no softening: G m1 m2 / r^2 toward each other
    f2 = np.zeros((2, 3))
    forces.add_gravitation(f2, x[:2], m[:2], Gravitation(G=2.0))
    np.testing.assert_allclose(f2[0], 2.0 * 1.5 * 2.0 / 25.0 * np.array([0.6, 0.8, 0.0]), rtol=1e-14)
    np.testing.assert_allclose(f2[1], -f2[0], rtol=1e-14)
    # energy: -sum G m_i m_j / sqrt(r^2 + eps^2); its negative gradient is the force
    e = sum(
        -g.G * m[i] * m[j] / math.sqrt((x[i] - x[j]) @ (x[i] - x[j]) + 0.25)
        for i in range(3)
        for j in range(i + 1, 3)
    )
    assert forces.gravitation_energy(x, m, g) == pytest.approx(e, rel=1e-14)
    np.testing.assert_allclose(forces.gravitation_energy(np.stack([x, x]), m, g), [e, e], rtol=1e-14)
    grad = central_jacobian(lambda z: np.array([forces.gravitation_energy(z.reshape(3, 3), m, g)]), x.ravel())
    np.testing.assert_allclose(-grad.reshape(3, 3), expected - 0.1, rtol=1e-7, atol=1e-9)
    # its Jacobian blocks are the derivatives of the forces
    jac = forces.gravitation_jacobian(x, m, g)

    def fx(z):
        out = np.zeros((3, 3))
        forces.add_gravitation(out, z.reshape(3, 3), m, g)
        return out.ravel()

    num = central_jacobian(fx, x.ravel()).reshape(3, 3, 3, 3).transpose(0, 2, 1, 3)
    np.testing.assert_allclose(jac, num, rtol=1e-6, atol=1e-8)


@pytest.mark.filterwarnings("ignore:overflow encountered in square:RuntimeWarning")  # on the axis
def test_the_vortex_field_swirls_about_its_axis():
    fld = ForceField(
        "vortex", {"center": [1.0, 0.0, 0.0], "axis": [0.0, 0.0, 2.0], "strength": 3.0, "core": 0.5}
    )
    x = np.array([[1.3, 0.0, 5.0], [1.0, 2.0, -1.0], [1.0, 0.0, 0.0]])
    m = np.array([2.0, 0.5, 1.0])
    f = forces.field_force(fld, x, np.zeros((3, 3)), m, 0.0)
    # inside the core: strength m (axis x r_perp) = 3 * 2 * (0, 0.3, 0)
    np.testing.assert_allclose(f[0], [0.0, 1.8, 0.0], atol=1e-15)
    # outside: times (core / |r_perp|)^2; axis x (0, 2, 0) = (-2, 0, 0)
    np.testing.assert_allclose(f[1], 3.0 * 0.5 * (0.5 / 2.0) ** 2 * np.array([-2.0, 0.0, 0.0]), rtol=1e-14)
    np.testing.assert_array_equal(f[2], 0.0)  # on the axis
    # defaults: centre at the origin, axis y, core 0.5
    d = forces.field_force(
        ForceField("vortex", {"strength": 1.0}),
        np.array([[0.2, 7.0, 0.0], [2.0, 0.0, 0.0]]),
        np.zeros((2, 3)),
        np.ones(2),
        0.0,
    )
    np.testing.assert_allclose(d, [[0.0, 0.0, -0.2], [0.0, 0.0, -2.0 * 0.25 / 4.0]], atol=1e-15)
    # an axis but no centre: the axis runs through the origin
    e = forces.field_force(
        ForceField("vortex", {"strength": 1.0, "axis": [1.0, 0.0, 0.0]}),
        np.array([[5.0, 0.3, 0.0]]),
        np.zeros((1, 3)),
        np.ones(1),
        0.0,
    )
    np.testing.assert_allclose(e, [[0.0, 0.0, 0.3]], atol=1e-15)


def test_the_wind_field_drags_toward_its_gusting_velocity():
    fld = ForceField(
        "wind", {"direction": [3.0, 0.0, 4.0], "speed": 2.0, "gust": 0.5, "freq": 0.75, "k": 1.5}
    )
    v = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 2.0]])
    t = 0.4
    w = (2.0 + 0.5 * math.sin(2 * math.pi * 0.75 * t)) * np.array([0.6, 0.0, 0.8])
    f = forces.field_force(fld, np.zeros((2, 3)), v, np.ones(2), t)
    np.testing.assert_allclose(f, 1.5 * (w - v), rtol=1e-14)
    # defaults: no speed, no gust, k = 1
    f = forces.field_force(
        ForceField("wind", {"direction": [0.0, 1.0, 0.0]}), np.zeros((2, 3)), v, np.ones(2), t
    )
    np.testing.assert_allclose(f, -v)
    # a gust without a frequency is a constant wind (sin 0 = 0)
    f = forces.field_force(
        ForceField("wind", {"direction": [0.0, 0.0, 1.0], "speed": 1.0, "gust": 3.0}),
        np.zeros((2, 3)),
        np.zeros((2, 3)),
        np.ones(2),
        0.7,
    )
    np.testing.assert_allclose(f, [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="unknown kind 'rain'"):
        forces.field_force(ForceField("rain", {}), np.zeros((1, 3)), np.zeros((1, 3)), np.ones(1), 0.0)
    acc = np.ones((2, 3))
    forces.add_fields(acc, [fld, fld], np.zeros((2, 3)), v, np.ones(2), t)
    np.testing.assert_allclose(acc, 1.0 + 3.0 * (w - v), rtol=1e-14)


def test_impulses_act_over_their_half_open_window():
    assert forces.impulse_active(1.0, 2.0, 1.0) and forces.impulse_active(1.0, 2.0, 1.999)
    assert not forces.impulse_active(1.0, 2.0, 2.0) and not forces.impulse_active(1.0, 2.0, 0.999)
    # the ends with round-off: a time one ulp below 0.01 counts as 0.01
    t = float(np.nextafter(0.01, 0.0))
    assert t < 0.01 and forces.impulse_active(0.01, 0.02, t)
    assert not forces.impulse_active(0.0, 0.01, t)
    assert forces.impulse_active(100.0, 200.0, 100.0 - 5e-8)  # margin relative to |t|
    assert not forces.impulse_active(100.0, 200.0, 100.0 - 2e-7)
    assert not forces.impulse_active(0.0, 1.0, -2e-9)
    f = np.zeros((2, 3))
    imps = [
        (1, np.array([1.0, 2.0, 3.0]), 0.0, 1.0),
        (1, np.array([0.5, 0.0, 0.0]), 0.5, 1.0),
        (0, np.array([9.0, 9.0, 9.0]), 2.0, 3.0),
    ]
    assert forces.add_impulses(f, imps, 0.7) is f
    np.testing.assert_allclose(f, [[0, 0, 0], [1.5, 2.0, 3.0]])


def test_the_force_loop_clears_then_adds_every_force_object():
    x = np.array([[0.0, 1.0, 0.0], [2.0, 1.0, 0.0]])
    v = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    m = np.array([2.0, 3.0])
    model = ParticleModel(
        mass=m,
        x0=x,
        v0=v,
        radius=np.zeros(2),
        fixed=np.zeros(2, bool),
        gravity=np.array([0.0, -10.0, 0.0]),
        drag=0.5,
        springs=Springs(np.array([0]), np.array([1]), np.array([4.0]), np.array([0.0]), np.array([1.0])),
        anchors=Anchors(
            np.array([1]), np.array([[2.0, 3.0, 0.0]]), np.array([1.0]), np.zeros(1), np.zeros(1)
        ),
        gravitation=Gravitation(G=1.0),
        fields=[ForceField("wind", {"direction": [1.0, 0.0, 0.0], "speed": 1.0, "k": 2.0})],
        impulses=[(0, np.array([0.0, 0.0, 7.0]), 0.0, 1.0)],
    )
    f = np.full((2, 3), 123.0)
    out = forces.add_model_forces(f, model, x, v, 0.5)
    assert out is f
    spring = -4.0 * (2.0 - 1.0) * np.array([-1.0, 0.0, 0.0])  # on particle 0, pulled toward 1
    grav = 1.0 * 2.0 * 3.0 / 4.0 * np.array([1.0, 0.0, 0.0])
    expected = np.array(
        [
            m[0] * np.array([0, -10, 0])
            - 0.5 * v[0]
            + spring
            + grav
            + 2.0 * (np.array([1, 0, 0]) - v[0])
            + np.array([0, 0, 7.0]),
            m[1] * np.array([0, -10, 0])
            - 0.5 * v[1]
            - spring
            - grav
            + np.array([0.0, 2.0, 0.0])
            + 2.0 * (np.array([1, 0, 0]) - v[1]),
        ]
    )
    np.testing.assert_allclose(f, expected, rtol=1e-13)
    g0 = forces.add_model_forces(np.zeros((2, 3)), model, x, v, 1.5, gravity=False)
    np.testing.assert_allclose(
        g0, expected - m[:, None] * np.array([0, -10, 0]) - [[0, 0, 7], [0, 0, 0]], rtol=1e-13, atol=1e-13
    )
