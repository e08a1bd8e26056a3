"""The MuJoCo adapter against exact discrete and continuous solutions (real MuJoCo)."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from truestep.adapters.base import Adapter
from truestep.adapters.contact_law import damping_ratio, max_damping_ratio, restitution_of
from truestep.adapters.mujoco_adapter import MujocoAdapter, build
from truestep.cases.case import Case, OdeSpec
from truestep.cases.loader import load_case
from truestep.reference_impl.forces import spring_forces
from truestep.reference_impl.model import Anchors, ForceField, Gravitation, ParticleModel, Plane, Springs
from truestep.reference_impl.particles import total_energy

pytestmark = pytest.mark.engine

CASES = Path(__file__).resolve().parents[2] / "cases"
G = np.array([0.0, -9.81, 0.0])


def make_case(model: ParticleModel, duration: float, dt: float, max_records: int = 2000) -> Case:
    """A case around ``model`` with one step size, recording at most ``max_records`` states."""
    return Case(
        name="mujoco-test",
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


def test_protocol_and_missing_features():
    adapter = MujocoAdapter()
    assert isinstance(adapter, Adapter)
    assert adapter.methods == ("Euler", "implicit", "implicitfast", "RK4")
    assert adapter.adaptive_methods == ()
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
    assert adapter.missing(ode, "RK4") == {"ode"}
    assert adapter.missing(load_case(CASES / "harmonic-oscillator.toml"), "Euler") == set()
    with pytest.raises(ValueError, match="method"):
        adapter.simulate(load_case(CASES / "harmonic-oscillator.toml"), "rk4", 1e-3)


@pytest.mark.parametrize("method", ["Euler", "implicit", "implicitfast", "RK4"])
def test_free_fall_is_the_integrators_exact_discrete_solution(method):
    """A 3-D particle falling from rest, 100 steps of 0.01 s.

    Euler, implicit and implicitfast step ``v' = v + h g, y' = y + h v'`` (semi-implicit;
    with no velocity-dependent force the implicit D matrix is empty), whose exact discrete
    solution is ``y_n = y_0 + g h^2 n (n + 1) / 2``, ``v_n = g h n``. RK4 integrates a
    constant acceleration exactly: ``y_n = y_0 + g (n h)^2 / 2``. Tolerance 1e-12 m:
    rounding over 100 additions of numbers of order 1.
    """
    h, n = 0.01, 100
    case = make_case(particle((0.2, 3.0, -0.4), gravity=G), n * h, h)
    run = MujocoAdapter().simulate(case, method, h)
    k = np.arange(n + 1)
    # nfev counts force evaluations: RK4 makes four per step, the others one.
    assert run.status == "ok" and run.steps == n
    assert run.nfev == (4 if method == "RK4" else 1) * n
    np.testing.assert_allclose(run.t, k * h, atol=1e-12)
    if method == "RK4":
        y = 3.0 + G[1] * (k * h) ** 2 / 2
    else:
        y = 3.0 + G[1] * h**2 * k * (k + 1) / 2
    np.testing.assert_allclose(run.x[:, 0, 1], y, rtol=0, atol=1e-12)
    np.testing.assert_allclose(run.v[:, 0, 1], G[1] * h * k, rtol=0, atol=1e-12)
    np.testing.assert_allclose(run.x[:, 0, [0, 2]], np.tile([0.2, -0.4], (n + 1, 1)), atol=0)


def test_tendon_is_the_lectures_spring_damper():
    """MuJoCo's passive force of a spatial tendon (stiffness, damping, springlength) equals
    the reference's damped spring at an arbitrary 3-D state, to rounding (1e-12 N)."""
    model = ParticleModel(
        mass=np.array([1.0, 2.0]),
        x0=np.array([[0.3, 0.2, -0.1], [1.1, -0.4, 0.5]]),
        v0=np.array([[0.5, -0.2, 0.3], [-0.1, 0.7, 0.2]]),
        radius=np.zeros(2),
        fixed=np.zeros(2, bool),
        springs=Springs(np.array([0]), np.array([1]), np.array([100.0]), np.array([3.0]), np.array([0.6])),
        anchors=Anchors(
            np.array([1]), np.array([[-1.0, 0.0, 0.0]]), np.array([40.0]), np.array([1.5]), np.array([1.2])
        ),
    )
    scene = build(make_case(model, 1.0, 0.01), "Euler", 0.01)
    x, v = model.x0, model.v0
    f01 = spring_forces(x[:1] - x[1:], v[:1] - v[1:], np.array([100.0]), np.array([3.0]), np.array([0.6]))[0]
    fa = spring_forces(x[1:] - [-1.0, 0.0, 0.0], v[1:], np.array([40.0]), np.array([1.5]), np.array([1.2]))[0]
    expected = np.concatenate([f01, -f01 + fa])
    np.testing.assert_allclose(scene.data.qfrc_passive, expected, rtol=0, atol=1e-12)


