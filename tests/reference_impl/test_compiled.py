"""The compiled path equals the numpy reference on every case and method it runs.

The numpy :class:`~truestep.reference_impl.particles.ParticleSystem`, the solver classes
and :func:`~truestep.reference_impl.integrate.integrate` are the oracle. Each case runs
its largest swept step for at most 300 steps both ways: the same status, records, steps
and evaluations, and the same states: bit for bit, but for RK4, whose numpy step ends
with the BLAS product ``B @ k`` (fused multiply-adds, in an order of its own) where the
compiled one sums ``b_s k_s`` in stage order: there, 1e-12 of the state's size (about
1e-16 a step; a bounded run cannot build that up beyond 1e-13 in 300 steps), absolute
for runs that blew up (their states are huge and only the status and the count must
agree).

Then what the compiled path adds: the energy watched at every step, tiles of
independent particles and the run again as one tile after a blow-up in one of them,
methods known by their facts alone, and the composition itself.
"""

from __future__ import annotations

import dataclasses
import inspect
import os
from pathlib import Path

import numba
import numpy as np
import pytest
from numba import njit, typeof

from truestep.adapters.reference import ReferenceAdapter
from truestep.cases import load_cases
from truestep.reference_impl import (
    cache_guard,
    compiled,
    integrate_kernels,
    particles_kernels,
    precompile,
    tiles,
)
from truestep.reference_impl.compiled import compiled_reason, independent, run_compiled
from truestep.reference_impl.forces_kernels import LOOP
from truestep.reference_impl.integrate import integrate
from truestep.reference_impl.model import ParticleModel, Plane, Springs
from truestep.reference_impl.particles import ParticleSystem, total_energy
from truestep.reference_impl.passes import passes_for
from truestep.reference_impl.solvers import METHODS, ExplicitRungeKutta, get_solver
from truestep.reference_impl.solvers.facts import MethodFacts

FIXED = ["euler", "midpoint", "heun", "rk4", "symplectic-euler", "verlet", "lecture"]
CASES = [c for c in load_cases("*") if compiled_reason(c.model, "rk4") is None]
ROUND_OFF = 1e-12
BLAS_ORDERED = {"rk4"}
"""Methods whose numpy step sums the stages with a BLAS product (see the docstring)."""


def test_every_particle_case_but_fields_and_emitters_is_compiled():
    names = {c.name for c in load_cases("*") if c.model is not None}
    assert names - {c.name for c in CASES} == {"hair-strands", "particle-fountain"}
    assert {c.name for c in CASES if independent(c.model)} >= {
        "particle-rain",
        "bouncing-ball",
        "harmonic-oscillator",
    }
    assert not independent(next(c for c in CASES if c.name == "spring-chain").model)


def short(case):
    dt = case.dts[0]
    return dataclasses.replace(case, duration=min(case.duration, 300 * case.steps_for(dt)[1])), dt


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_compiled_equals_numpy(case):
    case, dt = short(case)
    for method in FIXED:
        fast = ReferenceAdapter().simulate(case, method, dt)
        slow = ReferenceAdapter(compiled=False).simulate(case, method, dt)
        label = f"{case.name}/{method}"
        assert (fast.path, slow.path) == ("compiled", "numpy"), label
        assert fast.status == slow.status, label
        assert (fast.steps, fast.nfev, len(fast.t)) == (slow.steps, slow.nfev, len(slow.t)), label
        np.testing.assert_array_equal(fast.t, slow.t, err_msg=label)
        if method not in BLAS_ORDERED:
            np.testing.assert_array_equal(fast.x, slow.x, err_msg=label)
            np.testing.assert_array_equal(fast.v, slow.v, err_msg=label)
        elif fast.status == "ok":
            size = max(1.0, float(np.max(np.abs(slow.x))), float(np.max(np.abs(slow.v))))
            np.testing.assert_allclose(fast.x, slow.x, rtol=0, atol=ROUND_OFF * size, err_msg=label)
            np.testing.assert_allclose(fast.v, slow.v, rtol=0, atol=ROUND_OFF * size, err_msg=label)
            np.testing.assert_allclose(
                fast.energy, slow.energy, rtol=1e-9, atol=ROUND_OFF * size, err_msg=label
            )
        assert fast.t_fail == slow.t_fail, label


