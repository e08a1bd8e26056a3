"""The fillings of a compiled step's slots for one scene and method.

:mod:`~truestep.reference_impl.compose` compiles the driver written once against slots;
this module says what fills each slot for a packed scene (:func:`compiled.pack`), a
method's compiled step (:func:`compiled.method_kind`) and a layout
(:func:`compiled.layout_for`): the kernels of the force kinds the scene declares, called
in order by a line of glue each; its impulses' and planes' kernels, or nothing; the
method's step over a tile, or, fused, its step of one particle. :func:`loop_for` returns
the driver compiled with them.
"""

from __future__ import annotations

from typing import Any, cast

from truestep.reference_impl import compose, integrate_kernels, particles_kernels, tiles
from truestep.reference_impl.compose import (
    cache_name,
    glue,
    instantiate,
    name_of,
    nothing,
)
from truestep.reference_impl.forces_kernels import impulse_at, impulses_add
from truestep.reference_impl.particles_kernels import Scene
from truestep.reference_impl.solvers.any_method import KICK_DRIFT, KICK_DRIFT_KICK, TABLEAU
from truestep.reference_impl.tiles import Passes


def _kernel_calls(kinds: tuple, role: str, call: str) -> tuple[list[str], dict]:
    """Lines calling each kind's kernel ``role`` as ``call`` (formatted with the kernel's
    name and the kind's index), and the names they use."""
    names = {name_of(getattr(type(k), role)): getattr(type(k), role) for k in kinds}
    lines = [call.format(fn=name_of(getattr(type(k), role)), i=i) for i, k in enumerate(kinds)]
    return lines, names


def force_slots(scene: Scene) -> dict:
    """The fillings of the derivative's slots (:mod:`particles_kernels`) for ``scene``."""
    P, S = particles_kernels, scene
    kinds, pointwise = S.forces, all(type(k).pointwise for k in S.forces)
    adds, add_names = _kernel_calls(kinds, "add", "{fn}(scene.forces[{i}], F, X, V, t, scene.particles)")
    ats, at_names = _kernel_calls(
        kinds if pointwise else (), "at", "f = {fn}(scene.forces[{i}], f, x, v, t, scene.particles, p)"
    )
    energies, e_names = _kernel_calls(kinds, "energy", "e += {fn}(scene.forces[{i}], X, scene.particles)")
    kicked = S.impulses is not None
    return {
        "add_forces": glue(P.add_forces, adds, add_names),
        "point_force": glue(P.point_force, ["f = (0.0, 0.0, 0.0)", *ats, "return f"], at_names),
        "potential_energy": glue(P.potential_energy, ["e = 0.0", *energies, "return e"], e_names),
        "add_impulses": (
            glue(
                P.add_impulses,
                ["impulses_add(scene.impulses, F, X, V, t, scene.particles)"],
                {"impulses_add": impulses_add},
            )
            if kicked
            else nothing(P.add_impulses)
        ),
        "point_impulses": (
            glue(
                P.point_impulses,
                ["return impulse_at(scene.impulses, f, None, None, t, scene.particles, p)"],
                {"impulse_at": impulse_at},
            )
            if kicked
            else nothing(P.point_impulses, "f")
        ),
        "kicked": (
            glue(tiles.kicked, ["return scene.impulses.start[p + 1] > scene.impulses.start[p]"], {})
            if kicked
            else nothing(tiles.kicked, "False")
        ),
        "list_kicked": (
            glue(
                tiles.list_kicked,
                [
                    "k = scene.impulses.kicked",
                    "for q in range(k.shape[0]):",
                    "    special[q] = k[q] - scene.impulses.first",
                    "return k.shape[0]",
                ],
                {},
            )
            if kicked
            else nothing(tiles.list_kicked, "0")
        ),
        "cut": cut_glue(S),
    }


def cut_glue(scene: Scene):
    """The filling of the driver's slot ``cut``: ``scene`` for a tile of its particles,
    each pointwise kind cut by its ``cut`` kernel (the others are never cut: such a scene
    is one tile)."""
    names = {"Scene": Scene, "tile_particles": particles_kernels.tile_particles}
    parts = []
    for i, k in enumerate(scene.forces):
        cut = getattr(type(k), "cut", None)
        if cut is None:
            parts.append(f"scene.forces[{i}]")
        else:
            names[name_of(cut)] = cut
            parts.append(f"{name_of(cut)}(scene.forces[{i}], lo, hi)")
    impulses = "scene.impulses"
    if scene.impulses is not None:
        names["impulses_cut"] = type(cast(Any, scene.impulses)).cut  # set by @carries
        impulses = "impulses_cut(scene.impulses, lo, hi)"
    kinds = "".join(f"{part}, " for part in parts)
    return glue(
        integrate_kernels.cut,
        [f"return Scene(tile_particles(scene.particles, lo, hi), ({kinds}), {impulses}, scene.planes)"],
        names,
    )


