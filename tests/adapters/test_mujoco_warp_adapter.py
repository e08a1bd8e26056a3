"""The MuJoCo Warp adapter (real MuJoCo Warp, on Warp's CPU device) against MuJoCo C on
the same MJCF, at float32's tolerance, and against motions whose answer is known."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("mujoco_warp", reason='MuJoCo Warp is not installed: pip install "truestep[mujoco-warp]"')

from truestep.adapters import get_adapter
from truestep.adapters.base import Adapter
from truestep.adapters.mujoco_adapter import INTEGRATORS, MujocoAdapter
from truestep.adapters.mujoco_warp_adapter import (
    MAX_CPU_PARTICLES,
    MujocoWarpAdapter,
    build,
    mjw,
    remember_versions,
    wp,
)
from truestep.execution.analyses import _bounce_rows
from truestep.execution.runner import measure, plan
from truestep.measures.metrics import ROUND_OFF, ROUND_OFF_FLOAT32, fit_order, round_off_floor

pytestmark = pytest.mark.engine

FLOAT32 = 1e-5
"""Largest gap between MuJoCo Warp's and MuJoCo C's positions on a smooth scene, as a
fraction of the scene's size: float32 keeps 7 digits, and a few thousand steps round
each time (measured: 3e-6 on rope-pendulum, 1e-6 on the oscillator)."""


@pytest.fixture(scope="module")
def warp_mj() -> MujocoWarpAdapter:
    return MujocoWarpAdapter()


def _short(case, duration: float):
    return dataclasses.replace(case, duration=duration)


def test_it_is_an_adapter_registered_by_its_entry_point(warp_mj):
    assert isinstance(warp_mj, Adapter)
    assert isinstance(get_adapter("mujoco-warp"), MujocoWarpAdapter)
    assert warp_mj.methods == tuple(INTEGRATORS) == MujocoAdapter.methods
    assert warp_mj.method_facts == MujocoAdapter.method_facts
    assert warp_mj.precision == "float32" and round_off_floor("mujoco-warp") == ROUND_OFF_FLOAT32
    assert round_off_floor("mujoco") == ROUND_OFF


@pytest.mark.parametrize(
    ("name", "method", "dt", "duration"),
    [
        ("harmonic-oscillator", "Euler", 1e-3, 2.0),
        ("harmonic-oscillator", "RK4", 1e-3, 2.0),
        ("spring-damper-pair", "implicit", 0.01, 1.0),
        ("rope-pendulum", "RK4", 2e-3, 1.5),
        ("hanging-cloth", "implicitfast", 4e-3, 0.5),
    ],
)
def test_it_moves_as_mujoco_c_does_to_float32_precision(warp_mj, case_named, name, method, dt, duration):
    """The same model, integrator and step in both: positions agree to float32 rounding."""
    case = _short(case_named(name), duration)
    mine, theirs = warp_mj.simulate(case, method, dt), MujocoAdapter().simulate(case, method, dt)
    assert mine.status == theirs.status == "ok"
    assert mine.steps == theirs.steps
    np.testing.assert_allclose(mine.t, theirs.t, rtol=1e-12)
    size = float(np.ptp(theirs.x, axis=(0, 1)).max())
    assert np.abs(mine.x - theirs.x).max() <= FLOAT32 * size
    assert np.abs(mine.x - theirs.x).max() > 0, "float32 rounds somewhere: the engines are distinct"


@pytest.mark.parametrize("method", ["Euler", "RK4"])
def test_its_bounces_keep_mujoco_c_s_restitution(method):
    """The restitution analysis's own rows: the first bounce's rebound ratio equals MuJoCo
    C's to 1e-3. Later ones differ by up to 0.02 (measured 0.013, Euler's third): the
    ball meets the floor at another phase of a step once float32 has moved its flight by
    a rounding, and MuJoCo's contact starts at a step (module docstring of the MuJoCo
    adapter). All within 0.03 of the 0.8 asked, as MuJoCo C's are."""
    mine, theirs = _bounce_rows("mujoco-warp", method, 0.8, 1e-3), _bounce_rows("mujoco", method, 0.8, 1e-3)
    assert [r["status"] for r in mine] == ["ok"] * 3
    assert abs(mine[0]["e_measured"] - theirs[0]["e_measured"]) < 1e-3
    for a, b in zip(mine, theirs, strict=True):
        assert abs(a["e_measured"] - b["e_measured"]) < 0.02
        assert abs(a["e_measured"] - 0.8) < 0.03