def test_fields_and_emitters_run_on_the_numpy_path(case_named):
    traj = ReferenceAdapter().simulate(case_named("hair-strands"), "lecture", 1 / 150)
    assert traj.path == "numpy"
    assert compiled_reason(case_named("hair-strands").model, "lecture") == "emitters"
    assert compiled_reason(None, "rk4").startswith("an ODE case")
    assert "not a fixed-step explicit method" in compiled_reason(
        case_named("free-fall").model, "implicit-euler"
    )


@pytest.mark.parametrize(
    "name, method",
    [
        ("harmonic-oscillator", "rk4"),
        ("bouncing-ball", "lecture"),
        ("hanging-cloth", "verlet"),
        ("close-encounter", "heun"),
        ("particle-rain", "symplectic-euler"),
        ("triangle-impulse", "euler"),
        ("sliding-contact", "midpoint"),
    ],
)
def test_energy_watched_at_every_step_bounds_the_numpy_energy_of_every_record(case_named, name, method):
    case = case_named(name)
    dt = case.dts[0]
    h = case.steps_for(dt)[1]
    plain, _ = run_compiled(case.model, method, case.duration, h, max_records=case.max_records)
    watched, _ = run_compiled(
        case.model, method, case.duration, h, max_records=case.max_records, track_energy=True
    )
    # watching changes nothing in the run
    np.testing.assert_array_equal(watched.x, plain.x)
    np.testing.assert_array_equal(watched.v, plain.v)
    assert (watched.nfev, watched.steps, watched.status) == (plain.nfev, plain.steps, plain.status)
    energy = total_energy(case.model, watched.x, watched.v)
    low, high = watched.extra["energy_min"], watched.extra["energy_max"]
    scale = max(1.0, float(np.max(np.abs(energy))))
    # the compiled sums run in another order than numpy's (1e-16 of the energy a term)
    assert low <= energy.min() + 1e-12 * scale and high >= energy.max() - 1e-12 * scale
    every, _ = run_compiled(case.model, method, case.duration, h, max_records=plain.steps, track_energy=True)
    assert len(every.t) == every.steps + 1  # every state recorded: the bounds are theirs
    energy = total_energy(case.model, every.x, every.v)
    assert every.extra["energy_min"] == pytest.approx(energy.min(), rel=1e-12, abs=1e-12 * scale)
    assert every.extra["energy_max"] == pytest.approx(energy.max(), rel=1e-12, abs=1e-12 * scale)
    assert "energy_min" not in plain.extra


def unstable_in_one_tile(n: int = 3 * tiles.BLOCK) -> ParticleModel:
    """Independent particles under drag; those of the second tile so light that explicit
    Euler's factor ``1 - h k / m`` exceeds 1 in size: they blow up, the others do not."""
    mass = np.ones(n)
    mass[tiles.BLOCK + 10 : tiles.BLOCK + 20] = 1e-4
    rng = np.random.default_rng(5)
    return ParticleModel(
        mass=mass,
        x0=rng.normal(size=(n, 3)),
        v0=rng.normal(size=(n, 3)),
        radius=np.zeros(n),
        fixed=np.zeros(n, bool),
        gravity=np.array([0.0, -9.81, 0.0]),
        drag=0.5,
        planes=[Plane(np.array([0.0, -5.0, 0.0]), np.array([0.0, 1.0, 0.0]), 0.5)],
    )


@pytest.mark.parametrize("method", ["euler", "lecture"])
def test_a_blow_up_in_one_tile_ends_the_run_as_the_whole_scene_does(method):
    model = unstable_in_one_tile()
    assert compiled.layout_for(compiled.method_kind(method), compiled.pack(model)).size < model.n
    fast, _ = run_compiled(model, method, 1.0, 1e-3, max_records=40)
    assert fast.rerun_whole
    stable, _ = run_compiled(dataclasses.replace(model, mass=np.ones(model.n)), method, 0.2, 1e-3)
    assert stable.status == "ok" and not stable.rerun_whole
    system = ParticleSystem(model, passes_for(model))
    slow = integrate(get_solver(method)(system), 1.0, 1e-3, max_records=40)
    assert fast.status == slow.status == "unstable"
    assert (fast.steps, fast.nfev, fast.t_fail) == (slow.steps, slow.nfev, slow.t_fail)
    np.testing.assert_array_equal(fast.t, slow.t)
    n = model.n
    np.testing.assert_array_equal(fast.x, slow.x[:, : 3 * n].reshape(-1, n, 3))


