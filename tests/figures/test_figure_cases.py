"""The lecture figures' scenes: every figure case file loads and runs through the reference
adapter, none is in the case library, and each scene is the one the figures simulated
with their own step loops before they became cases.

The oracles below are those loops, rebuilt from the reference implementation's models,
solvers and :func:`~truestep.reference_impl.integrate.integrate` (the parameters typed as
the old figure code typed them); the figures' runs must match them to round-off.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from truestep.cases.loader import library
from truestep.figures.contact import contact_start, floor_bounces, with_restitution
from truestep.figures.lecture import LinearDecay, simulate_fountain
from truestep.figures.scenes import FIGURE_CASE_DIR, figure_case, run_reference
from truestep.reference_impl import meshes
from truestep.reference_impl.collisions import box_planes
from truestep.reference_impl.emitters import Emitter
from truestep.reference_impl.integrate import integrate
from truestep.reference_impl.model import EmitterSpec, ParticleModel, Plane, Springs
from truestep.reference_impl.odes import CircleField
from truestep.reference_impl.particles import ParticleSystem
from truestep.reference_impl.passes import passes_for
from truestep.reference_impl.solvers import get_solver

G = np.array([0.0, -9.81, 0.0])
"""The old figures' gravity, m/s^2."""
ROUND_OFF = 1e-12
"""Relative agreement of two runs of the same method on the same scene whose steps differ
by an ulp (the adapter fits the step to the duration: 12.6 / 63 is not the double 0.2)
or whose arithmetic is ordered differently (a compiled path): a few hundred steps of
round-off. A wrong parameter moves the states by many orders more."""

FIGURE_METHODS = {
    "integral-curves": "dopri5",
    "circle-field-two-turns": "euler",
    "viscous-decay": "euler",
    "stretched-spring-pair": "rk4",
    "triangle-push": "lecture",
    "pushed-cube-edges": "verlet",
    "pushed-cube-braced": "verlet",
    "cube-emitter-5000": "lecture",
    "particle-in-a-box": "lecture",
    "inclined-wall-drop": "lecture",
}
"""Every figure case and the method its figure runs it with."""


def _old_run(system, method: str, t_end: float, dt: float, **solver_kw):
    """The old figures' ``_simulate``: a reference solver stepped to ``t_end``, every step
    recorded."""
    solver = get_solver(method)(system, **solver_kw)
    return integrate(solver, t_end, dt, max_records=max(1, round(t_end / dt)))


