"""Emitters (spawning, lifetimes, the pool, attributes) and static particles (strands)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from truestep.adapters.reference import ReferenceAdapter
from truestep.cases import CaseError, load_case
from truestep.measures.properties import PROPERTIES
from truestep.reference_impl.emitters import Emitter, emitter_area, spawn_count_moments
from truestep.reference_impl.integrate import integrate
from truestep.reference_impl.model import EmitterSpec, ParticleModel
from truestep.reference_impl.particles import ParticleSystem
from truestep.reference_impl.passes import passes_for
from truestep.reference_impl.solvers import get_solver
from truestep.reference_impl.strands import ballistic_deviation, collect_strands


def pool_system(spec: EmitterSpec, gravity=(0.0, 0.0, 0.0)) -> tuple[ParticleSystem, Emitter]:
    n = spec.capacity
    model = ParticleModel(
        mass=np.full(n, spec.particle_mass),
        x0=np.zeros((n, 3)),
        v0=np.zeros((n, 3)),
        radius=np.zeros(n),
        fixed=np.zeros(n, bool),
        gravity=np.array(gravity),
        emitters=[spec],
    )
    passes = passes_for(model)
    return ParticleSystem(model, passes), passes[0]


def spec(**kw) -> EmitterSpec:
    base = dict(
        shape="cube",
        center=np.zeros(3),
        size=0.5,
        rate_n=7.0,
        rate_r=5.0,
        speed=1.0,
        spread=0.3,
        lifetime=10,
        lifetime_jitter=3,
        capacity=400,
        seed=1,
    )
    base.update(kw)
    return EmitterSpec(**base)


@pytest.mark.parametrize("per_area", [False, True])
def test_spawn_counts_match_n_plus_r_over_2(per_area):
    s = spec(per_area=per_area, rate_n=5.0 if per_area else 7.3, rate_r=4.5)
    system, emitter = pool_system(s)
    frames = 3000
    for _ in range(frames - 1):
        emitter.begin_frame(system)
    counts = np.array(emitter.spawned)
    n = s.rate_n * (emitter_area(s) if per_area else 1.0)
    mean, var = spawn_count_moments(n, s.rate_r)
    assert mean == pytest.approx(n + s.rate_r / 2)
    # The mean of 3000 independent counts lies within 3 standard errors of n + r/2.
    assert abs(counts.mean() - mean) < 3 * np.sqrt(var / frames)
    # Their variance estimates var = r^2/12 + E[f(1-f)] to about sqrt(2/F) ~ 3 %.
    assert counts.var() == pytest.approx(var, rel=0.1)
    assert emitter.dropped == 0


def test_a_particle_is_removed_on_the_frame_its_lifetime_reaches_zero():
    s = spec(rate_n=1.0, rate_r=0.0, lifetime=3, lifetime_jitter=0, capacity=10)
    system, emitter = pool_system(s)
    first = np.flatnonzero(system.alive)
    assert len(first) == 1  # frame 0: one particle, lifetime 3
    slot = first[0]
    history = []
    for _ in range(4):
        emitter.begin_frame(system)  # frames 1, 2, 3, 4
        history.append(bool(system.alive[slot]))
    # Lifetime 3 -> 2 (frame 1) -> 1 (frame 2) -> 0 (frame 3): removed at frame 3.
    assert history == [True, True, False, False]
    assert emitter.removed == [0, 0, 0, 1, 1]
    assert emitter.population == [1, 2, 3, 3, 3]


def test_frames_span_solver_steps_and_spawn_on_boundaries():
    s = spec(rate_n=2.0, rate_r=0.0, frame_dt=0.1, lifetime=100, lifetime_jitter=0)
    system, emitter = pool_system(s, gravity=(0.0, -9.81, 0.0))
    integrate(get_solver("lecture")(system), 1.0, 0.01)  # 100 steps, 10 per frame
    assert emitter.frame == 11  # frames begin at t = 0, 0.1, ..., 1.0
    assert system.alive.sum() == 22


def test_an_adaptive_run_spawns_at_each_frame_s_instant():
    """Dormand-Prince on a fountain in free flight ends a step at each frame's start, so
    its particles are born when a fixed-step run's are: both are exact on a parabola
    (fifth order; RK4 at a quarter frame), and their final states agree to round-off.
    Spawned at the end of a longer step instead, a particle starts late and ends up to
    ``speed x step`` away (particle-fountain's published 0.184 m)."""
    frame_dt = 1 / 30
    s = spec(rate_n=6.0, rate_r=2.0, speed=2.0, frame_dt=frame_dt, lifetime=40, lifetime_jitter=0)
    ends = {}
    for method, dt, kw in (("rk4", frame_dt / 4, {}), ("dopri5", frame_dt, {"rtol": 1e-9, "atol": 1e-9})):
        system, emitter = pool_system(s, gravity=(0.0, -9.81, 0.0))
        integrate(get_solver(method)(system, **kw), 0.5, dt)
        assert emitter.frame == 16, method  # frames at 0, 1/30, ..., 0.5
        ends[method] = (system.alive.copy(), system.positions.copy(), system.velocities.copy())
    (alive, x, v), (alive_a, x_a, v_a) = ends["rk4"], ends["dopri5"]
    np.testing.assert_array_equal(alive, alive_a)
    assert alive.sum() > 50
    np.testing.assert_allclose(x_a[alive], x[alive], rtol=0, atol=1e-12)
    np.testing.assert_allclose(v_a[alive], v[alive], rtol=0, atol=1e-12)


def test_emitter_runs_are_reproducible():
    def final_state():
        system, _ = pool_system(spec(), gravity=(0.0, -9.81, 0.0))
        integrate(get_solver("lecture")(system), 1.0, 1 / 120)
        return system.get_state(), system.alive.copy()

    (x1, a1), (x2, a2) = final_state(), final_state()
    assert np.array_equal(x1, x2) and np.array_equal(a1, a2)


def test_spawned_particles_start_on_the_faces_moving_within_the_cone():
    s = spec(rate_n=500.0, rate_r=0.0, capacity=600, spread=0.25, speed=2.0)
    system, emitter = pool_system(s)
    alive = system.alive
    x, v = system.positions[alive], system.velocities[alive]
    half = s.size / 2
    on_face = np.isclose(np.max(np.abs(x), axis=1), half, rtol=0, atol=1e-15)
    assert np.all(on_face) and np.all(np.abs(x) <= half + 1e-15)
    normal = np.zeros_like(x)
    axis = np.argmax(np.abs(x), axis=1)
    normal[np.arange(len(x)), axis] = np.sign(x[np.arange(len(x)), axis])
    cos = np.einsum("ij,ij->i", v, normal) / np.linalg.norm(v, axis=1)
    assert np.all(cos >= np.cos(s.spread) - 1e-12)
    assert np.allclose(np.linalg.norm(v, axis=1), 2.0, rtol=1e-14)
    rgba = emitter.colors(system)
    assert rgba.shape == (600, 4) and np.all(rgba[~alive[:600], 3] == 0.0)
    assert np.allclose(rgba[alive[:600], :3], s.color_birth)  # age 0: the birth colour
    assert emitter.shapes(system).shape == (600, 2)


def test_a_frame_allocates_nothing_proportional_to_the_pool():
    s = spec(rate_n=3.0, rate_r=2.0, capacity=1_000_000)
    system, emitter = pool_system(s)
    for _ in range(20):
        emitter.begin_frame(system)
    tracemalloc.start()
    for _ in range(20):
        emitter.begin_frame(system)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    # The pool's own arrays are 8 MB each; a frame may allocate per new or expired
    # particle (tens here) but nothing of the pool's size.
    assert peak < 100_000


def test_particle_fountain_statistics_within_three_standard_errors(case_named):
    case = case_named("particle-fountain")
    traj = ReferenceAdapter().simulate(case, "lecture", case.dts[0])
    for name in ("spawn_rate_z", "population_z"):
        z = PROPERTIES[name](case, traj)
        assert np.isfinite(z) and abs(z) < 3, (name, z)
    assert PROPERTIES["max_penetration"](case, traj) == 0.0


def test_strands_follow_each_particle_life(case_named):
    case = case_named("hair-strands")
    traj = ReferenceAdapter().simulate(case, "lecture", case.dts[0])
    strands = collect_strands(traj.t, traj.x, traj.v, traj.alive, root_thickness=2e-3, taper=0.8)
    alive = traj.alive
    assert len(strands) == alive[0].sum() + (alive[1:] & ~alive[:-1]).sum()
    # Every strand is a whole life: 12 frames of 1/30 s at dt = 1/150 s is 60 steps.
    finished = strands.times[strands.start[1:] - 1] < traj.t[-1]
    assert np.all(np.diff(strands.start)[finished] == 60)
    # Free flight is exact for the lecture's update: strands lie on their parabolas.
    dev = ballistic_deviation(strands, case.model.gravity, 0.0, 1.0)
    assert np.max(dev) < 1e-12
    roots, tips = strands.start[:-1], strands.start[1:] - 1
    grown = tips > roots  # strands born at the last record are a single point
    assert np.allclose(strands.thickness[roots], 2e-3, rtol=1e-14)
    assert np.allclose(strands.thickness[tips[grown]], 2e-3 * 0.2, rtol=1e-12)
    assert np.all(strands.lengths()[grown] > 0)


EMITTER = """
kind = "particles"
[scene]
[[scene.emitters]]
shape = "cube"
center = [0.0, 1.0, 0.0]
size = 0.2
rate_n = 5.0
rate_r = 2.0
speed = 1.0
lifetime = 10
capacity = 100
[run]
duration = 1.0
dt = [0.01]
"""


@pytest.mark.parametrize(
    ("change", "field", "reason"),
    [
        (('shape = "cube"', 'shape = "sphere"'), "scene.emitters[0].shape", "not one of"),
        (("rate_n = 5.0", "rate_n = -5.0"), "scene.emitters[0].rate_n", "negative"),
        (("lifetime = 10", "lifetime = 0"), "scene.emitters[0].lifetime", "at least 1"),
        (
            ("lifetime = 10", "lifetime = 10\nlifetime_jitter = 10"),
            "scene.emitters[0].lifetime_jitter",
            "below lifetime",
        ),
        (("capacity = 100", "capacity = 50"), "scene.emitters[0].capacity", "largest population"),
        (("size = 0.2", "size = 0.2\nnormal = [0, 1, 0]"), "scene.emitters[0].normal", "only a plane"),
        (("speed = 1.0", "speed = 1.0\nspread = 4.0"), "scene.emitters[0].spread", "at most"),
        (("speed = 1.0", "sped = 1.0"), "scene.emitters[0].speed", "missing"),
    ],
)
def test_bad_emitter_table_names_the_field(tmp_path, change, field, reason):
    path = tmp_path / "bad-emitter.toml"
    path.write_text(EMITTER.replace(*change))
    with pytest.raises(CaseError) as err:
        load_case(path)
    assert err.value.field == field
    assert reason in err.value.reason


def test_an_emitter_table_adds_its_pool(tmp_path):
    path = tmp_path / "good-emitter.toml"
    path.write_text(EMITTER)
    case = load_case(path)
    assert case.model.n == 100 and case.model.features() >= {"emitters", "3d"}