class Ralston(ExplicitRungeKutta):
    """A tableau no step of the compiled path names: Ralston's second-order method."""

    name = "ralston-test"
    A = np.array([[0.0, 0.0], [2.0 / 3.0, 0.0]])
    B = np.array([0.25, 0.75])
    facts = MethodFacts(order=2, evaluations_per_step=2, symplectic=False)


def test_a_new_tableau_is_compiled_from_its_facts_alone(case_named, monkeypatch):
    monkeypatch.setitem(METHODS, Ralston.name, Ralston)
    for name in ("bouncing-ball", "spring-chain"):
        case = case_named(name)
        dt = case.dts[0]
        h = case.steps_for(dt)[1]
        fast, _ = run_compiled(case.model, Ralston.name, 0.2, h)
        system = ParticleSystem(case.model, passes_for(case.model))
        slow = integrate(Ralston(system), 0.2, h)
        n = case.model.n
        np.testing.assert_allclose(
            fast.x, slow.x[:, : 3 * n].reshape(-1, n, 3), rtol=0, atol=1e-12 * max(1.0, np.abs(slow.x).max())
        )
        assert fast.nfev == slow.nfev == 2 * fast.steps


@pytest.mark.skipif(numba.config.DISABLE_JIT, reason="nothing is compiled with NUMBA_DISABLE_JIT=1")
def test_compiling_is_shown_as_progress(case_named, monkeypatch):
    monkeypatch.setattr(compiled, "SLOW_S", 0.0)
    monkeypatch.setattr(compiled, "drive", njit(**LOOP)(integrate_kernels.drive.py_func))  # none compiled
    monkeypatch.setattr(compiled, "_PREPARED", {})
    said: list[str] = []
    case = case_named("free-fall")
    run_compiled(case.model, "heun", 0.01, 0.001, progress=said.append)
    assert said[0] == "compiling reference kernels for gravity / every method / fused ..."
    assert said[1].startswith("compiled reference kernels for gravity / every method / fused in ")


def held(scene, method: str) -> tuple:
    """What the loop that runs ``method`` on ``scene`` holds, its layout and the scene."""
    kind = compiled.method_kind(method)
    layout = compiled.layout_for(kind, scene)
    return compiled.loop_kind(kind, layout, scene)[1], layout, scene


def test_a_step_calls_only_the_kernels_its_scene_declares(case_named):
    """numba picks what a step calls by the types of what its scene holds
    (:mod:`~truestep.reference_impl.by_type`): the kernels of its force kinds, and nothing
    for a part it lacks; every scene of a layout then shares one loop, compiled for each
    combination of types."""
    harmonic, ball = (
        compiled.pack(case_named(name).model) for name in ("harmonic-oscillator", "bouncing-ball")
    )

    def called(pick, scene) -> set[str]:
        """The names of the functions the generic call ``pick`` (an overload) makes for
        ``scene``, through the chain of calls it compiles (:func:`by_type.fold`)."""
        seen, todo = set(), [pick(typeof(scene), *[None] * (len(inspect.signature(pick).parameters) - 1))]
        while todo:
            item = todo.pop()
            fn = getattr(item, "py_func", item)
            for cell in fn.__closure__ or ():
                inner = cell.cell_contents
                if callable(inner) and getattr(inner, "__name__", "") not in seen:
                    seen.add(getattr(inner, "__name__", ""))
                    todo.append(inner)
        return seen

    # the forces: the anchors' kernels for the one, gravity's for the other, nothing else
    assert {"anchors_add"} <= called(particles_kernels._add_forces, harmonic)
    assert not {"gravity_add", "drag_add"} & called(particles_kernels._add_forces, harmonic)
    assert "gravity_at" in called(particles_kernels._point_force, ball)
    assert not {"anchors_at", "drag_at"} & called(particles_kernels._point_force, ball)
    assert "gravity_energy" in called(particles_kernels._potential_energy, ball)
    # no planes: a step's plane tests and collision passes are constants; with them, the kernels
    near = tiles._any_near(typeof(harmonic.planes), None, None)
    assert near(None, None, None) is False
    assert tiles._any_near(typeof(ball.planes), None, None)(ball.planes, (0.0, 0.01, 0.0), 0.05)
    collide = tiles._collide_if_planes(tiles.fused_collisions)
    assert collide(typeof(harmonic), None, None, None)(None, None, None, None) is False
    assert collide(typeof(ball), None, None, None).__closure__[0].cell_contents is tiles.fused_collisions
    # one function, compiled for each scene's types
    loops = [
        compiled.prepared(case_named(n).model, "lecture")[0] for n in ("harmonic-oscillator", "bouncing-ball")
    ]
    compiled_for = [c.entry_point for c in integrate_kernels.drive.overloads.values()]
    assert loops[0] is not loops[1] and all(loop in compiled_for for loop in loops)