def _particles(run_, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (T, n, 3) of a particle run's flat states."""
    return run_.x[:, : 3 * n].reshape(-1, n, 3), run_.x[:, 3 * n : 6 * n].reshape(-1, n, 3)


def test_the_figure_cases_are_exactly_the_files_the_figures_use():
    assert sorted(p.stem for p in FIGURE_CASE_DIR.glob("*.toml")) == sorted(FIGURE_METHODS)


@pytest.mark.parametrize("name", sorted(FIGURE_METHODS))
def test_every_figure_case_loads_and_runs_through_the_reference_adapter(name):
    case = figure_case(name)
    assert case.name == name
    traj = run_reference(case, FIGURE_METHODS[name])
    assert traj.status == "ok"
    assert traj.t[-1] == pytest.approx(case.duration, rel=1e-12)
    assert np.all(np.isfinite(traj.x))


def test_truestep_run_does_not_pick_up_the_figure_cases():
    # `truestep run` runs the library, cases/*.toml: the figures' cases stay out of it.
    assert not set(FIGURE_METHODS) & set(library())


def test_the_circle_field_scenes_are_the_old_ones():
    # Old: 63 Euler steps of 0.2 from (1, 0); the adapter steps 12.6 / 63, an ulp away.
    case = figure_case("circle-field-two-turns")
    old = _old_run(CircleField(np.array([1.0, 0.0])), "euler", 4 * np.pi, 0.2)
    new = run_reference(case, "euler", 0.2)
    assert len(new.t) == len(old.t) == 64
    np.testing.assert_allclose(new.x[:, 0, :], old.x, rtol=ROUND_OFF, atol=ROUND_OFF)
    # Old: dopri5 at tolerance 1e-9 over one period, from the first of its starting points.
    curves = figure_case("integral-curves")
    old = integrate(
        get_solver("dopri5")(CircleField(np.array([0.55, 0.0])), rtol=1e-9, atol=1e-9), 2 * np.pi, 2 * np.pi
    )
    new = run_reference(curves, "dopri5", 1e-9)
    at_steps = np.isin(new.t, old.t)  # besides its steps, the run is sampled in between
    assert at_steps.sum() == len(old.t)
    np.testing.assert_array_equal(new.x[at_steps, 0, :], old.x)


def test_the_drag_scene_is_the_test_equation_euler_stepped():
    # The instability figure's particle under drag has v' = -(b/m) v: Euler on it is Euler
    # on LinearDecay(1, k = b/m), record for record (the same products, so bit for bit).
    case = figure_case("viscous-decay")
    k = case.model.drag / case.model.mass[0]
    for dt in case.dts:
        new = run_reference(case, "euler", dt)
        old = _old_run(LinearDecay(1.0, k), "euler", case.duration, dt)
        np.testing.assert_array_equal(new.v[:, 0, 0], old.x[:, 0])
        np.testing.assert_allclose(new.v[1:, 0, 0] / new.v[:-1, 0, 0], 1 - k * dt, rtol=1e-12)


def test_the_spring_pair_and_the_triangle_are_the_old_scenes():
    model = ParticleModel(
        mass=np.array([1.0, 2.0]),
        x0=np.array([[0.0, 0, 0], [1.5, 0, 0]]),
        v0=np.zeros((2, 3)),
        radius=np.zeros(2),
        fixed=np.zeros(2, bool),
        springs=Springs(np.array([0]), np.array([1]), np.array([40.0]), np.array([1.5]), np.array([1.0])),
    )
    old, _ = _particles(_old_run(ParticleSystem(model), "rk4", 5.0, 1e-2), 2)
    np.testing.assert_allclose(
        run_reference(figure_case("stretched-spring-pair"), "rk4").x, old, rtol=ROUND_OFF, atol=ROUND_OFF
    )

    mesh = meshes.triangle(1.0)
    mass, springs = meshes.mass_spring(mesh, 3.0, 300.0, 0.0)
    model = ParticleModel(
        mass,
        mesh.vertices.copy(),
        np.zeros((3, 3)),
        np.zeros(3),
        np.zeros(3, bool),
        springs=springs,
        impulses=[(1, np.array([25.0, 0.0, 0.0]), 0.0, 0.02)],
        dimension=2,
    )
    old, _ = _particles(_old_run(ParticleSystem(model), "lecture", 0.28, 0.04), 3)
    np.testing.assert_allclose(
        run_reference(figure_case("triangle-push"), "lecture").x, old, rtol=ROUND_OFF, atol=ROUND_OFF
    )


@pytest.mark.parametrize("bracing", ["edges", "volume"])
def test_the_cubes_are_the_old_pushed_cubes(bracing):
    mesh = meshes.cube(1.0, np.array([0.0, 0.5, 0.0]), bracing)
    mass, springs = meshes.mass_spring(mesh, 8.0, 200.0, 1.0)
    fixed = np.zeros(8, bool)
    fixed[[0, 1, 4, 5]] = True
    push = [(i, np.array([20.0, -20.0, 0.0]), 0.0, np.inf) for i in (2, 3, 6, 7)]
    model = ParticleModel(
        mass,
        mesh.vertices.copy(),
        np.zeros((8, 3)),
        np.zeros(8),
        fixed,
        drag=2.0,
        springs=springs,
        impulses=push,
        surfaces=[mesh.faces],
    )
    old, _ = _particles(_old_run(ParticleSystem(model), "verlet", 3.0, 2e-3), 8)
    name = {"edges": "pushed-cube-edges", "volume": "pushed-cube-braced"}[bracing]
    np.testing.assert_allclose(
        run_reference(figure_case(name), "verlet").x, old, rtol=ROUND_OFF, atol=ROUND_OFF
    )


def test_the_fountain_is_the_old_fountain_and_its_attributes_are_the_emitters():
    # The old figure's loop: one lecture step per frame, 29 frames, a 12000-slot pool. The
    # figure case's pool is larger (its run is longer), which changes no draw of the seeded
    # emitter while no slot is reused: the first slots hold the same particles.
    spec = EmitterSpec(
        shape="cube",
        center=np.zeros(3),
        size=0.3,
        rate_n=260.0,
        rate_r=20.0,
        speed=3.0,
        spread=0.35,
        lifetime=20,
        lifetime_jitter=5,
        capacity=12000,
        speed_jitter=0.2,
        particle_size=0.006,
        size_jitter=0.5,
        fade_height=1.0,
        seed=7,
    )
    cap = spec.capacity
    model = ParticleModel(
        np.ones(cap),
        np.zeros((cap, 3)),
        np.zeros((cap, 3)),
        np.zeros(cap),
        np.zeros(cap, bool),
        gravity=G,
        emitters=[spec],
    )
    system = ParticleSystem(model, passes_for(model))
    emitter = next(p for p in system.passes if isinstance(p, Emitter))
    solver = get_solver("lecture")(system)
    new = simulate_fountain()
    for _ in range(new.snapshot):
        solver.step(spec.frame_dt)
        system.between_steps(spec.frame_dt)
    s = new.snapshot
    assert emitter.population[-1] == new.emitter.population[s] >= 5000
    np.testing.assert_array_equal(new.alive[s, :cap], system.alive)
    np.testing.assert_allclose(new.x[s, :cap], system.positions, rtol=ROUND_OFF, atol=ROUND_OFF)
    assert not new.alive[s, cap:].any()
    # Ages and lifespans read off the alive mask give the emitter's own colours.
    np.testing.assert_allclose(
        new.colors[:cap][system.alive], emitter.colors(system)[system.alive], rtol=1e-12, atol=1e-15
    )
    assert list(new.emitter.spawned[: s + 1]) == emitter.spawned


def test_the_box_is_the_old_box_and_its_floor_bounces_follow_k_r():
    base = figure_case("particle-in-a-box")
    for e in (1.0, 0.75, 0.5):
        planes = box_planes(np.array([-1.0, 0.0, -1.0]), np.array([1.0, 2.0, 1.0]), restitution=e)
        model = ParticleModel(
            np.ones(1),
            np.array([[-0.7, 1.6, 0.0]]),
            np.array([[2.6, 1.2, 0.0]]),
            np.zeros(1),
            np.zeros(1, bool),
            gravity=G,
            planes=planes,
            dimension=2,
        )
        old, _ = _particles(_old_run(ParticleSystem(model, passes_for(model)), "lecture", 2.0, 2e-3), 1)
        case = with_restitution(base, e)
        traj = run_reference(case, "lecture")
        np.testing.assert_allclose(traj.x, old, rtol=ROUND_OFF, atol=ROUND_OFF)
        found = floor_bounces(case, traj)
        # The floor and the side walls (gravity along them) are measured, not the ceiling.
        normals = {tuple(case.model.planes[pb.plane].normal) for pb in found}
        assert (0.0, 1.0, 0.0) in normals and (0.0, -1.0, 0.0) not in normals
        # Hard bounces: rebound speed k_r times the impact speed, up to gravity over the two
        # steps between the records either side of the impact (2 g dt = 0.039 m/s).
        for pb in found[:2]:
            assert pb.bounce.v_out == pytest.approx(e * pb.bounce.v_in, abs=2 * 9.81 * 2e-3)


def test_the_inclined_wall_is_the_old_wall_and_contact_is_read_off_the_state():
    angle = math.radians(20.0)
    normal = np.array([-math.sin(angle), math.cos(angle), 0.0])
    plane = Plane(np.zeros(3), normal, restitution=0.5)
    model = ParticleModel(
        np.ones(1),
        0.15 * normal[None, :],
        np.zeros((1, 3)),
        np.zeros(1),
        np.zeros(1, bool),
        gravity=G,
        planes=[plane],
        dimension=2,
    )
    system = ParticleSystem(model, passes_for(model))
    solver = get_solver("lecture")(system)
    x, flag = [system.positions[0].copy()], [False]
    for _ in range(1000):
        solver.step(1e-3)
        system.between_steps(1e-3)
        x.append(system.positions[0].copy())
        flag.append(bool(system.contact[0, 0]))
    case = figure_case("inclined-wall-drop")
    traj = run_reference(case, "lecture")
    # The adapter runs this scene through its compiled loop: equal to round-off.
    np.testing.assert_allclose(traj.x[:, 0], np.array(x), rtol=1e-9, atol=1e-12)
    p = case.model.planes[0]
    d, vn = (traj.x[:, 0] - p.point) @ p.normal, traj.v[:, 0] @ p.normal
    # The old figure read the contact pass's flag; the state the pass leaves says the same.
    assert contact_start(d, vn) == int(np.argmax(flag))
    assert all(flag[contact_start(d, vn) :])


def test_a_variant_changes_only_what_it_replaces():
    case = figure_case("particle-in-a-box")
    variant = with_restitution(case, 0.5)
    assert [p.restitution for p in variant.model.planes] == [0.5] * 6
    assert [p.restitution for p in case.model.planes] == [1.0] * 6
    shorter = replace(case, duration=1.0)
    assert shorter.model is case.model and case.duration == 2.0


def test_a_caption_states_what_its_runs_did(tmp_path, monkeypatch):
    # The instability figure's caption is read off its runs: with half the drag (k = 0.5/s)
    # every step of the sweep is stable, and the caption must say so with the new factors.
    import truestep.figures.odes as odes

    case = figure_case("viscous-decay")
    weaker = replace(case, scene=replace(case.particles, drag=0.5))
    monkeypatch.setattr(odes, "figure_case", lambda name: weaker)
    caption = odes.fig_euler_instability(tmp_path / "instability.png")
    assert "at kh = 1.25 it multiplies v by -0.25 per step and decays" in caption
    assert "diverges" not in caption