def test_harmonic_oscillator():
    """cases/harmonic-oscillator.toml (k = 100 N/m, 1 kg, x = 0.1 cos 10t) at h = 1e-3 s."""
    case = load_case(CASES / "harmonic-oscillator.toml")
    adapter = MujocoAdapter()
    e0 = 0.5 * 100.0 * 0.1**2

    euler = adapter.simulate(case, "Euler", 1e-3)
    # semi-implicit Euler keeps a modified energy: E oscillates by a relative h omega = 0.01
    # and does not drift; 0.02 leaves a factor 2.
    assert euler.status == "ok"
    assert np.max(np.abs(euler.energy - e0)) / e0 < 0.02

    rk4 = adapter.simulate(case, "RK4", 1e-3)
    # RK4's leading error on an oscillator is a phase lag of (h omega)^5 / 120 per step:
    # amplitude * omega t * (h omega)^4 / 120 = 0.1 * 20 * 1e-8 / 120 = 1.7e-10 m at t = 2 s.
    bound = 0.1 * 10.0 * rk4.t * (1e-3 * 10.0) ** 4 / 120
    assert np.all(np.abs(rk4.x[:, 0, 0] - 0.1 * np.cos(10.0 * rk4.t)) <= 1.05 * bound + 1e-15)

    for method in ("implicit", "implicitfast"):
        run = adapter.simulate(case, method, 1e-3)
        # velocity-implicit Euler has no damping to treat implicitly here: bounded like Euler
        assert run.status == "ok"
        assert np.max(run.energy) < e0 * 1.02 and run.energy[-1] < e0 * 1.02


def test_mujoco_energy_agrees_with_total_energy():
    """MuJoCo's own mjData.energy (flag energy) and total_energy on the read-back state:
    gravity, a spring between particles and an anchored damped spring, 3-D, RK4.

    Both zero points of gravity lie at the origin, but compare E(t) - E(0) anyway;
    the two are computed from the same state, so they agree to rounding (1e-10 J).
    """
    model = ParticleModel(
        mass=np.array([1.0, 0.5]),
        x0=np.array([[0.0, 1.0, 0.0], [0.3, 0.4, 0.2]]),
        v0=np.array([[0.2, 0.0, -0.1], [0.0, 0.5, 0.3]]),
        radius=np.zeros(2),
        fixed=np.zeros(2, bool),
        gravity=G,
        springs=Springs(np.array([0]), np.array([1]), np.array([50.0]), np.zeros(1), np.array([0.5])),
        anchors=Anchors(
            np.array([0]), np.array([[0.0, 2.0, 0.0]]), np.array([80.0]), np.array([0.5]), np.array([0.8])
        ),
    )
    scene = build(make_case(model, 1.0, 1e-3), "RK4", 1e-3)
    m, d = scene.model, scene.data
    ours, theirs = [], []
    for _ in range(20):
        mujoco.mj_step(m, d, nstep=50)
        mujoco.mj_forward(m, d)  # mj_step leaves energy of the state before the last step
        ours.append(total_energy(model, scene.positions(2), scene.velocities(2)))
        theirs.append(float(np.sum(d.energy)))
    ours, theirs = np.array(ours), np.array(theirs)
    assert np.ptp(ours) > 0.05  # the anchor's damper dissipates: the test sees a changing energy
    np.testing.assert_allclose(theirs - theirs[0], ours - ours[0], rtol=0, atol=1e-10)


