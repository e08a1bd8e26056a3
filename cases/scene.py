"""Read the ``[scene]`` table of a case file into a :class:`ParticleModel`.

Particles are numbered in the order they are declared: the groups of
``[[scene.particles]]`` first, then each ``[[scene.meshes]]`` in turn. Springs and
anchors refer to those global numbers.
"""

from __future__ import annotations

import numpy as np

from truestep.cases.fields import Fields, short
from truestep.cases.limits import DEFAULT, Budget
from truestep.cases.meshes import MeshPart, read_emitter, read_mesh
from truestep.reference_impl.model import (
    Anchors,
    ForceField,
    Gravitation,
    ParticleModel,
    Plane,
    Springs,
)

FIELD_KINDS = {"vortex", "wind"}
FIELD_PARAMS: dict[str, dict[str, str]] = {
    "vortex": {"center": "point", "axis": "direction", "strength": "number", "core": "positive"},
    "wind": {
        "direction": "direction",
        "speed": "number",
        "gust": "number",
        "freq": "nonnegative",
        "k": "nonnegative",
    },
}
"""Each field kind's parameters and what they must be (see
:func:`truestep.reference_impl.forces.field_force`)."""
FIELD_REQUIRED = {"vortex": {"strength"}, "wind": {"direction"}}


def read_scene(f: Fields, budget: Budget | None = None) -> ParticleModel:
    """Build the model described by the ``scene`` table ``f``; ``budget`` (default: the
    default limits) is charged with every part's particles and springs before it is built."""
    budget = budget or Budget(DEFAULT)
    dimension = f.integer("dimension", 3)
    if dimension not in (2, 3):
        raise f.error("dimension", f"must be 2 or 3, got {dimension}")
    parts = [_read_particles(p, budget) for p in f.subs("particles")]
    parts += [_read_block(b, dimension, budget) for b in f.subs("blocks")]
    parts += [read_mesh(m, budget) for m in f.subs("meshes")]
    emitters = [read_emitter(e) for e in f.subs("emitters")]
    for i, e in enumerate(emitters):
        budget.take(f, f"emitters[{i}].capacity", particles=e.capacity)
        parts.append(MeshPart.pool(e.capacity, e.particle_mass))

    offsets = np.cumsum([0] + [len(p.mass) for p in parts])
    n = int(offsets[-1])

    def cat(attr: str, width: int | None = None) -> np.ndarray:
        arrays = [getattr(p, attr) for p in parts]
        if not arrays:
            return np.zeros((0, width) if width else 0)
        return np.concatenate(arrays)

    mass, x0, v0 = cat("mass"), cat("x0", 3), cat("v0", 3)
    radius, fixed = cat("radius"), cat("fixed").astype(bool)

    spring_sets = [_offset(p.springs, off) for p, off in zip(parts, offsets, strict=False)]
    spring_sets += [_read_springs(s, x0, n, budget) for s in f.subs("springs")]
    springs = _concat_springs(spring_sets)
    anchor_tables = f.subs("anchors")
    if anchor_tables:
        budget.take(f, "anchors", springs=len(anchor_tables))
    anchors = _read_anchors(anchor_tables, x0, n)

    gravitation = None
    if f.has("gravitation"):
        g = f.sub("gravitation")
        gravitation = Gravitation(
            G=g.number("G", 6.67384e-11, positive=True),
            softening=g.number("softening", 0.0, nonnegative=True),
        )
        g.done()

    model = ParticleModel(
        mass=mass,
        x0=x0,
        v0=v0,
        radius=radius,
        fixed=fixed,
        gravity=f.vec3("gravity", [0.0, 0.0, 0.0]),
        drag=f.number("drag", 0.0, nonnegative=True),
        springs=springs,
        anchors=anchors,
        gravitation=gravitation,
        fields=[_read_field(x) for x in f.subs("fields")],
        planes=[_read_plane(p) for p in f.subs("planes")],
        emitters=emitters,
        impulses=[_read_impulse(i, n) for i in f.subs("impulses")],
        dimension=dimension,
        surfaces=[p.faces + off for p, off in zip(parts, offsets, strict=False) if p.faces is not None],
    )
    f.done()
    if dimension == 2:
        _check_planar(f, model)
    return model


