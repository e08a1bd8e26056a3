"""The fillings of a compiled step's slots for one layout and the methods its loop holds.

:mod:`~truestep.reference_impl.compose` compiles the driver written once against slots;
this module says what fills each slot for a layout (:func:`compiled.layout_for`) and the
methods' compiled steps (:func:`compiled.method_kind`): the layout's first pass and its
step over a tile, or, fused, each method's step of one particle. What a scene holds (its
force kinds, impulses and planes) fills no slot: numba picks their kernels by the scene's
types (:mod:`~truestep.reference_impl.by_type`), so every scene of a layout shares one
loop, compiled once for each combination of types. :func:`loop_for` returns the driver
compiled with them.
"""

from __future__ import annotations

from truestep.reference_impl import compose, integrate_kernels, particles_kernels, tiles
from truestep.reference_impl.compose import (
    cache_name,
    glue,
    instantiate,
)
from truestep.reference_impl.solvers.any_method import KICK_DRIFT, KICK_DRIFT_KICK, TABLEAU
from truestep.reference_impl.tiles import Passes


def slots_for(kind, layout) -> dict:
    """Every slot of the driver (:mod:`compose`) filled for a scene stepped in
    ``layout`` by ``kind``: in passes, its own step over a tile (every method's, for an
    :class:`AnyMethod`); fused, the fused step (:func:`tiles.fused_step`) of each of the
    loop's fused steps (``kind``, a tuple: :func:`fused_kinds`), picked once a step."""
    slots: dict = {"start": type(layout).start}
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


def derivative_loop():
    """:func:`particles_kernels.flat_derivative` compiled for scenes without planes (not
    yet compiled: numba compiles it for a scene's types when it is first called)."""
    slots: dict = {}
    name = cache_name("derivative", slots)
    if name not in _LOOPS:
        _LOOPS[name] = instantiate(particles_kernels.flat_derivative, slots, name=name, options=compose.LOOP)
    return _LOOPS[name]


def loop_for(kind, layout):
    """The driver composed for ``kind`` in ``layout`` (not yet compiled: numba compiles
    it for a scene's types, or loads it from its cache, when it is first called)."""
    slots = slots_for(kind, layout)
    name = cache_name("drive", slots)
    if name not in _LOOPS:
        _LOOPS[name] = instantiate(integrate_kernels.drive, slots, name=name, options=compose.LOOP)
    return _LOOPS[name]