def test_a_changed_module_compiles_every_function_of_the_package_afresh():
    """numba's cache takes a function's code as current while its own file is unchanged;
    the reference implementation's functions are stamped by the whole folder instead, so
    that a changed kernel in another module is never taken stale from the cache."""
    from numba.core import caching

    def locator(fn):
        return caching.CompileResultCacheImpl(fn.py_func)._locator

    assert isinstance(locator(integrate_kernels.drive), cache_guard.FolderStampedLocator)
    assert locator(integrate_kernels.drive).get_source_stamp() == (
        "truestep.reference_impl",
        cache_guard.FINGERPRINT,
    )
    assert not isinstance(locator(njit(cache=True)(_plain)), cache_guard.FolderStampedLocator)


def _plain(x):
    return x


def test_the_fingerprint_reads_every_module_of_the_reference_implementation(tmp_path):
    """No list of modules to keep: a change to any module under the folder, a new one or
    a renamed one, changes it (a loop compiled before is then compiled afresh)."""
    (tmp_path / "solvers").mkdir()
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "solvers" / "b.py").write_text("y = 2\n")
    first = cache_guard.source_fingerprint(tmp_path)
    assert cache_guard.source_fingerprint(tmp_path) == first
    (tmp_path / "solvers" / "b.py").write_text("y = 3\n")
    second = cache_guard.source_fingerprint(tmp_path)
    (tmp_path / "solvers" / "b.py").rename(tmp_path / "solvers" / "c.py")
    third = cache_guard.source_fingerprint(tmp_path)
    (tmp_path / "d.py").write_text("")
    assert len({first, second, third, cache_guard.source_fingerprint(tmp_path)}) == 4
    package = Path(cache_guard.__file__).parent
    assert cache_guard.FINGERPRINT == cache_guard.source_fingerprint(package)


def test_compile_all_prepares_every_fixed_step_method_the_scene_compiles(case_named, monkeypatch):
    monkeypatch.setattr(compiled, "_PREPARED", {})
    precompile.compile_all([case_named("free-fall").model], progress=lambda line: None)
    # one loop: euler, midpoint and heun, rk4 (three patterns of a tableau), a kick and
    # drift and velocity Verlet (in one tile: it carries state from step to step), fused;
    # the adaptive and implicit methods run on the numpy path; and the compiled derivative
    assert len(compiled._PREPARED) == 2
    model = case_named("free-fall").model
    assert compiled.derivative_key(model) in compiled._PREPARED
    assert {compiled.prepared(model, m)[2] for m in ("euler", "rk4", "verlet")} == {
        tiles.Fused(tiles.BLOCK),
        tiles.Fused(len(model.mass)),
    }