def _read_particles(f: Fields, budget: Budget) -> MeshPart:
    listed = f.raw("position")
    if isinstance(listed, list | np.ndarray):  # charged before any array is built
        budget.take(f, "position", particles=len(listed))
    x0 = f.array("position", shape=(None, 3))
    n = len(x0)
    if n == 0:
        raise f.error("position", "a particle group needs at least one position")
    _same_length(f, "velocity", n)
    v0 = f.array("velocity", np.zeros((n, 3)), shape=(n, 3))
    mass = _per_particle(f, "mass", n, positive=True)
    radius = _per_particle(f, "radius", n, default=0.0)
    fixed_raw = f.raw("fixed", False)
    if isinstance(fixed_raw, bool):
        fixed = np.full(n, fixed_raw)
    elif isinstance(fixed_raw, list) and len(fixed_raw) == n and all(isinstance(v, bool) for v in fixed_raw):
        fixed = np.array(fixed_raw, dtype=bool)
    else:
        raise f.error("fixed", f"expected true, false or a list of {n} of them, got {short(fixed_raw)}")
    f.done()
    return MeshPart(mass, x0, v0, radius, fixed, Springs.empty())


def _read_block(f: Fields, dimension: int, budget: Budget) -> MeshPart:
    """``count`` particles at seeded uniform random positions in the box ``[low, high]``."""
    count = f.integer("count", minimum=1)
    budget.take(f, "count", particles=count)
    low, high = f.vec3("low"), f.vec3("high")
    if np.any(high < low):
        raise f.error("high", "every component must be at least the one of low")
    if dimension == 2 and (low[2] != 0 or high[2] != 0):
        raise f.error("low", "a 2-D scene keeps z = 0: low[2] and high[2] must be 0")
    rng = np.random.default_rng(f.integer("seed", 0, minimum=0, maximum=2**63 - 1))
    x0 = low + (high - low) * rng.random((count, 3))
    v0 = np.tile(f.vec3("velocity", [0.0, 0.0, 0.0]), (count, 1))
    mass = np.full(count, f.number("mass", positive=True))
    radius = np.full(count, f.number("radius", 0.0, nonnegative=True))
    f.done()
    return MeshPart(mass, x0, v0, radius, np.zeros(count, bool), Springs.empty())


def _same_length(f: Fields, name: str, n: int) -> None:
    """A per-particle list must be ``n`` long: checked before its array is built."""
    raw = f.raw(name, None)
    if isinstance(raw, list | np.ndarray) and len(raw) != n:
        raise f.error(name, f"expected {n} entries (one per particle), got {len(raw)}")


def _per_particle(f: Fields, name: str, n: int, *, default=None, positive=False) -> np.ndarray:
    raw = f.raw(name, default) if default is not None else f.raw(name)
    if isinstance(raw, list):
        _same_length(f, name, n)
        arr = f.array(name, shape=(n,))
    else:
        arr = np.full(n, f.number(name, default, nonnegative=True, positive=positive))
    if positive and np.any(arr <= 0):
        raise f.error(name, "every mass must be positive (pin a particle with fixed = true)")
    if np.any(arr < 0):
        raise f.error(name, "must not be negative")
    return arr


def _read_springs(f: Fields, x0: np.ndarray, n: int, budget: Budget) -> Springs:
    listed = f.raw("pairs")
    if isinstance(listed, list | np.ndarray):  # charged before any array is built
        budget.take(f, "pairs", springs=len(listed))
    pairs = f.indices("pairs", n, shape=(None, 2))
    if len(pairs) == 0:
        raise f.error("pairs", "a spring set needs at least one pair")
    if np.any(pairs[:, 0] == pairs[:, 1]):
        raise f.error("pairs", "a spring needs two different particles")
    m = len(pairs)
    length = np.linalg.norm(x0[pairs[:, 0]] - x0[pairs[:, 1]], axis=1)
    rest = np.full(m, f.number("rest", None, nonnegative=True)) if f.has("rest") else length
    springs = Springs(
        pairs[:, 0],
        pairs[:, 1],
        np.full(m, f.number("stiffness", nonnegative=True)),
        np.full(m, f.number("damping", 0.0, nonnegative=True)),
        rest,
    )
    f.done()
    return springs


