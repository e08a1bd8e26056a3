"""Scene parts that expand into many particles: mass-spring meshes and emitter pools.

A ``[[scene.meshes]]`` table builds one mass-spring object of
:mod:`truestep.reference_impl.meshes`::

    [[scene.meshes]]
    kind = "cube"            # triangle, tetrahedron, cube, rope, cloth
    size = 1.0               # edge, m
    center = [0, 0.5, 0]     # m (default: the origin)
    bracing = "volume"       # edges (default), faces, volume
    mass = 1.0               # the whole object's, kg, spread evenly over the vertices
    stiffness = 200.0        # every spring, N/m
    damping = 1.0            # every spring, N s/m (default 0)
    velocity = [0, 0, 0]     # every vertex, m/s (default 0)
    radius = 0.0             # every vertex's collision radius, m (default 0)
    pinned = [0, 1]          # local vertex numbers that never move (default none)

The fields that place the mesh depend on its kind: a tetrahedron takes ``size`` and
``center`` like a cube (no ``bracing``); a triangle ``side`` and ``center``; a rope
``count`` (vertices), ``start`` and ``end``; a cloth ``rows``, ``cols``, ``spacing``,
``origin`` and optionally the unit grid directions ``u`` and ``w``, and
``shear_stiffness`` and ``bend_stiffness`` (default: ``stiffness``). Vertex numbers are
those of the builders in :mod:`truestep.reference_impl.meshes`; the mesh's particles follow the
``[[scene.particles]]`` groups and earlier meshes in the global numbering.

A ``[[scene.emitters]]`` table is an :class:`~truestep.reference_impl.model.EmitterSpec`, with the
same field names (``shape``, ``center``, ``size``, ``normal`` for a plane, ``rate_n``,
``rate_r``, ``per_area``, ``speed``, ``speed_jitter``, ``spread``, ``lifetime``,
``lifetime_jitter``, ``frame_dt``, ``capacity``, ``particle_mass``, ``particle_size``,
``size_jitter``, ``color_birth``, ``color_death``, ``fade_height``, ``seed``). The pool
must hold the largest possible population, ``ceil(n + r) x (lifetime + jitter)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from truestep.cases.fields import Fields, short
from truestep.cases.limits import MIN_STEP_S, Budget
from truestep.reference_impl import meshes
from truestep.reference_impl.emitters import spawn_mean
from truestep.reference_impl.model import EmitterSpec, Springs


@dataclass
class MeshPart:
    """Particles and springs with local numbering (0..n-1), before offsetting.

    mass (n,) kg, x0 and v0 (n, 3), radius (n,) m, fixed (n,) bool, springs local;
    faces (k, 3) local, outward, for a closed mesh (``None`` otherwise).
    """

    mass: np.ndarray
    x0: np.ndarray
    v0: np.ndarray
    radius: np.ndarray
    fixed: np.ndarray
    springs: Springs
    faces: np.ndarray | None = None

    @classmethod
    def pool(cls, capacity: int, mass: float) -> MeshPart:
        """An emitter's pool: ``capacity`` particles, all dead until spawned."""
        z = np.zeros((capacity, 3))
        return cls(
            np.full(capacity, mass),
            z,
            z.copy(),
            np.zeros(capacity),
            np.zeros(capacity, bool),
            Springs.empty(),
        )


MESH_KINDS: set[str] = {"triangle", "tetrahedron", "cube", "rope", "cloth"}
EMITTER_SHAPES = {"cube", "plane"}


def read_mesh(f: Fields, budget: Budget) -> MeshPart:
    """Build a mass-spring mesh from a ``[[scene.meshes]]`` table, charging ``budget`` with
    its particles and springs before it is built."""
    kind = f.string("kind", choices=MESH_KINDS)
    mesh = _build(f, kind, budget)
    n = len(mesh.vertices)
    stiffness = f.number("stiffness", positive=True)
    per_kind = np.full(len(mesh.edges), stiffness)
    if kind == "cloth":
        per_kind[mesh.kind == 1] = f.number("shear_stiffness", stiffness, positive=True)
        per_kind[mesh.kind == 2] = f.number("bend_stiffness", stiffness, positive=True)
    mass, springs = meshes.mass_spring(
        mesh, f.number("mass", positive=True), per_kind, f.number("damping", 0.0, nonnegative=True)
    )
    velocity = f.vec3("velocity", [0.0, 0.0, 0.0])
    radius = f.number("radius", 0.0, nonnegative=True)
    pinned = f.raw("pinned", [])
    if isinstance(pinned, list) and len(pinned) > n:
        raise f.error("pinned", f"{len(pinned)} vertex numbers for a {kind} of {n} vertices")
    if not isinstance(pinned, list) or not all(
        isinstance(i, int) and not isinstance(i, bool) for i in pinned
    ):
        raise f.error("pinned", f"expected a list of vertex numbers, got {short(pinned)}")
    bad = [i for i in pinned if not 0 <= i < n]
    if bad:
        raise f.error("pinned", f"vertex {bad[0]} out of range 0..{n - 1} of this {kind}")
    fixed = np.zeros(n, bool)
    fixed[pinned] = True
    f.done()
    return MeshPart(
        mass, mesh.vertices, np.tile(velocity, (n, 1)), np.full(n, radius), fixed, springs, mesh.faces
    )