def test_shares_hold_each_loop_once_and_about_equal_work(case_named, monkeypatch):
    """A test session's workers split the loops without talking to each other: every
    worker computes the same split, each loop lands in exactly one share, and the heaviest
    go first, each to the lightest share (here: two fused loops of weight 2 and three of
    weight 1 on two workers make shares of 3.5 and 3.5 or 4 and 3, never 5 and 2)."""
    weighted = [(("a", 1), 1.0), (("b", 2), 2.0), (("c", 3), 1.0), (("d", 4), 2.0), (("e", 5), 1.0)]
    parts = precompile.shares(weighted, 2)
    assert parts == precompile.shares(list(weighted), 2)
    assert sorted(p for part in parts for p in part) == sorted(p for p, _ in weighted)
    weight = dict(weighted)
    loads = sorted(sum(weight[p] for p in part) for part in parts)
    assert loads == [3.0, 4.0]
    assert parts[0][0] == ("b", 2) and parts[1][0] == ("d", 4)
    assert precompile.longest_first(weighted) == [("b", 2), ("d", 4), ("a", 1), ("c", 3), ("e", 5)]
    # the library's loops: a fused loop weighs more than one in passes
    monkeypatch.setattr(compiled, "_PREPARED", {})
    needed = precompile._needed_with_weights(
        [(case_named("free-fall").model, "rk4"), (case_named("spring-chain").model, "rk4")]
    )
    assert [w for _, w in needed] == [precompile.WEIGHTS["fused"], precompile.WEIGHTS["passes"]]


def test_workers_take_the_next_loop_when_free_and_none_is_compiled_twice(case_named, monkeypatch):
    """With two workers, the loops are handed out from one shared counter: each index is
    taken by exactly one process, and this process then loads every loop."""
    import multiprocessing

    queue = multiprocessing.get_context("fork").Value("i", 0)
    mine = list(precompile._taken(5, queue))
    assert mine == [0, 1, 2, 3, 4] and list(precompile._taken(5, queue)) == []
    queue.value = 3
    assert list(precompile._taken(5, queue)) == [3, 4]
    monkeypatch.setattr(compiled, "_PREPARED", {})
    models = [case_named(n).model for n in ("free-fall", "spring-chain", "bouncing-ball")]
    precompile.compile_all(models, ["rk4"], workers=2, progress=lambda line: None)
    assert len(compiled._PREPARED) == 3


def test_the_lines_of_shared_work_count_what_is_left_after_the_loop_under_way():
    """A worker's line says how many loops are begun and, from its own pace, the seconds
    the loops nobody has begun will take on the processes sharing them; on the last loop,
    none (not the time of the loop it just finished)."""
    import time

    said: list[str] = []
    began = time.perf_counter() - 10.0  # this worker finished one loop in 10 s
    precompile._counted(said.append, 2, 4, began, "worker 2 of 2: ", (1, 2))("compiling x")
    precompile._counted(said.append, 3, 4, began, "worker 2 of 2: ", (1, 2))("compiled y")
    assert said == [
        "[worker 2 of 2: 3/4, ~5 s left] compiling x",
        "[worker 2 of 2: 4/4, ~0 s left] compiled y",
    ]
    alone: list[str] = []
    precompile._counted(alone.append, 1, 3, began)("compiling z")  # one loop in 10 s, two to go
    assert alone == ["[2/3, ~20 s left] compiling z"]


def test_one_loop_runs_every_method_in_passes(case_named):
    loops = {m: compiled.prepared(case_named("spring-chain").model, m)[0] for m in FIXED}
    assert len({id(loop) for loop in loops.values()}) == 1


def test_method_facts_choose_the_step():
    from truestep.reference_impl.solvers.explicit_rk_kernels import Tableau
    from truestep.reference_impl.solvers.splitting_kernels import KickDrift, KickDriftKick

    kinds = {m: compiled.method_kind(m) for m in METHODS}
    assert {m for m, k in kinds.items() if isinstance(k, Tableau)} == {
        m for m, cls in METHODS.items() if issubclass(cls, ExplicitRungeKutta)
    }
    assert isinstance(kinds["verlet"], KickDriftKick) and kinds["verlet"].carries_state
    assert kinds["lecture"] == KickDrift(0.5, 0.5, 1)
    assert kinds["dopri5"] is None and kinds["implicit-euler"] is None
    rk4 = kinds["rk4"]
    assert list(rk4.terms) == [0, 1, 1, 1] and list(rk4.cols[1:, 0]) == [0, 1, 2]


# What the kernels' mutation sample (tools/campaigns/mutation, 40 mutants of 46eb984) found
# untested: a collision pass that skips a flag of a run of eight, contact forces read from
# the wrong component, contact flags not cleared, a blow-up between records not kept.
# Each test below is the compiled path against the numpy oracle on a scene made for it.