def plane_slots(layout, scene: Scene) -> dict:
    """The fillings of the collision slots (:mod:`tiles`) for ``scene`` in ``layout``."""
    T = tiles
    if scene.planes is None:
        return {
            "add_contact": nothing(particles_kernels.add_contact),
            "point_contact": nothing(T.point_contact, "f"),
            "near_planes": nothing(T.near_planes, "False"),
            "collisions": nothing(T.collisions, "False"),
        }
    near = " | ".join(
        f"near_plane(scene.planes[{k}], x, radius)" for k in range(len(cast(tuple, scene.planes)))
    )
    return {
        "add_contact": particles_kernels.add_contact_forces,
        "point_contact": glue(
            T.point_contact,
            ["return resting_force(scene, f, v, tile.contact, p)"],
            {"resting_force": particles_kernels.resting_force},
        ),
        "near_planes": glue(T.near_planes, [f"return {near}"], {"near_plane": T.near_plane}),
        "collisions": type(layout).collide,
    }


def slots_for(kind, layout, scene: Scene) -> dict:
    """Every slot of the driver (:mod:`compose`) filled for ``scene`` stepped in
    ``layout`` by ``kind``: in passes, its own step over a tile (every method's, for an
    :class:`AnyMethod`); fused, the fused step (:func:`tiles.fused_step`) of each of the
    loop's fused steps (``kind``, a tuple: :func:`fused_kinds`), picked once a step."""
    slots = {**force_slots(scene), **plane_slots(layout, scene), "start": type(layout).start}
    if isinstance(layout, Passes):
        slots["step"] = type(kind).passes
        return slots
    return fused_slots(slots, kind)


def fused_slots(slots: dict, steps: tuple) -> dict:
    """``slots`` with the step of a fused loop (:func:`tiles.fused_step`), its particles
    stepped by :func:`tiles.fused_particles` made once for each of ``steps`` ((field of
    :class:`AnyMethod`, step) each: :func:`fused_kinds`) with its own step of one particle
    (a tableau's unrolled), picked once a step by the :class:`AnyMethod` the loop is
    given; the special particles' steps (a tableau's in a loop, a splitting's) alike."""
    smooth = {**slots, "point_accel": tiles.smooth_accel}
    special = {**slots, "point_accel": tiles.special_accel}
    names: dict[str, object] = {"TABLEAU": TABLEAU, "KICK_DRIFT": KICK_DRIFT, "FRESH": tiles.FRESH}
    lines, specials = [], []
    for i, (field, kind) in enumerate(steps):
        shape = f"method.shape == {field.upper()}"
        test = f"{shape} and method.pattern == {i}" if field == "tableau" else shape
        point = instantiate(kind.point_step(), smooth, _memo={})
        slots[f"point_step_{i}"] = point
        names[f"particles_{i}"] = instantiate(tiles.fused_particles, {**slots, "point_step": point}, _memo={})
        made = (
            "2 if tile.count[FRESH] else 1" if field == "kick_drift_kick" else f"method.{field}.evaluations"
        )
        lines += [
            f"if {test}:",
            f"    n = {made}",
            f"    particles_{i}(method.{field}, scene, tile, t, h)",
            "    return n",
        ]
        if f"special_{field}" not in names:
            names[f"special_{field}"] = instantiate(
                kind.special_step(), special, _memo={}, options=compose.COPY_COLD
            )
            specials += [
                f"if {shape}:",
                f"    return special_{field}(method.{field}, scene, tile, x, v, t, h, p)",
            ]
    names["KICK_DRIFT_KICK"] = KICK_DRIFT_KICK
    slots["step_particles"] = glue(tiles.step_particles, [*lines, "return -1"], names)
    slots["special_step"] = glue(tiles.special_step, [*specials, "return x, v"], names)
    slots["step"] = tiles.fused_step
    return slots


_LOOPS: dict[str, object] = {}
"""The loops composed in this process, by :func:`compose.cache_name`."""


def derivative_loop(scene: Scene):
    """:func:`particles_kernels.flat_derivative` composed for ``scene`` (a scene without
    planes; not yet compiled)."""
    slots = {**force_slots(scene), **plane_slots(None, scene)}
    name = cache_name("derivative", slots)
    if name not in _LOOPS:
        _LOOPS[name] = instantiate(particles_kernels.flat_derivative, slots, name=name, options=compose.LOOP)
    return _LOOPS[name]


def loop_for(kind, layout, scene: Scene):
    """The driver composed for ``scene`` and ``kind`` in ``layout`` (not yet compiled:
    numba compiles it, or loads it from its cache, when it is first called)."""
    slots = slots_for(kind, layout, scene)
    name = cache_name("drive", slots)
    if name not in _LOOPS:
        _LOOPS[name] = instantiate(integrate_kernels.drive, slots, name=name, options=compose.LOOP)
    return _LOOPS[name]
