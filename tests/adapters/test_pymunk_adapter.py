"""The pymunk adapter against exact solutions and against the scheme its docstring states.

pymunk's step is semi-implicit Euler with the position update first:
``x_{n+1} = x_n + h v_n``, ``v_{n+1} = v_n + h a(x_{n+1})`` (see adapters/pymunk_adapter.py).
Every test runs the real engine.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from truestep.adapters.pymunk_adapter import PymunkAdapter
from truestep.cases.loader import CASE_DIR, load_case
from truestep.reference_impl import forces

pytestmark = pytest.mark.engine

G = 9.81


@pytest.fixture(scope="module")
def adapter() -> PymunkAdapter:
    return PymunkAdapter()


def write_case(tmp_path: Path, name: str, text: str):
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return load_case(path)


def test_free_fall_is_position_first_symplectic_euler(adapter, tmp_path):
    case = write_case(
        tmp_path,
        "free-fall",
        """
title = "free fall"
kind = "particles"
[scene]
dimension = 2
gravity = [0.0, -9.81, 0.0]
[[scene.particles]]
position = [[0.0, 10.0, 0.0]]
mass = 1.0
[run]
duration = 1.0
dt = [0.01]
""",
    )
    run = adapter.simulate(case, "default", 0.01)
    assert run.status == "ok" and run.steps == 100 and run.nfev == 100
    n = np.arange(101)
    h = 0.01
    t = n * h
    np.testing.assert_allclose(run.t, t, rtol=0, atol=1e-12)
    y, vy = run.x[:, 0, 1], run.v[:, 0, 1]
    # The map from rest gives y_n = y0 - g h^2 n (n - 1) / 2 and v_n = -g n h exactly (the
    # velocity-first variant would give n (n + 1) / 2); 1e-12 m covers the rounding of
    # 100 additions of numbers of size 10.
    np.testing.assert_allclose(y, 10.0 - G * h**2 * n * (n - 1) / 2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(vy, -G * n * h, rtol=0, atol=1e-12)
    # Against the exact 10 - g t^2 / 2 the position lags by exactly g t h / 2 (first order).
    lag = y - (10.0 - G * t**2 / 2)
    np.testing.assert_allclose(lag, G * t * h / 2, rtol=0, atol=1e-12)
    assert np.all(run.x[:, :, 2] == 0) and np.all(run.v[:, :, 2] == 0)
    # Energy of the read-back state, m v^2 / 2 + m g y, is not conserved by the scheme:
    # E_n - E_0 = m (g n h)^2 / 2 - m g^2 h^2 n (n - 1) / 2 = m g^2 h^2 n / 2 (m = 1 kg).
    np.testing.assert_allclose(run.energy - run.energy[0], G**2 * h**2 * n / 2, rtol=0, atol=1e-9)


def test_harmonic_oscillator_energy_bounded_and_first_order_phase(adapter):
    case = load_case(CASE_DIR / "harmonic-oscillator.toml")
    h, omega, x0 = 1e-3, 10.0, 0.1
    run = adapter.simulate(case, "default", h)
    assert run.status == "ok" and run.steps == 2000
    e = run.energy
    drift = np.max(np.abs(e - e[0])) / e[0]
    # The scheme keeps H~ = E - m omega^2 h x v / 2 exactly (v0 = 0, so H~ = E0), and
    # omega |x v| <= E; hence |E - E0| / E0 <= (omega h / 2) / (1 - omega h / 2) = 0.005025.
    bound = (omega * h / 2) / (1 - omega * h / 2)
    assert drift <= bound * (1 + 1e-9)
    assert drift < 0.02  # the brief's looser bar: about omega h / 2 at most
    # The discrete solution from rest: x_n = x0 cos(theta (n - 1/2)) / cos(theta / 2),
    # cos(theta) = 1 - omega^2 h^2 / 2 (x_1 = x_0: the first step moves nothing).
    theta = math.acos(1 - (omega * h) ** 2 / 2)
    n = np.round(run.t / h)
    np.testing.assert_allclose(
        run.x[:, 0, 0], x0 * np.cos(theta * (n - 0.5)) / math.cos(theta / 2), rtol=0, atol=1e-11
    )  # rounding over 2000 steps
    # Against the exact 0.1 cos(10 t) at t = 2 s: the half-step phase lag is the first-order
    # error, x0 (cos(omega t - omega h / 2) - cos(omega t)) = 4.56e-4 m; the second-order
    # terms (phase drift omega^3 h^2 t / 24, amplitude omega^2 h^2 / 8) bound the rest.
    t = run.t[-1]
    error = run.x[-1, 0, 0] - x0 * math.cos(omega * t)
    predicted = x0 * (math.cos(omega * t - omega * h / 2) - math.cos(omega * t))
    second_order = x0 * (omega**3 * h**2 * t / 24 + omega**2 * h**2 / 8)
    assert abs(error - predicted) <= second_order
    print(
        f"pymunk oscillator h={h}: x(2)-exact={error:.3e}, predicted {predicted:.3e}, "
        f"max |E-E0|/E0={drift:.5f}"
    )


BALL = """
title = "ball"
kind = "particles"
[scene]
dimension = 2
gravity = [0.0, -9.81, 0.0]
[[scene.particles]]
position = [[0.0, 1.0, 0.0]]
mass = 1.0
radius = 0.05
[[scene.planes]]
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
restitution = 0.8
[run]
duration = 1.0
dt = [1e-3]
"""


def test_ball_rebound_ratio(adapter, tmp_path):
    case = write_case(tmp_path, "ball", BALL)
    h, e, r = 1e-3, 0.8, 0.05
    run = adapter.simulate(case, "default", h)
    assert run.status == "ok" and len(run.t) == 1001  # every step recorded
    vy, y = run.v[:, 0, 1], run.x[:, 0, 1]
    k = int(np.argmax(vy > 0))
    assert k > 0
    ratio = vy[k] / -vy[k - 1]
    print(
        f"pymunk first rebound at t={run.t[k]:.3f} s: v- = {vy[k - 1]:.4f}, "
        f"v+ = {vy[k]:.4f}, ratio {ratio:.12f}"
    )
    # Chipmunk's bounce target is -e times the normal velocity at the start of the contact
    # step, and one contact with a static plane is solved exactly in the first sweep: the
    # ratio of consecutive recorded velocities is e to rounding.
    assert abs(ratio - e) < 1e-9
    # Against the continuous bounce e sqrt(2 g (1 - r)): the recorded pre-contact speed is
    # g (k - 1) h exactly and contact is found within h/2 + h of the exact contact time, so
    # the rebound is off by at most e g h (1.5 for the half-step lag of the position).
    v_exact = e * math.sqrt(2 * G * (1.0 - r))
    assert abs(vy[k] - v_exact) <= 1.5 * e * G * h
    # The deepest penetration is at most one step's travel at the impact speed.
    assert np.min(y - r) >= -math.sqrt(2 * G * (1.0 - r)) * h - 1e-12


def test_3d_scene_is_unsupported(adapter, tmp_path):
    case = write_case(
        tmp_path,
        "fall-3d",
        """