def lone_flag_model(n: int = 16, lone: tuple[int, ...] = (1, 9)) -> ParticleModel:
    """Independent particles above a floor (y = 0): all high up (never near it in the run)
    but those of ``lone``, which fall onto it and bounce. With (1, 9) the fused collision
    pass sees, in each run of eight flags, only the flag at offset 1 set."""
    x0 = np.zeros((n, 3))
    x0[:, 0] = np.arange(n)
    x0[:, 1] = 1000.0
    for p in lone:
        x0[p, 1] = 0.3
    return ParticleModel(
        mass=np.ones(n),
        x0=x0,
        v0=np.zeros((n, 3)),
        radius=np.zeros(n),
        fixed=np.zeros(n, bool),
        gravity=np.array([0.0, -9.81, 0.0]),
        planes=[Plane(np.zeros(3), np.array([0.0, 1.0, 0.0]), 0.5)],
    )


# Kills tiles.py:302 `flags[b + 1]` -> `flags[b ** 1]` in fused_collisions: the run of
# eight flags is then read without its second one, so a particle at offset 1 of its run
# that is alone near a plane is never collided and falls through the floor.
@pytest.mark.parametrize("method", ["euler", "symplectic-euler", "verlet", "lecture"])
def test_a_particle_alone_near_a_plane_at_each_offset_of_a_run_of_eight_is_collided(method):
    n = 16
    for lone in [(k, 8 + k) for k in range(8)]:
        model = lone_flag_model(n, lone)
        assert compiled.layout_for(compiled.method_kind(method), compiled.pack(model)).name == "fused"
        fast, _ = run_compiled(model, method, 0.6, 1e-3, max_records=60)
        slow = integrate(
            get_solver(method)(ParticleSystem(model, passes_for(model))), 0.6, 1e-3, max_records=60
        )
        assert fast.status == slow.status == "ok"
        np.testing.assert_array_equal(fast.t, slow.t)
        np.testing.assert_array_equal(
            fast.x, slow.x[:, : 3 * n].reshape(-1, n, 3), err_msg=f"{method}, lone {lone}"
        )
        # the falling particles never go below the floor
        assert fast.x[:, list(lone), 1].min() >= -1e-9, (method, lone)


def against_numpy(
    model: ParticleModel, method: str, duration: float, h: float, max_records: int, exact: bool = True
):
    """The compiled run against the numpy oracle: status, records, times, states."""
    n = model.n
    fast, _ = run_compiled(model, method, duration, h, max_records=max_records)
    slow = integrate(
        get_solver(method)(ParticleSystem(model, passes_for(model))), duration, h, max_records=max_records
    )
    assert fast.status == slow.status, method
    assert (fast.steps, fast.nfev) == (slow.steps, slow.nfev), method
    np.testing.assert_array_equal(fast.t, slow.t, err_msg=method)
    assert fast.t_fail == slow.t_fail, method
    if fast.status == "ok":
        xs = slow.x[:, : 3 * n].reshape(-1, n, 3)
        if exact:
            np.testing.assert_array_equal(fast.x, xs, err_msg=method)
        else:
            np.testing.assert_allclose(
                fast.x, xs, rtol=0, atol=1e-12 * max(1.0, np.abs(xs).max()), err_msg=method
            )
    return fast, slow


def dumbbell_on_floor(friction: float, v0=(1.0, 0.0, 0.0), lift: float = 0.0) -> ParticleModel:
    """Two particles joined by a spring along x resting on a floor (y = 0), sliding at
    ``v0``; a third particle rests on the floor alone. With ``lift`` > 0 a fourth particle,
    1 m above the first and joined to it by a spring, starts upward at ``lift`` m/s and
    yanks the first one off the floor. Springs make the scene non-pointwise: the
    ``Passes`` layout (passes_collisions, add_contact_forces)."""
    x0 = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [5.0, 0.0, 0.0]]
    v = [list(v0), list(v0), [0.0, 0.0, 0.0]]
    i, j = [0], [1]
    if lift > 0:
        x0.append([0.0, 1.0, 0.0])
        v.append([0.0, lift, 0.0])
        i.append(0)
        j.append(3)
    n = len(x0)
    m = len(i)
    springs = Springs(np.array(i), np.array(j), np.full(m, 50.0), np.full(m, 0.5), np.ones(m))
    return ParticleModel(
        mass=np.ones(n),
        x0=np.array(x0),
        v0=np.array(v),
        radius=np.zeros(n),
        fixed=np.zeros(n, bool),
        gravity=np.array([0.0, -9.81, 0.0]),
        springs=springs,
        planes=[Plane(np.zeros(3), np.array([0.0, 1.0, 0.0]), 0.5, friction)],
    )