def test_drag_is_joint_damping_implicit_in_euler():
    """Drag k = 2 N s/m on a 1 kg particle, h = 0.1 s, 30 steps. MuJoCo's Euler integrates
    joint damping implicitly: v_n = v_0 / (1 + h k)^n; RK4 explicitly:
    v_n = v_0 R(-h k)^n with R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24. Rounding: 1e-14 m/s."""
    h, n, k = 0.1, 30, 2.0
    case = make_case(particle((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), drag=k), n * h, h)
    z = -h * k
    for method, factor in (
        ("Euler", 1 / (1 + h * k)),
        ("implicitfast", 1 / (1 + h * k)),
        ("RK4", 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24),
    ):
        run = MujocoAdapter().simulate(case, method, h)
        np.testing.assert_allclose(run.v[:, 0, 0], factor ** np.arange(n + 1), rtol=0, atol=1e-14)


def test_pinned_particle_and_damped_spring_reach_static_equilibrium():
    """A 1 kg particle hangs straight below a pinned one on a damped spring (k = 100 N/m,
    k_d = 5 N s/m, rest 0.5 m). Equilibrium y = 1 - 0.5 - m g / k; after 10 s the transient
    has decayed by exp(-zeta omega t) = exp(-25), and semi-implicit Euler's fixed point is
    the exact equilibrium: 1e-8 m."""
    model = ParticleModel(
        mass=np.array([3.0, 1.0]),
        x0=np.array([[0.0, 1.0, 0.0], [0.0, 0.6, 0.0]]),
        v0=np.zeros((2, 3)),
        radius=np.zeros(2),
        fixed=np.array([True, False]),
        gravity=G,
        springs=Springs(np.array([0]), np.array([1]), np.array([100.0]), np.array([5.0]), np.array([0.5])),
        dimension=2,
    )
    run = MujocoAdapter().simulate(make_case(model, 10.0, 1e-3, max_records=10), "Euler", 1e-3)
    assert run.status == "ok"
    np.testing.assert_array_equal(run.x[:, 0], np.tile([0.0, 1.0, 0.0], (len(run.t), 1)))
    np.testing.assert_allclose(run.x[-1, 1], [0.0, 0.5 - 9.81 / 100.0, 0.0], atol=1e-8)
    assert np.all(run.x[:, 1, 2] == 0.0)  # a 2-D scene has no z joint


def test_stage_forces_keep_rk4_fourth_order():
    """Two 1 kg bodies on a circular orbit under gravitation (G = 1, separation 1 m):
    after one period T = pi sqrt(2) both are back where they started. With the passive
    callback RK4 converges at order 4 (error ratio 16 when h halves; 14 allows for the
    pre-asymptotic range); forces held in qfrc_applied through the stages make it order 1
    (ratio 2; between 1.6 and 2.4)."""
    speed = np.sqrt(0.5)
    model = ParticleModel(
        mass=np.ones(2),
        x0=np.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]]),
        v0=np.array([[0.0, -speed, 0.0], [0.0, speed, 0.0]]),
        radius=np.zeros(2),
        fixed=np.zeros(2, bool),
        gravitation=Gravitation(G=1.0),
        dimension=2,
    )
    period = np.pi / speed

    def error(stage: bool, h: float) -> float:
        run = MujocoAdapter(stage_forces=stage).simulate(make_case(model, period, h, max_records=4), "RK4", h)
        return float(np.max(np.abs(run.x[-1] - model.x0)))

    staged = error(True, 0.02), error(True, 0.01)
    held = error(False, 0.02), error(False, 0.01)
    assert staged[1] < 1e-8
    assert staged[0] / staged[1] > 14
    assert 1.6 < held[0] / held[1] < 2.4
    assert mujoco.get_mjcb_passive() is None  # the callback does not outlive the run


def test_divergence_is_unstable_not_reset():
    """Semi-implicit Euler on the oscillator diverges for h omega > 2 (here 5). With
    autoreset off MuJoCo flags the state instead of resetting it to qpos0."""
    case = load_case(CASES / "harmonic-oscillator.toml")
    case.duration = 100.0
    run = MujocoAdapter().simulate(case, "Euler", 0.5)
    assert run.status == "unstable"
    assert run.t_fail is not None and 0 < run.t_fail <= 100.0
    assert np.all(np.abs(run.x[1:, 0, 0]) > 0.1)  # never back at the start: no reset


def test_restitution_relation():
    """The zero-force-release restitution of a linear spring-dashpot and its inverse."""
    assert restitution_of(0.0) == 1.0
    assert restitution_of(1.0) == pytest.approx(np.exp(-2.0))
    assert restitution_of(1.0 - 1e-6) == pytest.approx(np.exp(-2.0), rel=1e-3)
    assert restitution_of(1.0 + 1e-6) == pytest.approx(np.exp(-2.0), rel=1e-3)
    for e in (0.01, 0.1, 0.5, 0.8, 0.95):
        assert restitution_of(damping_ratio(e)) == pytest.approx(e, rel=1e-12)
    assert damping_ratio(0.0) == np.inf
    assert max_damping_ratio(10 * 0.001, 0.001) == pytest.approx(10 / (2 * np.pi))