def _read_anchors(tables: list[Fields], x0: np.ndarray, n: int) -> Anchors:
    if not tables:
        return Anchors.empty()
    rows = []
    for f in tables:
        i = f.integer("particle", minimum=0)
        if i >= n:
            raise f.error("particle", f"index {i} out of range 0..{n - 1}")
        point = f.vec3("point")
        rest = f.number("rest", float(np.linalg.norm(x0[i] - point)), nonnegative=True)
        rows.append(
            (
                i,
                point,
                f.number("stiffness", nonnegative=True),
                f.number("damping", 0.0, nonnegative=True),
                rest,
            )
        )
        f.done()
    return Anchors(
        np.array([r[0] for r in rows]),
        np.array([r[1] for r in rows]),
        np.array([r[2] for r in rows]),
        np.array([r[3] for r in rows]),
        np.array([r[4] for r in rows]),
    )


def _read_plane(f: Fields) -> Plane:
    normal = f.vec3("normal")
    norm = float(np.linalg.norm(normal))
    if not 1e-150 < norm < np.inf:
        raise f.error("normal", f"must be a non-zero vector of finite length, got {short(normal.tolist())}")
    plane = Plane(
        point=f.vec3("point"),
        normal=normal / norm,
        restitution=f.number("restitution", 1.0, nonnegative=True, at_most=1.0),
        friction=f.number("friction", 0.0, nonnegative=True),
        thickness=f.number("thickness", 0.0, nonnegative=True),
    )
    f.done()
    return plane


def _read_field(f: Fields) -> ForceField:
    """A force field: its kind's parameters (:data:`FIELD_PARAMS`), each checked."""
    kind = f.string("kind", choices=FIELD_KINDS)
    params: dict[str, float | list[float]] = {}
    for key in FIELD_REQUIRED[kind]:
        f.raw(key)  # required: raises naming it when missing
    for key, what in FIELD_PARAMS[kind].items():
        if not f.has(key):
            continue
        if what == "point":
            params[key] = f.vec3(key).tolist()
        elif what == "direction":
            vec = f.vec3(key)
            if not 1e-150 < float(np.linalg.norm(vec)) < np.inf:
                raise f.error(key, "must be a non-zero vector of finite length")
            params[key] = vec.tolist()
        else:
            params[key] = f.number(key, positive=what == "positive", nonnegative=what == "nonnegative")
    f.done()
    return ForceField(kind, params)


def _read_impulse(f: Fields, n: int) -> tuple[int, np.ndarray, float, float]:
    i = f.integer("particle", minimum=0)
    if i >= n:
        raise f.error("particle", f"index {i} out of range 0..{n - 1}")
    start = f.number("start", 0.0, nonnegative=True)
    end = f.number("end", positive=True)
    if end <= start:
        raise f.error("end", f"must be after start ({start:g}), got {end:g}")
    impulse = (i, f.vec3("force"), start, end)
    f.done()
    return impulse


def _offset(s: Springs, off: int) -> Springs:
    return Springs(s.i + off, s.j + off, s.stiffness, s.damping, s.rest)


def _concat_springs(sets: list[Springs]) -> Springs:
    sets = [s for s in sets if len(s)]
    if not sets:
        return Springs.empty()
    return Springs(
        *(np.concatenate([getattr(s, a) for s in sets]) for a in ("i", "j", "stiffness", "damping", "rest"))
    )


def _check_planar(f: Fields, m: ParticleModel) -> None:
    if np.any(m.x0[:, 2] != 0) or np.any(m.v0[:, 2] != 0) or m.gravity[2] != 0:
        raise f.error("dimension", "a 2-D scene must keep positions, velocities and gravity at z = 0")
