"""The reference's fixed-step methods on a particle scene, compiled from only what it needs.

:func:`run_compiled` runs a :class:`~truestep.reference_impl.model.ParticleModel` with a
fixed-step method of :mod:`truestep.reference_impl.solvers` as
:func:`~truestep.reference_impl.integrate.integrate` runs it over a
:class:`~truestep.reference_impl.particles.ParticleSystem`, with the same results (tested
on every case and method), in a loop compiled for this kind of scene and method. This
module only selects and packs; the physics is in the kernels beside its numpy spec:

- the scene is packed (:func:`pack`) into the force kinds it declares, in the order of
  :func:`~truestep.reference_impl.forces.add_model_forces`
  (:mod:`~truestep.reference_impl.forces_kernels`), its impulses and its planes
  (:mod:`~truestep.reference_impl.collisions_kernels`);
- the method's facts give its compiled step (:func:`method_kind`): an explicit tableau
  (:mod:`~truestep.reference_impl.solvers.explicit_rk_kernels`) or a splitting
  (:mod:`~truestep.reference_impl.solvers.splitting_kernels`);
- the layout (:func:`layout_for`, :mod:`~truestep.reference_impl.tiles`) follows from both;
- one driver steps it (:mod:`~truestep.reference_impl.integrate_kernels`).

numba compiles one loop per combination of their types when it is first needed (shown as
progress when that takes a while) and caches it on disk. Scenes with force fields or
emitters are not compiled (:func:`compiled_reason` says why) and run on the numpy path;
implicit Euler (a Newton solve per step) and dopri5 (adaptive) stay there too.
"""

from __future__ import annotations

import functools
import sys
import threading
import time
from collections.abc import Callable
from contextlib import contextmanager
from typing import Any, TypeAlias, cast

import numpy as np
from numba import typeof

from truestep.reference_impl import tiles
from truestep.reference_impl.collisions_kernels import Plane
from truestep.reference_impl.forces_kernels import (
    Anchors,
    Drag,
    Gravitation,
    Gravity,
    Impulses,
    Springs,
)
from truestep.reference_impl.integrate_kernels import DrivenRun, drive, run, unwatched
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.particles_kernels import Particles, Scene, flat_derivative
from truestep.reference_impl.solvers.any_method import AnyMethod, fused_kinds, pattern
from truestep.reference_impl.solvers.explicit_rk_kernels import Tableau
from truestep.reference_impl.solvers.splitting_kernels import KickDrift, KickDriftKick
from truestep.reference_impl.tiles import BLOCK, Fused, Passes

CompiledRun = DrivenRun
"""What :func:`run_compiled` returns (with its wall time)."""

SLOW_S = 0.5
"""Compiling (or loading from numba's cache) that takes longer than this is shown."""

_Vec3: TypeAlias = tuple[float, float, float]
"""A point, direction or acceleration as the compiled kinds hold it."""


def method_kind(method: str | type):
    """The compiled step of a fixed-step method, from its facts on its solver class: its
    tableau (:class:`Tableau`) or its splitting (:class:`KickDrift`, or
    :class:`KickDriftKick` for a half kick); ``None`` if it has neither."""
    from truestep.reference_impl.solvers import get_solver
    from truestep.reference_impl.solvers.explicit_rk import ExplicitRungeKutta

    try:
        cls = get_solver(method)
    except KeyError:
        return None
    if issubclass(cls, ExplicitRungeKutta):
        return Tableau.of(cls.A, cls.B, cls.nodes())
    s = getattr(cls, "splitting", None)
    if s is None:
        return None
    return (
        KickDrift(float(s.old), float(s.new), 1)
        if s.kick == 1.0
        else KickDriftKick(float(s.kick), float(s.old), float(s.new))
    )


def compiled_reason(model: ParticleModel | None, method: str | type) -> str | None:
    """Why ``method`` on ``model`` cannot take the compiled path, or ``None`` if it can."""
    if model is not None and method_kind(method) is None:
        return f"{method} is not a fixed-step explicit method"
    return _scene_reason(model)


def _scene_reason(model: ParticleModel | None) -> str | None:
    """Why no compiled kernel holds ``model``'s forces, or ``None``: an ODE case, force
    fields, emitters."""
    if model is None:
        return "an ODE case (its system is Python code)"
    if model.fields:
        return "force fields"
    if model.emitters:
        return "emitters"
    return None