def test_the_captured_graph_steps_as_plain_calls_do_bit_for_bit(case_named):
    """The graph launched k times and ``mujoco_warp.step`` called k times from the same
    state end in the same bits."""
    case = case_named("spring-damper-pair")
    graphed, plain = build(case, "RK4", 0.01), build(case, "RK4", 0.01)
    for _ in range(25):
        wp.capture_launch(graphed.graph)
        mjw.step(plain.model, plain.data)
    assert np.array_equal(graphed.data.qpos.numpy(), plain.data.qpos.numpy())
    assert np.array_equal(graphed.data.qvel.numpy(), plain.data.qvel.numpy())
    assert not np.array_equal(graphed.data.qpos.numpy(), build(case, "RK4", 0.01).data.qpos.numpy())


@pytest.mark.parametrize("name", ["spring-chain", "hanging-cloth", "bouncing-ball"])
def test_a_run_after_a_run_at_another_step_is_the_run_of_a_scene_built_afresh(warp_mj, case_named, name):
    """A sweep's runs reuse the scene built for its first step where the model differs by
    its step alone (no contact): each run at the second step, after one at the first (the
    same scene, reset), ends in the bits of a run whose scene was built afresh; a scene
    with plane contacts (its step in their solref) is built afresh."""
    from truestep.adapters import mujoco_warp_adapter as module

    case = _short(case_named(name), 0.3)
    for method in INTEGRATORS:
        h1, h2 = case.sweep(adaptive=False, quick=False)[:2]
        module._LAST.clear()
        warp_mj.simulate(case, method, h1)
        first = module._LAST["scene"].data
        after = warp_mj.simulate(case, method, h2)
        assert (module._LAST["scene"].data is first) == (name != "bouncing-ball")
        module._LAST.clear()
        afresh = warp_mj.simulate(case, method, h2)
        assert after.status == afresh.status == "ok"
        for a, b in ((after.t, afresh.t), (after.x, afresh.x), (after.v, afresh.v)):
            assert np.array_equal(a, b), (name, method)


def test_a_snapshot_is_the_state_of_its_step_and_stays_so(warp_mj, case_named):
    """On the CPU the state is read through views of the device's memory made once: a
    snapshot equals Warp's own ``numpy()`` copy at its step, and later steps leave it as it
    was (it is a copy, not the view)."""
    case = case_named("spring-damper-pair")
    scene = warp_mj.build(case, "RK4", 0.01)
    assert all(v is not None for v in scene.views)
    wp.capture_launch(scene.graph)
    snap = warp_mj.snapshot(scene)
    assert np.array_equal(snap[0], scene.data.qpos.numpy())
    assert np.array_equal(snap[1], scene.data.qvel.numpy())
    before = (snap[0].copy(), snap[1].copy())
    wp.capture_launch(scene.graph)
    assert np.array_equal(snap[0], before[0]) and np.array_equal(snap[1], before[1])
    assert not np.array_equal(warp_mj.snapshot(scene)[0], before[0])


def test_a_free_fall_is_semi_implicit_euler_in_float32(warp_mj, case_named):
    """``Euler`` without damping: ``y_n = y_0 + v_0 n h - g h^2 n (n + 1) / 2`` (the closed
    form of the velocity-first step), to float32's rounding of the height."""
    case = case_named("free-fall")
    h = case.dts[0]
    traj = warp_mj.simulate(case, "Euler", h)
    n = np.rint(traj.t / h)
    m = case.particles
    g = -m.gravity[2]
    expected = m.x0[0, 2] + m.v0[0, 2] * n * h - g * h**2 * n * (n + 1) / 2
    assert np.abs(traj.x[:, 0, 2] - expected).max() <= 1e-6 * max(1.0, np.abs(expected).max())


