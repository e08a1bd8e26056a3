"""Each compiled kernel against its numpy twin, on data chosen to reach every branch.

The kernels of :mod:`truestep.reference_impl.forces_kernels` and
:mod:`truestep.reference_impl.collisions_kernels` are called from Python here (each
compiles on its own) and compared with the numpy functions they are the twins of: the
same bits where both sum in the same order, else to 1e-15 of the result's size (the
numpy vector products may sum in another order). The composed step built from them is
tested equal to the numpy path on every case in ``test_compiled.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from truestep.reference_impl import forces
from truestep.reference_impl import forces_kernels as fk
from truestep.reference_impl.collisions import PlaneCollisions, add_contact_forces
from truestep.reference_impl.collisions_kernels import (
    Plane,
    collide,
    contact_force,
    signed_distance,
    within,
)
from truestep.reference_impl.model import Anchors, Gravitation, ParticleModel, Springs
from truestep.reference_impl.model import Plane as ModelPlane
from truestep.reference_impl.particles import ParticleSystem, total_energy
from truestep.reference_impl.particles_kernels import Particles, kinetic_energy

ROUND_OFF = 1e-15


def particles(mass: np.ndarray, fixed: np.ndarray | None = None) -> Particles:
    fixed = np.zeros(len(mass), bool) if fixed is None else fixed
    return Particles(
        mass, np.where(fixed, 0.0, 1.0 / mass), np.zeros(len(mass)), ~fixed, np.where(fixed, 0.0, mass)
    )


def tup(a) -> tuple:
    return tuple(float(c) for c in a)


def test_gravity_and_drag_kernels_are_add_gravity_and_add_drag_bit_for_bit():
    RNG = np.random.default_rng(1)
    n = 7
    mass, f0, v = RNG.uniform(0.1, 3, n), RNG.normal(size=(n, 3)), RNG.normal(size=(n, 3))
    g = np.array([0.3, -9.81, 0.0])
    spec = f0.copy()
    forces.add_gravity(spec, mass, g)
    forces.add_drag(spec, v, 0.7)
    par = particles(mass)
    for p in range(n):
        f = fk.gravity_at(fk.Gravity(tup(g)), tup(f0[p]), None, None, 0.0, par, p)
        f = fk.drag_at(fk.Drag(0.7), f, None, tup(v[p]), 0.0, par, p)
        assert f == tup(spec[p])
    F = np.ascontiguousarray(f0.T)
    fk.gravity_add(fk.Gravity(tup(g)), F, F, np.ascontiguousarray(v.T), 0.0, par)
    fk.drag_add(fk.Drag(0.7), F, F, np.ascontiguousarray(v.T), 0.0, par)
    np.testing.assert_array_equal(F.T, spec)


def test_spring_kernels_are_the_lecture_spring_on_both_ends():
    RNG = np.random.default_rng(2)
    n = 5
    x, v = RNG.normal(size=(3, n)), RNG.normal(size=(3, n))
    x[:, 4] = x[:, 3]  # a zero-length spring 3-4 exerts nothing
    i, j = np.array([0, 1, 3, 2]), np.array([1, 2, 4, 0])
    k, c, r = RNG.uniform(1, 9, 4), RNG.uniform(0, 2, 4), RNG.uniform(0.1, 2, 4)
    F = np.full((3, n), 0.5)
    fk.add_spring_forces(F, x, v, i, j, k, c, r)
    expected = np.full((n, 3), 0.5)
    f1 = forces.spring_forces(x.T[i] - x.T[j], v.T[i] - v.T[j], k, c, r)
    for s in range(4):
        expected[i[s]] += f1[s]
        expected[j[s]] -= f1[s]
    np.testing.assert_allclose(F.T, expected, rtol=ROUND_OFF * 10, atol=ROUND_OFF * 10)
    assert np.all(f1[2] == 0.0)
    point = RNG.normal(size=(3, 2))
    F = np.zeros((3, n))
    fk.add_anchor_forces(F, x, v, np.array([2, 0]), point, k[:2], c[:2], r[:2])
    fa = forces.spring_forces(x.T[[2, 0]] - point.T, v.T[[2, 0]], k[:2], c[:2], r[:2])
    np.testing.assert_allclose(F[:, 2], fa[0], rtol=1e-14)
    np.testing.assert_allclose(F[:, 0], fa[1], rtol=1e-14)
    assert not F[:, [1, 3, 4]].any()


def test_force_kinds_and_their_energies_match_the_numpy_scene():
    RNG = np.random.default_rng(3)
    n = 6
    x, v = RNG.normal(size=(n, 3)), RNG.normal(size=(n, 3))
    mass, fixed = RNG.uniform(0.5, 2, n), np.array([False] * 5 + [True])
    springs = Springs(
        np.array([0, 2, 4]),
        np.array([1, 3, 5]),
        RNG.uniform(1, 5, 3),
        RNG.uniform(0, 1, 3),
        RNG.uniform(0.2, 1, 3),
    )
    anchors = Anchors(
        np.array([1]), RNG.normal(size=(1, 3)), np.array([4.0]), np.array([0.3]), np.array([0.5])
    )
    model = ParticleModel(
        mass=mass,
        x0=x,
        v0=v,
        radius=np.zeros(n),
        fixed=fixed,
        gravity=np.array([0.0, -9.81, 0.0]),
        drag=0.2,
        springs=springs,
        anchors=anchors,
        gravitation=Gravitation(G=0.5, softening=0.1),
    )
    from truestep.reference_impl.compiled import forces_of

    kinds = forces_of(model)
    assert [type(k).__name__ for k in kinds] == ["Gravity", "Drag", "Springs", "Anchors", "Gravitation"]
    par = particles(mass, fixed)
    X, V = np.ascontiguousarray(x.T), np.ascontiguousarray(v.T)
    F = np.zeros((3, n))
    for kind in kinds:
        type(kind).add(kind, F, X, V, 0.0, par)
    spec = forces.add_model_forces(np.zeros((n, 3)), model, x, v, 0.0)
    np.testing.assert_allclose(F.T, spec, rtol=1e-14, atol=1e-14)
    energy = kinetic_energy(V, par) + sum(type(k).energy(k, X, par) for k in kinds)
    assert energy == pytest.approx(total_energy(model, x, v), rel=1e-14)


@pytest.mark.parametrize("t", [0.0, 0.1, 0.2 - 1e-12, 0.2, 0.35])
def test_impulse_kernel_is_add_impulses_with_its_round_off_margin(t):
    imp = [
        (1, np.array([1.0, 2.0, 0.0]), 0.1, 0.2),
        (0, np.array([0.0, 0.0, 5.0]), 0.0, 0.3),
        (1, np.array([-3.0, 0.0, 1.0]), 0.2, 0.4),
    ]
    model = ParticleModel(
        mass=np.ones(3),
        x0=np.zeros((3, 3)),
        v0=np.zeros((3, 3)),
        radius=np.zeros(3),
        fixed=np.zeros(3, bool),
        impulses=imp,
    )
    from truestep.reference_impl.compiled import impulses_of

    kind = impulses_of(model)
    assert list(kind.kicked) == [0, 1] and list(kind.start) == [0, 1, 3, 3]
    spec = forces.add_impulses(np.full((3, 3), 0.25), imp, t)
    F = np.full((3, 3), 0.25)
    fk.impulses_add(kind, F, F, F, t, particles(np.ones(3)))
    np.testing.assert_array_equal(F.T, spec)


def planes_and_states(count: int):
    """Axis-aligned and slanted planes, with and without friction, a thin wall among
    them (the same every time)."""
    RNG = np.random.default_rng(4)
    for k in range(count):
        normal = RNG.normal(size=3) if k % 2 else np.eye(3)[k % 3] * (-1) ** k
        normal /= np.linalg.norm(normal)
        yield ModelPlane(
            RNG.normal(size=3), normal, RNG.uniform(0, 1), [0.0, 0.4][k % 2], [0.0, 0.05][k % 3 == 2]
        )


@pytest.mark.parametrize("k", range(6))
def test_contact_force_kernel_is_add_contact_forces(k):
    plane = list(planes_and_states(6))[k]
    RNG = np.random.default_rng(50 + k)
    n = 12
    f, v = RNG.normal(size=(n, 3)), RNG.normal(size=(n, 3))
    v[:4] -= np.outer(v[:4] @ plane.normal, plane.normal)  # sliding along the plane
    v[4:8] = 0.0  # at rest: static friction holds, or slips when the force is large
    f[6:8] *= 50.0
    spec = f.copy()
    add_contact_forces(spec, v, np.ones((1, n), bool), [plane])
    kp = Plane(tup(plane.point), tup(plane.normal), plane.restitution, plane.friction, plane.thickness)
    got = np.array([contact_force(tup(f[p]), tup(v[p]), kp) for p in range(n)])
    np.testing.assert_allclose(got, spec, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("k", range(6))
@pytest.mark.parametrize("dt", [0.0, 1e-3])
def test_collide_kernel_is_the_plane_collision_pass(k, dt):
    plane = list(planes_and_states(6))[k]
    RNG = np.random.default_rng(60 + k)
    n = 16
    radius = RNG.uniform(0, 0.05, n)
    depth = np.concatenate([RNG.uniform(-0.02, 0, 8), np.zeros(4), RNG.uniform(-1, -0.2, 4)])
    x = plane.point + np.outer(depth + radius, plane.normal) + RNG.normal(size=(n, 3)) * 0.3
    x -= np.outer((x - plane.point) @ plane.normal - depth - radius, plane.normal)
    v = RNG.normal(size=(n, 3))
    v[8:12] -= np.outer(v[8:12] @ plane.normal, plane.normal)  # resting candidates
    f = RNG.normal(size=(n, 3)) - 20.0 * plane.normal  # pushed into the plane
    mass = RNG.uniform(0.5, 2, n)
    model = ParticleModel(mass=mass, x0=x, v0=v, radius=radius, fixed=np.zeros(n, bool), planes=[plane])
    system = ParticleSystem(model)
    pass_ = PlaneCollisions([plane], radius, model.fixed, mass)
    kp = Plane(tup(plane.point), tup(plane.normal), plane.restitution, plane.friction, plane.thickness)
    d_spec = (x - plane.point) @ plane.normal - radius
    inside = d_spec < 1e-9
    if plane.thickness > 0:
        inside &= d_spec > -(plane.thickness + 2 * radius)
    idx = np.flatnonzero(inside)
    on = pass_._collide(system, plane, idx, f[idx], dt)
    for p in range(n):
        d = signed_distance(tup(x[p]), radius[p], kp)
        assert d == pytest.approx(d_spec[p], abs=1e-15)
        assert within(d, radius[p], kp) == bool(inside[p])
        if not inside[p]:
            continue
        y, u, resting = collide(tup(x[p]), tup(v[p]), tup(f[p]), 1.0 / mass[p], d, kp, dt)
        spot = int(np.flatnonzero(idx == p)[0])
        np.testing.assert_allclose(y, system.positions[p], rtol=1e-14, atol=1e-14)
        np.testing.assert_allclose(u, system.velocities[p], rtol=1e-13, atol=1e-13)
        assert resting == on[spot]


def test_anchors_of_one_particle_are_the_anchor_loop_on_it():
    RNG = np.random.default_rng(5)
    n = 4
    x, v = RNG.normal(size=(n, 3)), RNG.normal(size=(n, 3))
    anchors = Anchors(
        np.array([2, 0, 2, 3]),
        RNG.normal(size=(4, 3)),
        RNG.uniform(1, 5, 4),
        RNG.uniform(0, 1, 4),
        RNG.uniform(0.1, 1, 4),
    )
    anchors.point[3] = x[3]  # a zero-length anchor exerts nothing
    model = ParticleModel(
        mass=np.ones(n), x0=x, v0=v, radius=np.zeros(n), fixed=np.zeros(n, bool), anchors=anchors
    )
    from truestep.reference_impl.compiled import forces_of

    (kind,) = forces_of(model)
    spec = np.full((n, 3), 0.5)
    forces.add_anchors(spec, x, v, anchors)
    par = particles(np.ones(n))
    for p in range(n):  # particle 2 has two anchors, added in the case's order
        f = fk.anchors_at(kind, (0.5, 0.5, 0.5), tup(x[p]), tup(v[p]), 0.0, par, p)
        np.testing.assert_array_equal(f, spec[p])
    cut = fk.anchors_cut(kind, 2, 4)
    f = fk.anchors_at(cut, (0.5, 0.5, 0.5), tup(x[2]), tup(v[2]), 0.0, par, 0)
    np.testing.assert_array_equal(f, spec[2])


@pytest.mark.parametrize("slide", [0.2, 0.9, 1.1, 5.0])
@pytest.mark.parametrize("speed", [0.0, 1e-12, 1e-4])
def test_friction_stops_a_particle_in_contact_as_the_numpy_pass_does(slide, speed):
    """On a rough floor (mu = 0.5, a_N = -9.81): the particle stops within the step when its
    tangential speed is below eps_v + mu |a_N| dt and its tangential force below
    mu |F_N| (``slide`` times that limit), else it keeps sliding."""
    dt, mu, mass = 1e-3, 0.5, 2.0
    plane = ModelPlane(np.zeros(3), np.array([0.0, 1.0, 0.0]), 0.3, mu)
    x, v = np.array([[0.0, 0.0, 0.0]]), np.array([[speed, 0.0, 0.0]])
    f = np.array([[slide * mu * 9.81 * mass, -9.81 * mass, 0.0]])
    model = ParticleModel(
        mass=np.array([mass]), x0=x, v0=v, radius=np.zeros(1), fixed=np.zeros(1, bool), planes=[plane]
    )
    system = ParticleSystem(model)
    on = PlaneCollisions([plane], model.radius, model.fixed, model.mass)._collide(
        system, plane, np.array([0]), f, dt
    )
    kp = Plane((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 0.3, mu, 0.0)
    y, u, resting = collide(tup(x[0]), tup(v[0]), tup(f[0]), 1.0 / mass, 0.0, kp, dt)
    assert resting == bool(on[0]) is True
    np.testing.assert_array_equal(u, system.velocities[0])
    np.testing.assert_array_equal(y, system.positions[0])
    if speed > 0:  # (a particle at rest stays at rest in the pass either way)
        assert (u[0] == 0.0) == (slide <= 1.0 and speed < 1e-3)


def test_the_blow_up_checks_find_every_component_out_of_range():
    from truestep.reference_impl.integrate import BLOWUP
    from truestep.reference_impl.integrate_kernels import finite, first_bad

    base = np.zeros((3, 4))
    assert finite(base, base)
    for value in (BLOWUP, -BLOWUP, np.inf, -np.inf, np.nan, 2 * BLOWUP, -2 * BLOWUP):
        for which in range(2):
            for c, p in ((0, 0), (1, 3), (2, 2)):
                x, v = base.copy(), base.copy()
                (x, v)[which][c, p] = value
                assert not finite(x, v), (value, which, c, p)
                xs, vs = np.zeros((5, 4, 3)), np.zeros((5, 4, 3))
                (xs, vs)[which][3, p, c] = value
                assert first_bad(xs, vs, 0, 4, 1, 5) == 3
                assert first_bad(xs, vs, 0, 4, 1, 3) == -1  # not among these records
                assert first_bad(xs, vs, 0, p, 1, 5) == -1  # nor among these particles
    assert finite(base + 0.999 * BLOWUP, base - 0.999 * BLOWUP)