title = "3-D fall"
kind = "particles"
[scene]
dimension = 3
gravity = [0.0, -9.81, 0.0]
[[scene.particles]]
position = [[0.0, 1.0, 0.5]]
mass = 1.0
[run]
duration = 1.0
dt = [0.01]
""",
    )
    assert adapter.missing(case, "default") == {"3d"}


def test_spring_damper_is_integrated_exactly(adapter, tmp_path):
    # A pure damper (stiffness 0) on an anchored spring: m v' = -c v, v = v0 exp(-c t / m).
    # pymunk multiplies the velocity along the spring by exp(-c h / m) each step, which is
    # that solution at every step (rounding only), unlike the lecture's explicit force.
    case = write_case(
        tmp_path,
        "damper",
        """
title = "damper"
kind = "particles"
[scene]
dimension = 2
[[scene.particles]]
position = [[0.0, 0.0, 0.0]]
velocity = [[1.0, 0.0, 0.0]]
mass = 2.0
[[scene.anchors]]
particle = 0
point = [-1.0, 0.0, 0.0]
stiffness = 0.0
damping = 3.0
rest = 1.0
[run]
duration = 1.0
dt = [0.01]
""",
    )
    run = adapter.simulate(case, "default", 0.01)
    np.testing.assert_allclose(run.v[:, 0, 0], np.exp(-3.0 * run.t / 2.0), rtol=1e-12, atol=0)


def test_per_step_forces_follow_the_stated_scheme(adapter, tmp_path):
    # Drag, gravitation, a vortex and an impulse are evaluated at x_n + h v_n, v_n and t_n;
    # the engine then steps x_{n+1} = x_n + h v_n, v_{n+1} = v_n + h (g + f / m).
    case = write_case(
        tmp_path,
        "forced",
        """
