"""The compiled rain kernel computes what the numpy particle system computes."""

from __future__ import annotations

import numpy as np
import pytest

from truestep.reference_impl.kernels import rain_run, rain_step
from truestep.reference_impl.model import ParticleModel, Plane
from truestep.reference_impl.particles import ParticleSystem
from truestep.reference_impl.passes import passes_for
from truestep.reference_impl.solvers import LectureUpdate


@pytest.mark.parametrize(("normal", "drag", "restitution"),
                         [((0.0, 1.0, 0.0), 0.1, 0.7), ((0.3, 1.0, -0.2), 0.0, 0.0)])
def test_kernel_equals_the_numpy_path(normal, drag, restitution):
    rng = np.random.default_rng(4)
    n, mass, radius, dt, steps = 1000, 0.5, 0.01, 2e-3, 1000
    normal = np.array(normal) / np.linalg.norm(normal)
    point = np.array([0.0, -0.2, 0.0])
    g = np.array([0.0, -9.81, 0.0])
    x0 = rng.uniform(-1, 1, (n, 3))
    x0 += np.maximum(0.0, radius + 0.05 - (x0 - point) @ normal)[:, None] * normal
    x0[:50] -= (((x0[:50] - point) @ normal) - radius)[:, None] * normal  # on the plane
    v0 = rng.normal(0, 2, (n, 3))
    v0[:50] = 0.0  # at rest on the plane: resting contact from the start
    model = ParticleModel(mass=np.full(n, mass), x0=x0, v0=v0, radius=np.full(n, radius),
                          fixed=np.zeros(n, bool), gravity=g, drag=drag,
                          planes=[Plane(point, normal, restitution, 0.0)])
    system = ParticleSystem(model, passes_for(model))
    x, v, contact = system.positions.copy(), system.velocities.copy(), system.contact[0].copy()
    solver = LectureUpdate(system)
    for _ in range(steps):
        solver.step(dt)
        system.between_steps(dt)
    rain_step(x, v, contact, dt, g, drag, mass, radius, point, normal, restitution, steps)
    # The same formulas in the same order; the kernel lets the compiler fuse
    # multiply-adds, which moves results by round-off (1e-16 relative per operation,
    # ~1e-14 m after 1000 steps), far below 1e-12.
    assert np.max(np.abs(x - system.positions)) < 1e-12
    assert np.max(np.abs(v - system.velocities)) < 1e-12
    assert np.array_equal(contact, system.contact[0])
    assert contact.sum() > 50  # many came to rest: the contact branch was exercised


def test_kernel_splits_steps_across_calls():
    rng = np.random.default_rng(1)
    n = 1000
    args = (2e-3, np.array([0.0, -9.81, 0.0]), 0.2, 1.0, 0.0, np.zeros(3),
            np.array([0.0, 1.0, 0.0]), 0.5)
    x, v = rng.uniform(0, 2, (n, 3)), rng.normal(0, 1, (n, 3))
    c = np.zeros(n, bool)
    x2, v2, c2 = x.copy(), v.copy(), c.copy()
    rain_step(x, v, c, *args, 500)
    for _ in range(5):
        rain_step(x2, v2, c2, *args, 100)
    assert np.array_equal(x, x2) and np.array_equal(v, v2) and np.array_equal(c, c2)


def test_one_run_records_what_separate_calls_reach():
    """rain_run's records after stretches of 100, 50 and 350 steps are the states that
    rain_step reaches in three separate calls."""
    rng = np.random.default_rng(2)
    n = 700
    args = (2e-3, np.array([0.0, -9.81, 0.0]), 0.2, 1.0, 0.0, np.zeros(3),
            np.array([0.0, 1.0, 0.0]), 0.5)
    x, v = rng.uniform(0, 2, (n, 3)), rng.normal(0, 1, (n, 3))
    c = np.zeros(n, bool)
    x2, v2, c2 = x.copy(), v.copy(), c.copy()
    stretches = np.array([100, 50, 350])
    xs, vs = np.empty((3, n, 3)), np.empty((3, n, 3))
    rain_run(x, v, c, *args, stretches, xs, vs)
    for k, steps in enumerate(stretches):
        rain_step(x2, v2, c2, *args, int(steps))
        assert np.array_equal(xs[k], x2) and np.array_equal(vs[k], v2)
    assert np.array_equal(x, x2) and np.array_equal(c, c2)
