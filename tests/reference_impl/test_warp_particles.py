"""The reference's device kernel (:mod:`truestep.reference_impl.warp_particles`) on Warp's CPU
device gives the compiled path's records bit for bit: every library scene it models, both
of its methods, and a box of particles that exercises what those scenes do not (six planes,
friction on two of them, three dimensions, particles resting from the first step). What it does not
model it refuses, saying why; a run in which a particle runs away is the CPU's run."""

from __future__ import annotations

import numpy as np
import pytest

from truestep.api import select_cases
from truestep.reference_impl.compiled import run_compiled
from truestep.reference_impl.model import ParticleModel, Plane

pytest.importorskip("warp")

from truestep.adapters import warp_runtime
from truestep.reference_impl import warp_particles

METHODS = tuple(warp_particles.KICK_DRIFT)


@pytest.fixture(scope="module", autouse=True)
def warp_started():
    warp_runtime.start()


def _same_run(model: ParticleModel, method: str, h: float, n_steps: int, max_records: int) -> None:
    on_device = warp_particles.run(model, method, h, n_steps, device="cpu", max_records=max_records)
    compiled, _ = run_compiled(model, method, n_steps * h, h, max_records=max_records)
    assert compiled.status == "ok" and on_device.blew_up is None
    assert (on_device.steps, on_device.nfev) == (compiled.steps, compiled.nfev)
    assert np.array_equal(on_device.t, compiled.t)
    assert np.array_equal(on_device.x, compiled.x) and np.array_equal(on_device.v, compiled.v)


def _modelled() -> list:
    return [
        pytest.param(case, method, id=f"{case.name}-{method}")
        for case in select_cases(["*"])
        for method in METHODS
        if warp_particles.device_reason(case.model, method) is None
    ]


@pytest.mark.parametrize(("case", "method"), _modelled())
def test_every_library_scene_it_models_gives_the_compiled_records_bit_for_bit(case, method):
    n_steps, h = case.steps_for(max(case.dts))
    _same_run(case.particles, method, h, n_steps, case.max_records)


def test_the_library_scenes_it_models_cover_contact_friction_drag_and_thin_walls():
    features = {f for case, _ in (p.values for p in _modelled()) for f in case.features}
    assert {"planes", "friction", "drag", "thin-walls", "uniform-gravity"} <= {str(f) for f in features}
    assert any(case.particles.n >= 1000 for case, _ in (p.values for p in _modelled()))


def _box(n: int = 200, seed: int = 3) -> ParticleModel:
    """Particles in a closed 3D box: a floor with friction, four walls (one a thin wall, one
    with friction), a ceiling; gravity (the force kinds and plane count of the figure case
    ``particle-in-a-box``, whose compiled loop the suite has made); a tenth of them start
    at rest on the floor."""
    rng = np.random.default_rng(seed)
    radius = np.full(n, 0.02)
    x0 = rng.uniform([-0.9, 0.02, -0.9], [0.9, 1.5, 0.9], (n, 3))
    v0 = rng.normal(0.0, 2.0, (n, 3))
    x0[: n // 10, 1] = radius[: n // 10]
    v0[: n // 10] = 0.0
    planes = [
        Plane(np.array([0.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), restitution=0.4, friction=0.3),
        Plane(np.array([-1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), restitution=0.8),
        Plane(np.array([1.0, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0]), restitution=0.8, thickness=0.05),
        Plane(np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 1.0]), restitution=0.9, friction=0.1),
        Plane(np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0]), restitution=0.9),
        Plane(np.array([0.0, 2.0, 0.0]), np.array([0.0, -1.0, 0.0]), restitution=1.0),
    ]
    return ParticleModel(
        mass=rng.uniform(0.01, 0.1, n),
        x0=x0,
        v0=v0,
        radius=radius,
        fixed=np.zeros(n, bool),
        gravity=np.array([0.0, -9.81, 0.0]),
        planes=planes,
    )


@pytest.mark.parametrize("method", METHODS)
def test_a_box_of_six_planes_with_friction_and_resting_particles_is_the_compiled_run(method):
    model = _box()
    _same_run(model, method, 2e-3, 750, 40)
    on_device = warp_particles.run(model, method, 2e-3, 750, device="cpu", max_records=40)
    resting = np.abs(on_device.x[-1, :, 1] - model.radius) < 1e-9
    assert resting.sum() >= 10  # particles came to rest on the floor: the contact pass ran


@pytest.mark.parametrize(
    ("case", "method", "said"),
    [
        ("hanging-cloth", "lecture", "springs"),
        ("kepler-orbit", "lecture", "an ODE case"),
        ("particle-fountain", "lecture", "emitters"),
        ("particle-rain", "rk4", "lecture and symplectic-euler only"),
    ],
)
def test_what_it_does_not_model_is_refused_saying_why(case, method, said):
    model = select_cases([case])[0].model
    assert said in (warp_particles.device_reason(model, method) or "")
    if model is not None:
        with pytest.raises(ValueError, match=said):
            warp_particles.run(model, method, 1e-3, 10, device="cpu")


def test_a_run_in_which_a_particle_runs_away_says_where_and_the_adapter_gives_the_cpu_run():
    """Drag that overshoots (``k h / m`` of 5): the velocity grows fourfold a step. The
    kernel stops that particle's thread at the check that finds it; the reference adapter
    on a device then gives the CPU's run of the same steps, saying so."""
    from dataclasses import replace

    from truestep.adapters.reference import ReferenceAdapter

    case = select_cases(["projectile-drag"])[0]
    model = replace(case.particles, drag=float(case.particles.mass[0]) * 5.0 / 0.1)
    run = warp_particles.run(model, "lecture", 0.1, 30, device="cpu")
    assert run.blew_up is not None and 0 < run.blew_up <= 30
    on_cpu = ReferenceAdapter()
    on_device = ReferenceAdapter()
    on_device.device = "cpu"  # Warp's CPU device, through the adapter's device path
    scene = replace(case, scene=model, duration=3.0)
    cpu_run = on_cpu.simulate(scene, "lecture", 0.1)
    device_run = on_device._simulate_on_device(scene, "lecture", 0.1)
    assert cpu_run.status == device_run.status == "unstable" and cpu_run.t_fail == device_run.t_fail
    assert np.array_equal(cpu_run.x, device_run.x, equal_nan=True)
    assert "ran away" in device_run.message and "the CPU's run" in device_run.message


def test_the_adapter_s_device_run_is_the_cpu_row_bit_for_bit_and_names_its_path():
    from truestep.adapters.reference import ReferenceAdapter

    case = select_cases(["sliding-contact"])[0]
    on_device = ReferenceAdapter()
    on_device.device = "cpu"  # Warp's CPU device, through the adapter's device path
    warped = on_device._simulate_on_device(case, "lecture", 0.005)
    compiled = ReferenceAdapter().simulate(case, "lecture", 0.005)
    assert (warped.path, compiled.path) == ("warp", "compiled")
    assert np.array_equal(warped.x, compiled.x) and np.array_equal(warped.energy, compiled.energy)
    assert (warped.status, warped.steps, warped.nfev) == (compiled.status, compiled.steps, compiled.nfev)