# Kills particles_kernels.py:119 `F[1, p]` -> `F[2, p]` in add_contact_forces: the contact
# force of a particle resting on a floor y = 0 is then computed from (F_x, F_z, F_z), whose
# normal push is F_z = 0, so Coulomb friction (limit mu |F_N|) vanishes and the dumbbell
# slides on at its speed instead of slowing down.
@pytest.mark.parametrize("method", ["euler", "symplectic-euler", "verlet", "lecture"])
def test_friction_on_a_resting_dumbbell_of_the_passes_layout_is_the_numpy_one(method):
    model = dumbbell_on_floor(friction=0.3)
    assert compiled.layout_for(compiled.method_kind(method), compiled.pack(model)).name == "passes"
    fast, _ = against_numpy(model, method, 0.5, 1e-3, max_records=50)
    # friction slowed it: mu g t = 0.3 * 9.81 * 0.5 = 1.47 m/s > 1 m/s, it stopped
    assert fast.x[-1, 0, 0] < 0.5 * 1.0 * 0.5 + 0.1


# Kills tiles.py:190 `for p in range(contact.shape[1])` -> `for p in []` in
# passes_collisions: the contact flags are then not cleared at the start of a pass, so a
# particle yanked off the floor keeps its stale flag while another one still rests (the
# pass's contact count is not zero): the floor keeps cancelling its downward push in the
# air. A particle gets such a stale flag only when it leaves eps (1e-9 m) of the floor
# within the step after a pass that found it resting, which a method whose later stages
# already feel the spring's growing pull can do. Checked against the mutant: the rk4 case
# fails (positions off by up to 3.9 m); midpoint and heun (kept here) and euler,
# symplectic-euler, verlet, lecture in this scene do not tell it.
@pytest.mark.parametrize("method", ["midpoint", "heun", "rk4"])
def test_a_particle_leaving_the_floor_loses_its_contact_in_the_passes_layout(method):
    model = dumbbell_on_floor(friction=0.0, v0=(0.0, 0.0, 0.0), lift=6.0)
    fast, _ = against_numpy(model, method, 1.5, 1e-3, max_records=150, exact=method != "rk4")
    assert fast.x[:, 0, 1].max() > 0.05  # the first particle did leave the floor


# Kills integrate_kernels.py:122 `return kept + 1` -> `return kept ** 1` in stopped: a
# blow-up first seen between records (no record since the last good check) is recorded
# as the last state, as integrate() does; the mutant writes it but does not keep it.
@pytest.mark.parametrize("method", ["euler", "lecture"])
def test_a_blow_up_seen_between_records_is_recorded_as_integrate_does(method):
    n = 3
    model = ParticleModel(
        mass=np.full(n, 1e-4),
        x0=np.ones((n, 3)),
        v0=np.ones((n, 3)),
        radius=np.zeros(n),
        fixed=np.zeros(n, bool),
        gravity=np.array([0.0, -9.81, 0.0]),
        drag=0.5,
    )
    # explicit Euler's factor 1 - h k / m = -4: beyond BLOWUP in about 20 steps, found at
    # the check of step 64; with 2 records (t = 0 and the end) no record lies between
    fast, slow = against_numpy(model, method, 1.0, 1e-3, max_records=2)
    assert fast.status == slow.status == "unstable"
    assert len(slow.t) == 2 and len(fast.t) == 2
    n_ = model.n
    np.testing.assert_array_equal(fast.x, slow.x[:, : 3 * n_].reshape(-1, n_, 3))


DERIVED = [c for c in load_cases("*") if compiled.derivative_reason(c.model) is None]


def test_the_compiled_derivative_covers_the_particle_cases_without_planes_fields_or_emitters():
    names = {c.name for c in DERIVED}
    assert {"earth-orbit", "stiff-cloth", "spring-chain", "triangle-impulse", "rope-pendulum"} <= names
    assert not names & {"bouncing-ball", "particle-fountain", "hair-strands", "kepler-orbit"}
    assert compiled.derivative_for(None) is None