title = "forced"
kind = "particles"
[scene]
dimension = 2
gravity = [0.0, -1.0, 0.0]
drag = 0.1
[[scene.particles]]
position = [[0.0, 0.0, 0.0], [1.0, 0.5, 0.0]]
velocity = [[0.0, 0.3, 0.0], [-0.2, 0.0, 0.0]]
mass = [1.0, 2.0]
[scene.gravitation]
G = 1.0
softening = 0.1
[[scene.fields]]
kind = "vortex"
center = [0.5, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
strength = 0.7
core = 0.4
[[scene.impulses]]
particle = 0
start = 0.0
end = 0.1
force = [1.0, 0.5, 0.0]
[run]
duration = 0.5
dt = [0.01]
""",
    )
    run = adapter.simulate(case, "default", 0.01)
    m = case.model
    h = 0.01
    x, v = m.x0.copy(), m.v0.copy()
    for n in range(50):
        t = n * h
        x_next = x + h * v
        f = np.zeros_like(x)
        forces.add_drag(f, v, m.drag)
        forces.add_gravitation(f, x_next, m.mass, m.gravitation)
        forces.add_fields(f, m.fields, x_next, v, m.mass, t)
        if t < 0.1:
            f[0] += m.impulses[0][1]
        x, v = x_next, v + h * (m.gravity + f / m.mass[:, None])
        # 1e-12: the engine sums the same terms in its own order; nothing else differs.
        np.testing.assert_allclose(run.x[n + 1], x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(run.v[n + 1], v, rtol=0, atol=1e-12)


def test_pinned_particle_acts_as_an_anchor(adapter, tmp_path):
    scene = """
title = "hang"
kind = "particles"
[scene]
dimension = 2
gravity = [0.0, -9.81, 0.0]
[[scene.particles]]
position = [[0.0, 0.0, 0.0]]
mass = 0.5
{extra}
[run]
duration = 1.0
dt = [0.005]
"""
    pinned = write_case(
        tmp_path,
        "pinned",
        scene.format(
            extra="""
[[scene.particles]]
position = [[0.0, 1.0, 0.0]]
mass = 1.0
fixed = true
[[scene.springs]]
pairs = [[0, 1]]
stiffness = 50.0
damping = 0.5
rest = 0.8
"""
        ),
    )
    anchored = write_case(
        tmp_path,
        "anchored",
        scene.format(
            extra="""
[[scene.anchors]]
particle = 0
point = [0.0, 1.0, 0.0]
stiffness = 50.0
damping = 0.5
rest = 0.8
"""
        ),
    )
    a = adapter.simulate(pinned, "default", 0.005)
    b = adapter.simulate(anchored, "default", 0.005)
    assert {"pinned-particles", "springs"} <= pinned.features
    # A kinematic body at rest and the static anchor are the same to the spring (rounding).
    np.testing.assert_allclose(a.x[:, 0], b.x[:, 0], rtol=0, atol=1e-12)
    assert np.all(a.x[:, 1] == [0.0, 1.0, 0.0]) and np.all(a.v[:, 1] == 0.0)


def test_coulomb_friction_decelerates_at_mu_g(adapter, tmp_path):
    case = write_case(
        tmp_path,
        "slide",
        """
title = "slide"
kind = "particles"
[scene]
dimension = 2
gravity = [0.0, -9.81, 0.0]
[[scene.particles]]
position = [[0.0, 0.05, 0.0]]
velocity = [[2.0, 0.0, 0.0]]
mass = 1.0
radius = 0.05
[[scene.planes]]
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
restitution = 0.0
friction = 0.5
[run]
duration = 0.6
dt = [1e-3]
""",
    )
    run = adapter.simulate(case, "default", 1e-3)
    vx = run.v[:, 0, 0]
    # Resting contact: the normal impulse per step is m g h, friction takes mu m g h of the
    # tangential momentum, so v_x falls at mu g = 4.905 m/s^2 (rounding) once in contact...
    decel = (vx[100] - vx[300]) / (run.t[300] - run.t[100])
    assert abs(decel - 0.5 * G) < 1e-9
    # ...and stops, within two steps of the exact 2 / (mu g) = 0.4077 s, without reversing.
    t_stop = run.t[int(np.argmax(vx <= 0.0))]
    assert abs(t_stop - 2.0 / (0.5 * G)) <= 2e-3
    assert np.all(vx >= 0.0)


def test_blow_up_is_reported_unstable(adapter, tmp_path):
    # omega h = 10 * 0.5 = 5 > 2: the scheme's oscillator is unstable.
    case = write_case(
        tmp_path,
        "unstable",
        """
title = "unstable"
kind = "particles"
[scene]
dimension = 2
[[scene.particles]]
position = [[0.1, 0.0, 0.0]]
mass = 1.0
[[scene.anchors]]
particle = 0
point = [-1.0, 0.0, 0.0]
stiffness = 100.0
rest = 1.0
[run]
duration = 200.0
dt = [0.5]
""",
    )
    run = adapter.simulate(case, "default", 0.5)
    assert run.status == "unstable"
    assert run.t_fail is not None and 0.0 < run.t_fail <= 200.0
    assert run.steps < 400  # stopped at the blow-up