def _rebound_ratio(run, radius: float, g: float) -> float:
    """First bounce: rebound over impact normal speed, both extrapolated ballistically from
    the last step before the contact and the first step after it to the surface y = radius."""
    gap = run.x[:, 0, 1] - radius
    v = run.v[:, 0, 1]
    first_in = int(np.argmax(gap < 0))
    first_out = first_in + int(np.argmax(gap[first_in:] >= 0))
    v_in = np.sqrt(v[first_in - 1] ** 2 + 2 * g * gap[first_in - 1])
    v_out = np.sqrt(v[first_out] ** 2 + 2 * g * gap[first_out])
    return float(v_out / v_in)


@pytest.mark.parametrize("method", ["Euler", "RK4"])
def test_ball_bounce_restitution(method):
    """A ball (r = 0.05 m) dropped from 1 m onto a floor with e = 0.8 at h = 1/1000 s.

    The contact spring-damper is tuned to e = 0.8 in continuous time; two discrete errors
    remain. The contact is detected at the first step start inside the floor, up to one
    step of travel deep, and the spring returns the energy it finds stored there: at most
    (omega h)^2 = (pi / 10)^2 = 10% of the impact energy, 5% in speed; and the 10-step
    resolution of the contact adds O(omega h) to Euler. Tolerance 0.04 on the ratio
    (5% of 0.8). Measured: Euler 0.787, RK4 0.801.
    """
    model = particle(
        (0.0, 1.0, 0.0),
        radius=0.05,
        gravity=G,
        dimension=2,
        planes=[Plane(np.zeros(3), np.array([0.0, 1.0, 0.0]), restitution=0.8)],
    )
    h = 1e-3
    run = MujocoAdapter().simulate(make_case(model, 0.7, h, max_records=700), method, h)
    assert run.status == "ok"
    assert _rebound_ratio(run, 0.05, 9.81) == pytest.approx(0.8, abs=0.04)
    depth = 0.05 - run.x[:, 0, 1].min()
    # penetration ~ v t_c / pi = 4.3 m/s * 0.01 s / pi = 14 mm, less with damping
    assert 0.005 < depth < 0.015


def test_coulomb_friction_stops_a_sliding_particle():
    """A particle slides at 2 m/s on a floor with mu = 0.5 and e = 1: it decelerates at
    mu g and stops after v^2 / (2 mu g) = 0.4077 m. Semi-implicit Euler at h = 1e-3 s
    travels h v / 2 = 1 mm less; tolerance 2 mm."""
    model = particle(
        (0.0, 0.05, 0.0),
        (2.0, 0.0, 0.0),
        radius=0.05,
        gravity=G,
        planes=[Plane(np.zeros(3), np.array([0.0, 1.0, 0.0]), 1.0, 0.5)],
    )
    run = MujocoAdapter().simulate(make_case(model, 0.6, 1e-3, max_records=60), "Euler", 1e-3)
    assert run.x[-1, 0, 0] == pytest.approx(4.0 / (2 * 0.5 * 9.81), abs=2e-3)
    assert abs(run.v[-1, 0, 0]) < 1e-9