@pytest.mark.parametrize("case", DERIVED, ids=[c.name for c in DERIVED])
def test_the_compiled_derivative_is_the_numpy_system_s_bit_for_bit(case):
    """At states around the start and far from it (stretched springs, particles close
    together, impulses on and off): ``derivative_for`` against ``ParticleSystem.derivative``."""
    fast = compiled.derivative_for(case.model)
    system = ParticleSystem(case.model, passes_for(case.model))
    y0 = system.get_state()
    rng = np.random.default_rng(7)
    for k in range(12):
        y = y0 * (1 + 0.2 * rng.standard_normal(y0.shape)) + 0.05 * rng.standard_normal(y0.shape)
        t = float(rng.uniform(0.0, case.duration))
        np.testing.assert_array_equal(fast(y, t), system.derivative(y, t), err_msg=f"{case.name} at {k}")
    np.testing.assert_array_equal(fast(y0, 0.0), system.derivative(y0, 0.0))


def test_a_compile_helper_whose_parent_is_gone_stops_before_its_next_loop():
    """``compile_all``'s forked helpers check, before each loop, that the process that
    started them still runs: after a SIGKILL of ``truestep compile`` they stop instead of
    compiling on into the cache for nobody."""
    import multiprocessing

    from truestep.cases import load_cases
    from truestep.reference_impl import precompile

    model = load_cases("spring-chain")[0].particles
    helper = multiprocessing.get_context("fork").Process(
        target=precompile._prepare_each, args=([(model, "rk4")], None, os.getppid())
    )
    helper.start()
    helper.join(60)
    assert helper.exitcode == 1  # its parent is this process, not the pid it was given


@pytest.mark.parametrize("method", ["symplectic-euler", "rk4", "lecture"])
@pytest.mark.parametrize("threads", [2, 3])
def test_tiles_on_several_threads_step_as_one_thread_does(method, threads):
    """A scene of independent particles in more tiles than threads (and one short tile),
    stepped on several threads at once: every record, count and status is one thread's,
    bit for bit; and a blow-up in one tile is the run made again as one tile, as on one
    thread."""
    model = dataclasses.replace(
        unstable_in_one_tile(4 * tiles.BLOCK + 17), mass=np.ones(4 * tiles.BLOCK + 17)
    )
    assert compiled.layout_for(compiled.method_kind(method), compiled.pack(model)).size < model.n
    one, _ = run_compiled(model, method, 0.5, 1e-3, max_records=30)
    many, _ = run_compiled(model, method, 0.5, 1e-3, max_records=30, threads=threads)
    assert one.status == many.status == "ok"
    assert (one.steps, one.nfev, one.rerun_whole) == (many.steps, many.nfev, many.rerun_whole)
    for a, b in ((one.t, many.t), (one.x, many.x), (one.v, many.v)):
        np.testing.assert_array_equal(a, b)
    bad = unstable_in_one_tile()
    one, _ = run_compiled(bad, "euler", 1.0, 1e-3, max_records=40)
    many, _ = run_compiled(bad, "euler", 1.0, 1e-3, max_records=40, threads=threads)
    assert many.rerun_whole and many.status == one.status == "unstable"
    assert (one.steps, one.nfev, one.t_fail) == (many.steps, many.nfev, many.t_fail)
    np.testing.assert_array_equal(one.x, many.x)


def test_the_adapter_s_threads_give_its_one_thread_trajectory():
    """``ReferenceAdapter(threads=2)`` through the adapter API: the same trajectory as
    the default adapter's; a count that is not a whole number of at least 1 is refused."""
    from truestep.execution.bench import rain_case

    case = rain_case(3 * tiles.BLOCK + 5)
    one = ReferenceAdapter().simulate(case, "lecture", 1e-3)
    two = ReferenceAdapter(threads=2).simulate(case, "lecture", 1e-3)
    assert one.path == two.path == "compiled" and one.status == two.status == "ok"
    for a, b in ((one.t, two.t), (one.x, two.x), (one.v, two.v), (one.energy, two.energy)):
        np.testing.assert_array_equal(a, b)
    for bad in (0, 1.5, "2"):
        with pytest.raises(ValueError, match="threads"):
            ReferenceAdapter(threads=bad)  # type: ignore[arg-type]