def independent(model: ParticleModel) -> bool:
    """Whether no particle of ``model`` acts on another (no springs between particles, no
    gravitation): every force it declares is pointwise, and a method that carries nothing
    over the whole scene from step to step steps it in fused tiles (:func:`layout_for`)."""
    return not len(model.springs) and model.gravitation is None


def _f64(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _i64(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.int64)


def forces_of(m: ParticleModel) -> tuple:
    """The force kinds ``m`` declares, in the order of :func:`forces.add_model_forces`."""
    kinds: list = []
    if np.any(m.gravity):
        kinds.append(Gravity(cast(_Vec3, tuple(float(g) for g in m.gravity))))
    if m.drag:
        kinds.append(Drag(float(m.drag)))
    s, a = m.springs, m.anchors
    if len(s):
        kinds.append(Springs(_i64(s.i), _i64(s.j), _f64(s.stiffness), _f64(s.damping), _f64(s.rest)))
    if len(a):
        order, start = _grouped(_i64(a.i), m.n)
        kinds.append(
            Anchors(
                _i64(a.i),
                _f64(np.reshape(a.point, (-1, 3)).T),
                _f64(a.stiffness),
                _f64(a.damping),
                _f64(a.rest),
                start,
                order,
            )
        )
    if m.gravitation is not None:
        kinds.append(Gravitation(float(m.gravitation.G), float(m.gravitation.softening)))
    return tuple(kinds)


def _grouped(particle: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Entries acting on particles ``particle`` (int, (k,)) grouped by particle, each
    particle's in their order: ``order`` (k,) and ``start`` (n + 1,), particle ``p``'s
    being ``order[start[p]:start[p + 1]]``."""
    order = np.argsort(particle, kind="stable")
    start = np.zeros(n + 1, dtype=np.int64)
    np.add.at(start, particle + 1, 1)
    return _i64(order), _i64(np.cumsum(start))


def impulses_of(m: ParticleModel) -> Impulses | None:
    """The impulses of ``m`` grouped by particle, each particle's in the case's order."""
    if not m.impulses:
        return None
    particle = _i64([i for i, _, _, _ in m.impulses])
    order, start = _grouped(particle, m.n)
    force = _f64([f for _, f, _, _ in m.impulses]).reshape(-1, 3)[order].T
    on = _f64([t0 for _, _, t0, _ in m.impulses])[order]
    off = _f64([t1 for _, _, _, t1 in m.impulses])[order]
    return Impulses(start, _f64(force), on, off, np.flatnonzero(start[1:] > start[:-1]), 0)


def pack(m: ParticleModel) -> Scene:
    """``m`` as a compiled step reads it (:class:`~truestep.reference_impl.particles_kernels.Scene`)."""
    fixed = np.asarray(m.fixed, dtype=bool)
    mass = _f64(m.mass)
    particles = Particles(
        mass,
        _f64(np.where(fixed, 0.0, 1.0 / mass)),
        _f64(m.radius),
        np.ascontiguousarray(~fixed),
        _f64(np.where(fixed, 0.0, mass)),
    )
    planes = tuple(
        Plane(
            cast(_Vec3, tuple(float(c) for c in p.point)),
            cast(_Vec3, tuple(float(c) for c in p.normal)),
            float(p.restitution),
            float(p.friction),
            float(p.thickness),
        )
        for p in m.planes
    )
    return Scene(particles, forces_of(m), impulses_of(m), planes or None)


def pointwise(scene: Scene) -> bool:
    """Whether every force kind of ``scene`` is pointwise (its particles independent)."""
    return all(type(k).pointwise for k in scene.forces)


def layout_for(kind, scene: Scene):
    """Fused tiles of :data:`BLOCK` particles where every force is pointwise (one tile of
    the whole scene for a method that carries state from step to step over it); else
    passes over one tile."""
    n = len(scene.particles.mass)
    if pointwise(scene):
        return Fused(max(n, 1) if kind.carries_state else BLOCK)
    return Passes(max(n, 1))


@functools.cache
def _fused_methods() -> tuple:
    """The compiled steps of the built-in methods."""
    from truestep.reference_impl.solvers import METHODS

    return tuple(k for k in (method_kind(m) for m in METHODS) if k is not None)


def loop_kind(kind, layout, scene: Scene) -> tuple:
    """(the record a loop is called with for ``kind``, what the loop holds): an
    :class:`AnyMethod`, and, fused, the fused steps of every built-in method and ``kind``
    (:func:`fused_kinds`), in passes, every shape of step. One loop a scene and layout
    runs every method."""
    if isinstance(layout, Fused):
        patterns, steps = fused_kinds((*_fused_methods(), kind))
        return AnyMethod.of(kind, patterns), steps
    return AnyMethod.of(kind), AnyMethod.of(kind)


def stages(kind) -> int:
    """The stages a compiled step of ``kind`` keeps in its scratch (0 for a splitting)."""
    return kind.stages if isinstance(kind, (Tableau, AnyMethod)) else 0


_PREPARED: dict[tuple, Any] = {}
"""The compiled loops of this process, by :func:`composition`."""


def composition(held, layout, scene: Scene) -> tuple:
    """What a compiled loop depends on, in short: the classes of the scene's force kinds,
    whether it has impulses, its number of planes, the layout and the steps the loop holds
    (``held``, :func:`loop_kind`; fused, its tableaux' patterns of non-zero entries). Runs
    that agree on it share one loop."""
    planes = len(cast(tuple, scene.planes)) if scene.planes is not None else 0
    kinds = (tuple(type(k) for k in scene.forces), scene.impulses is not None, planes, type(layout))
    if isinstance(layout, Fused):
        return (*kinds, tuple((field, pattern(k) if field == "tableau" else ()) for field, k in held))
    return (*kinds, type(held))


def describe(held, layout, scene: Scene) -> str:
    """What a compiled loop is for, in words: its force kinds, planes, steps and layout."""
    parts = [type(k).__name__.lower() for k in scene.forces]
    if scene.impulses is not None:
        parts.append("impulses")
    if scene.planes is not None:
        parts.append(f"{len(cast(tuple, scene.planes))} plane(s)")
    return f"{', '.join(parts) or 'no forces'} / every method / {type(layout).__name__.lower()}"


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


@contextmanager
def _shown_if_slow(label: str, say: Callable[[str], None]):
    """Say ``compiling ... <label>`` if the block runs longer than :data:`SLOW_S`, and how
    long it took once it is done."""
    began = time.perf_counter()
    line = f"compiling reference kernels for {label} ..."
    timer = threading.Timer(SLOW_S, say, (line,))
    timer.daemon = True
    if SLOW_S > 0:
        timer.start()
    else:
        say(line)
    try:
        yield
    finally:
        timer.cancel()
        if time.perf_counter() - began >= SLOW_S:
            say(f"compiled reference kernels for {label} in {time.perf_counter() - began:.1f} s")


def prepared(model: ParticleModel, method: str, *, progress: Callable[[str], None] | None = None) -> tuple:
    """The packed run of ``method`` on ``model``: (loop, kind, layout, scene), the loop
    compiled or loaded from the cache (shown through ``progress``, stderr by default,
    when slow). The loop is the compiled function itself (``Dispatcher.get_overload``):
    calling it skips the dispatcher's typing of the arguments (microseconds for the
    scene's tuples, more than a small run's stepping)."""
    reason = compiled_reason(model, method)
    if reason is not None:
        raise ValueError(f"the compiled path cannot run {method} here: {reason}")
    scene = pack(model)
    layout = layout_for(method_kind(method), scene)
    kind, held = loop_kind(method_kind(method), layout, scene)
    key = composition(held, layout, scene)
    if key in _PREPARED:
        return _PREPARED[key], kind, layout, scene
    loop = drive
    if not hasattr(loop, "overloads"):  # NUMBA_DISABLE_JIT: the composition runs as Python
        _PREPARED[key] = loop
        return loop, kind, layout, scene
    sig = tuple(
        typeof(a)
        for a in (
            kind,
            layout,
            1,
            0,
            1,
            scene,
            np.zeros((3, 1)),
            np.zeros((3, 1)),
            1.0,
            1,
            np.zeros(1, bool),
            tiles.scratch(1, stages(kind), len(model.planes)),
            np.zeros((1, 1, 3)),
            np.zeros((1, 1, 3)),
            np.zeros(1),
            unwatched(),
        )
    )
    if sig not in loop.overloads:
        with _shown_if_slow(describe(held, layout, scene), progress or _stderr):
            loop.compile(sig)
    _PREPARED[key] = loop.get_overload(sig)
    return _PREPARED[key], kind, layout, scene


def derivative_reason(model: ParticleModel | None) -> str | None:
    """Why the compiled path cannot make ``model``'s derivative (:func:`derivative_for`),
    or ``None`` if it can."""
    reason = _scene_reason(model)
    if reason is None and model is not None and model.planes:
        return "planes (a collision pass sets their contact between steps)"
    return reason


def _derivative_args(model: ParticleModel) -> tuple:
    """The arguments of :func:`particles_kernels.flat_derivative` for ``model`` (the state,
    time and output placeholders) and their numba types: (args, signature)."""
    scene = pack(model)
    n = model.n
    scratch = tuple(np.zeros((3, n)) for _ in range(4))
    args = (scene, np.zeros(6 * n), 0.0, np.zeros(6 * n), *scratch, np.zeros((0, n), dtype=np.bool_))
    return args, tuple(typeof(a) for a in args)


def derivative_key(model: ParticleModel) -> tuple:
    """What a compiled derivative depends on: the types of its arguments."""
    return ("derivative", _derivative_args(model)[1])


def derivative_for(
    model: ParticleModel | None, *, progress: Callable[[str], None] | None = None
) -> Callable[[np.ndarray, float], np.ndarray] | None:
    """The derivative of ``model``'s particle system compiled (or loaded from numba's
    cache, shown through ``progress`` when slow): a function of a flat state ``y`` (6 n,:
    positions (n, 3) then velocities, m and m/s) and a time ``t`` (s) that returns
    ``dy/dt`` (6 n,), bit for bit :meth:`ParticleSystem.derivative` (tested on every case
    it compiles), for an integrator outside truestep that calls a derivative (Drake's).
    ``None`` where :func:`derivative_reason` says the compiled path cannot make it."""
    if derivative_reason(model) is not None:
        return None
    assert model is not None
    args, sig = _derivative_args(model)
    key = ("derivative", sig)
    if key not in _PREPARED:
        scene = args[0]
        loop = flat_derivative
        if hasattr(loop, "overloads"):  # else NUMBA_DISABLE_JIT: the composition runs as Python
            if sig not in loop.overloads:
                kinds = ", ".join(type(k).__name__.lower() for k in scene.forces) or "no forces"
                with _shown_if_slow(f"the derivative of {kinds}", progress or _stderr):
                    loop.compile(sig)
            loop = loop.get_overload(sig)
        _PREPARED[key] = loop
    entry = _PREPARED[key]
    scene, _, _, _, X, V, F, A, contact = args
    dim = 6 * model.n

    def derivative(y: np.ndarray, t: float) -> np.ndarray:
        out = np.empty(dim)
        entry(scene, np.ascontiguousarray(y, dtype=np.float64), float(t), out, X, V, F, A, contact)
        return out

    return derivative


def run_compiled(
    model: ParticleModel,
    method: str,
    duration: float,
    h: float,
    *,
    max_records: int = 2000,
    track_energy: bool = False,
    progress: Callable[[str], None] | None = None,
    threads: int = 1,
) -> tuple[CompiledRun, float]:
    """Run ``method`` on ``model`` for ``round(duration / h)`` steps of ``h`` s; return the
    run and the wall time of the stepping (s, the compiled loop only: packing the scene,
    compiling and allocating the records happen before it). With ``track_energy`` the
    run's ``extra`` holds ``energy_min`` and ``energy_max`` (J) over every step.
    ``threads``: how many threads step the tiles of a scene of independent particles at
    once (:func:`integrate_kernels.run`; the same numbers as one)."""
    loop, kind, layout, scene = prepared(model, method, progress=progress)
    result = run(
        loop,
        kind,
        layout,
        scene,
        model.x0,
        model.v0,
        h,
        round(duration / h),
        stages=stages(kind),
        planes=len(model.planes),
        max_records=max_records,
        track_energy=track_energy,
        threads=threads,
    )
    return result, result.wall_s
