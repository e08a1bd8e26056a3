"""The pybullet adapter against exact solutions and the scheme its docstring states (real pybullet).

pybullet's step is semi-implicit Euler with the velocity update first:
``v_{n+1} = v_n + h (g + f_n / m)``, ``x_{n+1} = x_n + h v_{n+1}`` (adapters/pybullet_adapter.py),
the reference's ``symplectic-euler``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from truestep.adapters.base import Adapter
from truestep.adapters.pybullet_adapter import PybulletAdapter
from truestep.adapters.reference import ReferenceAdapter
from truestep.cases.case import Case, OdeSpec
from truestep.reference_impl.model import (
    Anchors,
    EmitterSpec,
    ForceField,
    Gravitation,
    ParticleModel,
    Plane,
    Springs,
)

pytestmark = pytest.mark.engine

G = 9.81
GRAVITY = np.array([0.0, -G, 0.0])
FLOOR = np.array([0.0, 1.0, 0.0])


@pytest.fixture(scope="module")
def adapter() -> PybulletAdapter:
    return PybulletAdapter()


def make_case(model: ParticleModel, duration: float, dt: float, max_records: int = 2000) -> Case:
    """A case around ``model`` with one step size, recording at most ``max_records`` states."""
    return Case(
        name="pybullet-test",
        file="<test>",
        title="",
        description="",
        duration=duration,
        dts=[dt],
        quick_dts=[dt],
        tolerances=[],
        quick_tolerances=[],
        scene=model,
        max_records=max_records,
    )


def particle(x0, v0=(0.0, 0.0, 0.0), **kw) -> ParticleModel:
    """One 1 kg particle (more keywords go to :class:`ParticleModel`)."""
    return ParticleModel(
        mass=np.array([1.0]),
        x0=np.array([x0], float),
        v0=np.array([v0], float),
        radius=np.array([kw.pop("radius", 0.0)]),
        fixed=np.array([False]),
        **kw,
    )


def test_protocol_and_missing_features(adapter, case_named):
    assert isinstance(adapter, Adapter)
    assert adapter.methods == ("default", "clean") and adapter.adaptive_methods == ()
    for method in adapter.methods:
        assert adapter.missing(case_named("harmonic-oscillator"), method) == set()
    emitter = EmitterSpec(
        shape="cube",
        center=np.zeros(3),
        size=0.1,
        rate_n=1.0,
        rate_r=0.0,
        speed=1.0,
        spread=0.1,
        lifetime=10,
        capacity=2,
    )
    pool = ParticleModel(
        mass=np.ones(2),
        x0=np.zeros((2, 3)),
        v0=np.zeros((2, 3)),
        radius=np.zeros(2),
        fixed=np.zeros(2, bool),
        gravity=GRAVITY,
        emitters=[emitter],
    )
    case = make_case(pool, 1.0, 0.01)
    assert adapter.missing(case, "clean") == {"emitters"}
    with pytest.raises(ValueError, match="emitters"):
        adapter.simulate(case, "clean", 0.01)
    ode = Case(
        name="o",
        file="",
        title="",
        description="",
        duration=1.0,
        dts=[0.1],
        quick_dts=[0.1],
        tolerances=[],
        quick_tolerances=[],
        scene=OdeSpec("circle-field", np.array([1.0, 0.0])),
    )
    assert adapter.missing(ode, "default") == {"ode"}
    with pytest.raises(ValueError, match="method"):
        adapter.simulate(case_named("harmonic-oscillator"), "Euler", 1e-3)


@pytest.mark.parametrize("method", ["default", "clean"])
def test_free_fall_is_velocity_first_symplectic_euler(adapter, method):
    h = 0.01
    run = adapter.simulate(make_case(particle([0.0, 10.0, 0.0], gravity=GRAVITY), 1.0, h), method, h)
    assert run.status == "ok" and run.steps == run.nfev == 100
    n = np.arange(101)
    np.testing.assert_allclose(run.t, n * h, rtol=0, atol=1e-12)
    # Bullet from rest: v_n = -g n h, y_n = y0 - g h^2 n (n + 1) / 2 (velocity first; the
    # position-first variant gives n (n - 1) / 2). 1e-9 m is rounding of 100 steps at
    # double precision, with room. This holds only because the adapter zeroes the
    # multibody's default linearDamping of 0.04: left there, the same fall at h = 1/240
    # ends 0.35 m higher after 1 s (measured), 3e8 times this tolerance.
    np.testing.assert_allclose(run.x[:, 0, 1], 10.0 - G * h**2 * n * (n + 1) / 2, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.v[:, 0, 1], -G * n * h, rtol=0, atol=1e-9)
    assert np.all(run.x[:, 0, [0, 2]] == 0) and np.all(run.v[:, 0, [0, 2]] == 0)


@pytest.mark.parametrize("method", ["default", "clean"])
def test_no_velocity_clamp(adapter, method):
    # A btMultiBody clamps each velocity coordinate to 100 m/s unless maxJointVelocity is
    # lifted (measured: a 15 s fall ended at -100 m/s). Exact: v = -g t at 15 s, 1e-9 m/s
    # for the rounding of 1500 additions.
    run = adapter.simulate(
        make_case(particle([0.0, 0.0, 0.0], (150.0, 0.0, 0.0), gravity=GRAVITY), 15.0, 0.01), method, 0.01
    )
    np.testing.assert_allclose(run.v[-1, 0], [150.0, -G * 15.0, 0.0], rtol=0, atol=1e-9)


@pytest.mark.parametrize("method", ["default", "clean"])
def test_harmonic_oscillator(adapter, case_named, method):
    case = case_named("harmonic-oscillator")
    h, omega, amp, t_end = 1e-3, 10.0, 0.1, 2.0
    run = adapter.simulate(case, method, h)
    assert run.status == "ok" and run.steps == 2000
    e = run.energy
    # Symplectic Euler keeps E - m omega^2 h x v / 2 exactly, so |E - E0| / E0 stays below
    # (omega h / 2) / (1 - omega h / 2) = 0.005; the 0.02 asked for is met with room.
    assert np.max(np.abs(e - e[0])) / e[0] < 0.02
    # The anchored spring along x is exactly f = -k x, so the run must be the linear map
    # v' = v - omega^2 h x, x' = x + h v' applied 2000 times: to rounding (1e-12 m).
    step = np.array([[1.0 - (omega * h) ** 2, h], [-(omega**2) * h, 1.0]])
    x_end, v_end = np.linalg.matrix_power(step, 2000) @ np.array([amp, 0.0])
    assert abs(run.x[-1, 0, 0] - x_end) < 1e-12 and abs(run.v[-1, 0, 0] - v_end) < 1e-11
    # Against the exact 0.1 cos(10 t): the discrete orbit starts off its own axes by a phase
    # of omega h / 2 (the first-order error, A omega h / 2 = 5e-4 m) and its frequency is
    # high by omega^3 h^2 / 24 (A omega^3 h^2 T / 24 = 8e-6 m after 2 s); 10 % covers the
    # dropped O(h^2) amplitude terms (A omega^2 h^2 / 8 = 1.3e-6 m).
    bound = 1.1 * amp * (omega * h / 2 + omega**3 * h**2 * t_end / 24)
    assert abs(run.x[-1, 0, 0] - amp * np.cos(omega * t_end)) < bound


def busy_scene() -> ParticleModel:
    """Four particles, one pinned and drifting at 0.1 m/s (a kinematic point, as in the
    reference): damped springs, an anchor, drag, gravitation, two force fields, an impulse
    and gravity, all away from contact."""
    return ParticleModel(
        mass=np.array([1.0, 2.0, 0.5, 1.5]),
        x0=np.array([[0.3, 0.0, 0.2], [1.0, 0.2, 0.1], [2.0, -0.1, 0.0], [0.5, 1.0, -0.3]]),
        v0=np.array([[0.1, 0.0, 0.0], [0.1, 0.0, 0.2], [0.0, 0.3, 0.0], [-0.2, 0.0, 0.1]]),
        radius=np.zeros(4),
        fixed=np.array([True, False, False, False]),
        gravity=GRAVITY,
        drag=0.1,
        springs=Springs(
            np.array([0, 1, 2]),
            np.array([1, 2, 3]),
            np.array([50.0, 80.0, 30.0]),
            np.array([0.5, 0.0, 0.2]),
            np.array([1.0, 1.0, 1.2]),
        ),
        anchors=Anchors(
            np.array([3]), np.array([[0.5, 2.0, 0.0]]), np.array([20.0]), np.array([0.3]), np.array([0.8])
        ),
        gravitation=Gravitation(G=0.05, softening=0.1),
        fields=[
            ForceField(
                "vortex", {"center": [0.0, 0.0, 0.0], "axis": [0.0, 1.0, 0.0], "strength": 0.5, "core": 0.5}
            ),
            ForceField(
                "wind", {"direction": [1.0, 0.0, 0.0], "speed": 0.5, "gust": 0.2, "freq": 1.0, "k": 0.2}
            ),
        ],
        impulses=[(2, np.array([0.0, 0.0, 3.0]), 0.2, 0.4)],
    )


@pytest.mark.parametrize("method", ["default", "clean"])
def test_forces_match_reference_symplectic_euler(adapter, method):
    # Every per-step force (springs with damping, anchor, drag, gravitation, vortex, wind,
    # impulse) goes through applyExternalForce at (x_n, v_n, t_n); with gravity from
    # setGravity that is the reference's symplectic Euler step for step. Measured agreement:
    # 8e-16 m; 1e-12 m / 1e-11 m/s leaves room for rounding differences over 1000 steps.
    case = make_case(busy_scene(), 1.0, 1e-3)
    ref = ReferenceAdapter().simulate(case, "symplectic-euler", 1e-3)
    run = adapter.simulate(case, method, 1e-3)
    assert run.status == "ok" and run.x.shape == ref.x.shape == (1001, 4, 3)
    np.testing.assert_allclose(run.x, ref.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(run.v, ref.v, rtol=0, atol=1e-11)
    np.testing.assert_allclose(run.energy, ref.energy, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(
        run.x[:, 0], busy_scene().x0[0] + np.outer(run.t, [0.1, 0, 0]), rtol=0, atol=1e-14
    )


def bounce(adapter: PybulletAdapter, method: str, e: float, h: float, radius: float = 0.05):
    """Drop a ball from 1 m onto the floor y = 0; return (v_in, v_out, depth_in, y) at the
    first contact step: velocities before and after it, the depth at its start, positions."""
    model = particle(
        [0.0, 1.0, 0.0],
        radius=radius,
        gravity=GRAVITY,
        planes=[Plane(np.zeros(3), FLOOR, restitution=e, friction=0.0)],
    )
    run = adapter.simulate(make_case(model, 0.6, h), method, h)
    assert run.status == "ok" and run.steps == len(run.t) - 1
    y, vy = run.x[:, 0, 1], run.v[:, 0, 1]
    k = int(np.argmax(vy > 0))
    return vy[k - 1], vy[k], radius - y[k - 1], y


def test_bounce_clean_restores_exactly_e(adapter):
    # clean: split impulse keeps the penetration push out of the velocity and restitution
    # acts on the velocity at the step's start, so v_out = -e v_in to rounding (measured
    # 2e-16); 1e-12 is rounding with room.
    v_in, v_out, depth, y = bounce(adapter, "clean", 0.8, 1 / 240)
    assert depth > 0.01  # the ball is 15.8 mm deep when the contact step starts
    assert abs(-v_out / v_in - 0.8) < 1e-12
    # the push lifts the ball back to the surface in that step (contactERP 0.08 of 15.8 mm
    # plus the rebound's 14.4 mm): it never goes deeper
    assert np.min(y) > 0.05 - depth - 1e-12


def test_bounce_default_adds_the_baumgarte_velocity(adapter):
    # default: btMultiBody contacts take the restitution target from the velocity *after*
    # the step's gravity kick and add the Baumgarte term contactERP (d - slop) / h to it
    # (contactERP 0.08, contactSlop 1e-5 m, d the depth at the step's start), so
    # v_out = e (|v_in| + g h) + 0.08 (d - 1e-5) / h. Measured 0.8777054 (vs e = 0.8) and
    # the model agrees to 1e-16; 1e-9 is rounding with room.
    h, e = 1 / 240, 0.8
    v_in, v_out, depth, _ = bounce(adapter, "default", e, h)
    predicted = (e * (-v_in + G * h) + 0.08 * (depth - 1e-5) / h) / -v_in
    assert abs(-v_out / v_in - predicted) < 1e-9
    assert -v_out / v_in > e + 0.07  # 7.8 % more rebound speed than asked for


def test_point_particle_bounces_on_the_plane_itself(adapter):
    # A radius-0 particle gets a 1 cm sphere and a plane moved 1 cm back, so it bounces at
    # y = 0 itself: from 1 m at h = 1 ms its contact step starts at most one step's travel
    # (4.5 mm) below y = 0, and before that it passed y = 0.01, where the 1 cm sphere on
    # the case's plane would have stopped.
    v_in, v_out, depth, y = bounce(adapter, "clean", 0.5, 1e-3, radius=0.0)
    assert abs(-v_out / v_in - 0.5) < 1e-12
    assert 0.0 < depth < -v_in * 1e-3 + 1e-12
    assert np.min(y) < 0.0


@pytest.mark.parametrize("method", ["default", "clean"])
def test_sliding_friction_is_coulomb(adapter, method):
    # A point mass sliding diagonally at 2 m/s on a floor with mu = 0.5: each step takes
    # mu g h off the speed (along the velocity) until it stops; the semi-implicit Euler
    # distance is h (N v0 - mu g h N (N + 1) / 2) with N = floor(v0 / (mu g h)). Measured
    # 5e-6 m more (the first step's 10 um contact settling); 2e-5 m allows for it.
    h, mu, v0 = 1e-3, 0.5, 2.0
    vel = v0 / np.sqrt(2) * np.array([1.0, 0.0, 1.0])
    model = particle(
        [0.0, 0.05, 0.0],
        vel,
        radius=0.05,
        gravity=GRAVITY,
        planes=[Plane(np.zeros(3), FLOOR, restitution=0.0, friction=mu)],
    )
    run = adapter.simulate(make_case(model, 0.6, h), method, h)
    steps = int(np.floor(v0 / (mu * G * h)))
    exact = h * (steps * v0 - mu * G * h * steps * (steps + 1) / 2)
    x, z = run.x[-1, 0, 0], run.x[-1, 0, 2]
    assert abs(np.hypot(x, z) - exact) < 2e-5 and abs(x - z) < 1e-12
    assert np.all(np.abs(run.v[-1, 0]) < 1e-12)  # at rest, to rounding


@pytest.mark.parametrize("method", ["default", "clean"])
def test_blow_up_is_unstable_not_clamped(adapter, method):
    # k = 1e4 N/m (omega = 100 rad/s) at h = 0.05 s: omega h = 5 > 2, the map's eigenvalue
    # is about -23, so |x| passes 1e12 m within 10 steps (t = 0.5 s); the run must say so.
    model = particle(
        [0.1, 0.0, 0.0],
        anchors=Anchors(np.array([0]), np.array([[-1.0, 0, 0]]), np.array([1e4]), np.zeros(1), np.ones(1)),
    )
    run = adapter.simulate(make_case(model, 5.0, 0.05), method, 0.05)
    assert run.status == "unstable" and run.t_fail is not None and run.t_fail <= 0.5 + 1e-12
    assert run.steps < 100


@pytest.mark.parametrize("name", ["spring-chain", "triangle-impulse", "hanging-cloth"])
def test_clean_is_default_bit_for_bit_without_contacts(adapter, case_named, name):
    """The harness skips `clean` on scenes without planes as a duplicate of `default`:
    that holds only if the two trajectories are identical, which this checks."""
    case = dataclasses.replace(case_named(name), duration=0.3)
    assert adapter.duplicate(case, "clean") and adapter.duplicate(case, "default") is None
    a, b = adapter.simulate(case, "default", 2e-3), adapter.simulate(case, "clean", 2e-3)
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
    assert adapter.duplicate(case_named("bouncing-ball"), "clean") is None


@pytest.mark.parametrize("method", ["default", "clean"])
@pytest.mark.parametrize(
    "name", ["bouncing-ball", "sliding-contact", "high-speed-impact", "triangle-impulse", "hanging-cloth"]
)
def test_a_run_in_the_emptied_client_is_the_run_in_a_new_one(case_named, name, method):
    """The adapter builds each scene in its process's client emptied by ``resetSimulation``:
    after runs of the other method (its contact parameters), of another scene and of this
    one, a run steps the bits of a run in a client opened for it (contact and restitution,
    friction, a thin wall, impulses, springs and pins)."""
    from truestep.adapters import pybullet_adapter as pb

    case = dataclasses.replace(case_named(name), duration=min(case_named(name).duration, 0.5))
    adapter = PybulletAdapter()
    dt = case.dts[-1]
    fresh_adapter = PybulletAdapter()
    fresh_adapter.build = lambda c, m, h: pb._Run(  # type: ignore[method-assign]
        c.particles, pb.build_scene(c.particles, h, clean=m == "clean")
    )
    fresh_adapter.close = lambda run: pb.p.disconnect(run.scene.client)  # type: ignore[method-assign]
    fresh = fresh_adapter.simulate(case, method, dt)
    other = "clean" if method == "default" else "default"
    adapter.simulate(case_named("spring-damper-pair"), other, 0.01)
    adapter.simulate(case, other, dt)
    runs = [adapter.simulate(case, method, dt), adapter.simulate(case, method, dt)]
    for run in runs:
        assert run.status == fresh.status and run.message == fresh.message
        assert np.array_equal(run.x, fresh.x) and np.array_equal(run.v, fresh.v)