@pytest.mark.parametrize("stage_forces", [True, False])
def test_force_field_and_impulse_through_applied_forces(stage_forces):
    """A steady wind f = k (w - v) (k = 2 N s/m, w = 3 m/s along x) and an impulse of 2 N along
    y for 0.2 <= t < 0.5 s on a 1 kg particle, 1 s at h = 0.01 s.

    Wind: v = w (1 - exp(-k t)), x = w t - (w / k) (1 - exp(-k t)). With the callback, RK4
    is fourth order: (h k)^4 / 120 per unit time ~ 1e-10, tolerance 1e-8 m. Held through
    the stages the velocity-dependent wind force leaves RK4 first order: error ~ h = 0.01 m,
    tolerance 0.02 m. The wind also drags the y motion the impulse starts:
    v_y(0.5) = (F / k) (1 - exp(-0.3 k)), v_y(1) = v_y(0.5) exp(-0.5 k), up to one step's
    worth of impulse, F h = 0.02 m/s, depending on which stage times fall inside the window.
    """
    model = particle(
        (0.0, 0.0, 0.0),
        impulses=[(0, np.array([0.0, 2.0, 0.0]), 0.2, 0.5)],
        fields=[
            ForceField(
                "wind", {"direction": [1.0, 0.0, 0.0], "speed": 3.0, "gust": 0.0, "freq": 0.0, "k": 2.0}
            )
        ],
    )
    adapter = MujocoAdapter(stage_forces=stage_forces)
    run = adapter.simulate(make_case(model, 1.0, 0.01), "RK4", 0.01)
    t = run.t
    x_wind = 3.0 * t - 1.5 * (1.0 - np.exp(-2.0 * t))
    tol = 1e-8 if stage_forces else 0.02
    np.testing.assert_allclose(run.x[:, 0, 0], x_wind, rtol=0, atol=tol)
    assert run.v[-1, 0, 1] == pytest.approx((1.0 - np.exp(-0.6)) * np.exp(-1.0), abs=0.02)
    assert ("held constant" in run.message) is not stage_forces


@pytest.mark.parametrize("name", ["rope-pendulum", "hanging-cloth", "damped-oscillator"])
def test_a_scene_without_constraints_steps_the_same_bits_without_contact_and_solver(name):
    """MuJoCo C on the model of a scene without planes, written with contact and constraint
    disabled and with both on: the same qpos and qvel, bit for bit, for every integrator,
    stepped by ``mj_step`` itself."""
    from truestep.adapters.mujoco_adapter import INTEGRATORS, NEEDS_NO_CONSTRAINTS, mjcf

    model = load_case(CASES / f"{name}.toml").particles
    assert not model.planes
    for method in INTEGRATORS:
        states = []
        for lean in (True, False):
            xml, layout = mjcf(model, method, 0.002, only_what_it_needs=lean)
            assert (NEEDS_NO_CONSTRAINTS in xml) is lean
            m = mujoco.MjModel.from_xml_string(xml)
            d = mujoco.MjData(m)
            d.qpos[:] = model.x0[layout.free, : layout.dim].ravel()
            d.qvel[:] = model.v0[layout.free, : layout.dim].ravel()
            mujoco.mj_step(m, d, nstep=300)
            states.append((d.qpos.copy(), d.qvel.copy()))
        assert np.array_equal(states[0][0], states[1][0]) and np.array_equal(states[0][1], states[1][1]), (
            method
        )


def test_a_scene_with_a_plane_keeps_contact_and_constraints():
    from truestep.adapters.mujoco_adapter import NEEDS_NO_CONSTRAINTS, mjcf

    model = load_case(CASES / "bouncing-ball.toml").particles
    assert model.planes and NEEDS_NO_CONSTRAINTS not in mjcf(model, "Euler", 0.002)[0]


@pytest.mark.parametrize("name", ["bouncing-ball", "projectile-drag", "hanging-cloth", "triangle-impulse"])
def test_a_run_from_the_reused_model_is_the_run_of_a_model_compiled_afresh(name):
    """The adapter compiles a row's model once (``build(..., reuse=True)``): its runs after
    the first, and a run after a run of another scene and back, step the bits of a scene
    compiled afresh for the run (contact, a Python force, pinned particles, impulses)."""
    case = load_case(CASES / f"{name}.toml")
    adapter = MujocoAdapter()
    method, dt = "RK4", case.dts[0]
    fresh_adapter = MujocoAdapter()
    fresh_adapter.build = lambda c, m, h: build(c, m, h, reuse=False)  # type: ignore[method-assign]
    fresh = fresh_adapter.simulate(case, method, dt)
    other = load_case(CASES / "harmonic-oscillator.toml")
    runs = [adapter.simulate(case, method, dt), adapter.simulate(case, method, dt)]
    adapter.simulate(other, method, other.dts[0])
    runs.append(adapter.simulate(case, method, dt))
    first = build(case, method, case.steps_for(dt)[1], reuse=True)
    assert build(case, method, case.steps_for(dt)[1], reuse=True).model is first.model
    for run in runs:
        assert run.status == fresh.status == "ok"
        assert np.array_equal(run.x, fresh.x) and np.array_equal(run.v, fresh.v)
        assert np.array_equal(run.t, fresh.t) and run.message == fresh.message