def test_the_float32_stall_is_not_fitted_as_an_order(warp_mj, case_named):
    """RK4 on the oscillator: float32 rounding, not the scheme, sets the error at small
    steps (the reference's RK4 is 1000 times more accurate there). The float64 round-off
    floor would fit that plateau as an order near 0; the float32 floor leaves it out."""
    case = _short(case_named("harmonic-oscillator"), 2.0)
    dts = np.array([2e-3, 1e-3, 5e-4])
    errors = np.array([measure(case, warp_mj.simulate(case, "RK4", h))["error"] for h in dts])
    reference = get_adapter("reference")
    exact = np.array([measure(case, reference.simulate(case, "rk4", h))["error"] for h in dts])
    assert np.all(errors > 50 * exact) and errors[-1] > 1e4 * exact[-1]
    assert fit_order(dts, errors, scale=case.error_scale) < 2
    assert np.isnan(fit_order(dts, errors, scale=case.error_scale, floor=ROUND_OFF_FLOAT32))


def test_forces_without_an_mjcf_element_are_unsupported_with_the_reason(case_named):
    rows = list(plan(case_named("earth-orbit"), "mujoco-warp", quick=True))
    assert rows and all(why == "unsupported:universal-gravitation" for *_, why in rows)
    from truestep.execution.runner import unsupported_message

    assert "passive-force callback" in unsupported_message("mujoco-warp", "universal-gravitation")


def test_a_scene_over_the_cpu_bound_is_a_skipped_row_that_says_why(case_named, monkeypatch):
    from truestep.adapters import warp_runtime

    monkeypatch.setattr(warp_runtime, "_GPU_WANTED", [])  # the GPU adapter made below: this test's
    case = case_named("particle-rain")
    assert case.particles.n > MAX_CPU_PARTICLES
    rows = list(plan(case, "mujoco-warp", quick=True))
    assert rows and all(why.startswith("skipped:") and "device='cuda:0'" in why for *_, why in rows)
    assert MujocoWarpAdapter(device="cuda:0").skip(case, "Euler") is None


def test_a_blow_up_is_unstable_at_its_time(warp_mj, case_named):
    """Semi-implicit Euler on the oscillator diverges for h omega > 2 (here 5): float32
    overflows, and the run stops at the first check that reads a state past the blow-up
    bound (MuJoCo Warp has no autoreset to hide it)."""
    case = dataclasses.replace(case_named("harmonic-oscillator"), duration=100.0)
    traj = warp_mj.simulate(case, "Euler", 0.5)
    assert traj.status == "unstable"
    assert traj.t_fail is not None and 0 < traj.t_fail <= 100.0
    assert not np.any(np.abs(traj.x[1:, 0, 0]) <= 0.1), "never back at the start: no reset"


def test_the_row_says_float32_on_the_cpu(warp_mj, case_named):
    traj = warp_mj.simulate(_short(case_named("harmonic-oscillator"), 0.1), "Euler", 1e-3)
    assert "float32" in traj.message and "no speed claim" in traj.message


@pytest.mark.skipif(
    wp.get_cuda_device_count() == 0, reason="no CUDA device: the GPU path runs only where one exists"
)
def test_on_a_gpu_it_moves_as_on_the_cpu(case_named):
    """The GPU path (docs: "On a GPU"): the same scene on ``cuda:0`` agrees with the CPU
    device to float32 rounding."""
    case = _short(case_named("harmonic-oscillator"), 1.0)
    cpu = MujocoWarpAdapter().simulate(case, "RK4", 1e-3)
    gpu = MujocoWarpAdapter(device="cuda:0").simulate(case, "RK4", 1e-3)
    assert gpu.status == "ok" and "cuda:0" in gpu.message
    assert np.abs(gpu.x - cpu.x).max() <= FLOAT32 * 0.2