SMALL_MESHES = {"triangle": (3, 3), "tetrahedron": (4, 6), "cube": (8, 28)}
"""Vertices and (at most) springs of the meshes of fixed size."""


def _build(f: Fields, kind: str, budget: Budget) -> meshes.Mesh:
    """The mesh of the builder named ``kind``, from its own fields."""
    if kind in SMALL_MESHES:
        vertices, springs = SMALL_MESHES[kind]
        budget.take(f, "kind", particles=vertices, springs=springs)
    if kind == "rope":
        count = f.integer("count", minimum=2)
        budget.take(f, "count", particles=count, springs=count - 1)
        start, end = f.vec3("start"), f.vec3("end")
        if np.array_equal(start, end):
            raise f.error("end", "a rope needs distinct start and end points")
        return meshes.rope(count, start, end)
    if kind == "cloth":
        rows, cols = f.integer("rows", minimum=2), f.integer("cols", minimum=2)
        budget.take(f, "rows", particles=rows * cols, springs=6 * rows * cols)
        spacing = f.number("spacing", positive=True)
        origin = f.vec3("origin", [0.0, 0.0, 0.0])
        u, w = _unit(f, "u", [1.0, 0.0, 0.0]), _unit(f, "w", [0.0, 0.0, -1.0])
        if abs(float(u @ w)) > 1e-9:
            raise f.error("w", "the grid directions u and w must be perpendicular")
        return meshes.cloth(rows, cols, spacing, origin, u, w)
    center = f.vec3("center", [0.0, 0.0, 0.0])
    if kind == "triangle":
        return meshes.triangle(f.number("side", positive=True), center)
    size = f.number("size", positive=True)
    if kind == "tetrahedron":
        return meshes.tetrahedron(size, center)
    return meshes.cube(size, center, f.string("bracing", "edges", choices=set(meshes.CUBE_BRACING)))


def _unit(f: Fields, name: str, default: list[float]) -> np.ndarray:
    vec = f.vec3(name, default)
    norm = float(np.linalg.norm(vec))
    if norm == 0:
        raise f.error(name, "must not be the zero vector")
    return vec / norm


def read_emitter(f: Fields) -> EmitterSpec:
    """Read a ``[[scene.emitters]]`` table (fields as in :class:`EmitterSpec`)."""
    shape = f.string("shape", choices=EMITTER_SHAPES)
    normal = np.array([0.0, 1.0, 0.0])
    if shape == "plane":
        normal = _unit(f, "normal", [0.0, 1.0, 0.0])
    elif f.has("normal"):
        raise f.error("normal", "only a plane emitter has a normal (a cube sprays from all faces)")
    lifetime = f.integer("lifetime", minimum=1, maximum=10**9)
    jitter = f.integer("lifetime_jitter", 0, minimum=0, maximum=10**9)
    if jitter >= lifetime:
        raise f.error(
            "lifetime_jitter", f"must be below lifetime ({lifetime}) so every life lasts at least one frame"
        )
    spec = EmitterSpec(
        shape=shape,
        center=f.vec3("center"),
        size=f.number("size", positive=True),
        rate_n=f.number("rate_n", nonnegative=True),
        rate_r=f.number("rate_r", 0.0, nonnegative=True),
        speed=f.number("speed", nonnegative=True),
        spread=f.number("spread", 0.0, nonnegative=True, at_most=math.pi),
        lifetime=lifetime,
        lifetime_jitter=jitter,
        frame_dt=f.number("frame_dt", 1.0 / 30.0, at_least=MIN_STEP_S),
        capacity=f.integer("capacity", minimum=1),
        per_area=f.boolean("per_area", False),
        normal=normal,
        particle_mass=f.number("particle_mass", 1.0, positive=True),
        seed=f.integer("seed", 0, minimum=0, maximum=2**63 - 1),
        speed_jitter=f.number("speed_jitter", 0.0, nonnegative=True, at_most=1.0),
        particle_size=f.number("particle_size", 0.01, positive=True),
        size_jitter=f.number("size_jitter", 0.0, nonnegative=True, at_most=1.0),
        color_birth=_color(f, "color_birth", [1.0, 0.9, 0.5]),
        color_death=_color(f, "color_death", [0.6, 0.1, 0.0]),
        fade_height=f.number("fade_height", 1.0, positive=True),
    )
    per_frame = spawn_mean(spec) + spec.rate_r
    if not per_frame < 1e15:
        raise f.error("rate_n", f"spawns {per_frame:.3g} particles per frame: no pool holds that")
    most = math.ceil(per_frame) * (lifetime + jitter)
    if spec.capacity < most:
        raise f.error(
            "capacity",
            f"the pool must hold the largest population, "
            f"ceil(n + r) x (lifetime + jitter) = {most}, got {spec.capacity}",
        )
    f.done()
    return spec


def _color(f: Fields, name: str, default: list[float]) -> np.ndarray:
    rgb = f.vec3(name, default)
    if np.any(rgb < 0) or np.any(rgb > 1):
        raise f.error(name, f"RGB components must lie in 0..1, got {rgb.tolist()}")
    return rgb