def test_its_implicit_is_c_s_implicitfast_on_a_cloth(warp_mj, case_named):
    """On the hanging cloth MuJoCo C's ``implicit`` and ``implicitfast`` part (their damping
    derivatives differ on its tendons); MuJoCo Warp 4.0.0's ``implicit`` moves as C's
    ``implicitfast`` does, to float32 rounding, and far from C's ``implicit``."""
    case = _short(case_named("hanging-cloth"), 0.5)
    mine = warp_mj.simulate(case, "implicit", 4e-3)
    fast, full = (
        MujocoAdapter().simulate(case, "implicitfast", 4e-3),
        MujocoAdapter().simulate(case, "implicit", 4e-3),
    )
    size = float(np.ptp(fast.x, axis=(0, 1)).max())
    assert np.abs(mine.x - fast.x).max() <= FLOAT32 * size
    assert np.abs(mine.x - full.x).max() > 100 * FLOAT32 * size


def test_on_the_cpu_its_rows_run_once_untimed_and_say_so(case_named):
    """MuJoCo Warp on Warp's CPU device makes no speed claim: its sweep is the measured run
    alone (repeats 0), its numbers those of a timed sweep; Newton's rows stay timed."""
    from truestep.execution.runner import QUICK_TIMING, UNTIMED, makes_speed_claim, simulate_timed

    assert not makes_speed_claim(get_adapter("mujoco-warp"))
    assert makes_speed_claim(get_adapter("newton")) and makes_speed_claim(get_adapter("reference"))
    case = case_named("harmonic-oscillator")
    once = simulate_timed("mujoco-warp", case, "Euler", case.quick_dts[0], UNTIMED)
    timed = simulate_timed("mujoco-warp", case, "Euler", case.quick_dts[0], QUICK_TIMING)
    assert int(once.extra["repeats"]) == 0 and int(timed.extra["repeats"]) == 1
    assert once.wall_s > 0 and np.array_equal(once.x, timed.x)
    assert "no speed claim" in once.message


@pytest.mark.parametrize("name", ["rope-pendulum", "hanging-cloth", "damped-oscillator", "bouncing-ball"])
def test_the_lean_model_steps_the_same_bits_as_the_whole_one(case_named, name, monkeypatch):
    """A scene without planes is written with contact and constraint disabled
    (:data:`~truestep.adapters.mujoco_adapter.NEEDS_NO_CONSTRAINTS`), and every scene
    without MuJoCo's energy and sensor stages: every integrator's steps equal those of the
    model with every stage on, bit for bit (the ball on its plane: only the energy and
    sensor stages differ)."""
    from truestep.adapters import mujoco_adapter as mj

    case = case_named(name)
    plain_mjcf = mj.mjcf
    whole = {"only_what_it_needs": False, "energy": True, "sensors": True}
    for method in INTEGRATORS:
        lean = build(case, method, 0.002)
        monkeypatch.setattr(mj, "mjcf", lambda *a, **k: plain_mjcf(*a, **{**k, **whole}))
        full = build(case, method, 0.002)
        monkeypatch.setattr(mj, "mjcf", plain_mjcf)
        assert lean.model.opt.disableflags != full.model.opt.disableflags
        for _ in range(40):
            wp.capture_launch(lean.graph)
            wp.capture_launch(full.graph)
        for a, b in ((lean.data.qpos, full.data.qpos), (lean.data.qvel, full.data.qvel)):
            assert np.array_equal(a.numpy(), b.numpy()), method


def test_package_versions_are_looked_up_once_and_answer_as_before():
    """MuJoCo Warp's version checks (four a scene build) keep their answers for the
    process (:func:`remember_versions`): the same answers as a fresh lookup."""
    from mujoco_warp._src import util_pkg

    assert remember_versions()
    check = util_pkg.check_version
    assert hasattr(check, "cache_info") and remember_versions()  # applied once, not wrapped again
    assert not hasattr(check.__wrapped__, "cache_info")
    for spec in ("mujoco>=3.0", "mujoco>=999.0", "numpy!=0.0.1", "warp-lang>=1.0"):
        assert check(spec) == check.__wrapped__(spec)
