"""What never changes during a particle simulation: masses, springs, planes, fields.

A :class:`ParticleModel` is the scene as structure-of-arrays (NVIDIA Warp's ``Model``,
MuJoCo's ``MjModel``); the changing state (positions, velocities) lives in the system
that steps it. Every engine adapter reads the same model, so a scene is described once.
Units are SI throughout: metres, kilograms, seconds, newtons.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from truestep.reference_impl.features import Feature

G_UNIVERSAL = 6.67384e-11
"""The lecture's gravitational constant, m^3 kg^-1 s^-2."""


@dataclass
class Springs:
    """Damped springs between particle pairs (the lecture's spring-damper).

    i, j : ndarray of int, shape (m,)     the two particles of each spring
    stiffness : ndarray, shape (m,)        k_s, N/m
    damping : ndarray, shape (m,)          k_d, N s/m (along the spring)
    rest : ndarray, shape (m,)             rest length r, m
    """

    i: np.ndarray
    j: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    rest: np.ndarray

    @classmethod
    def empty(cls) -> Springs:
        z = np.zeros(0)
        return cls(np.zeros(0, int), np.zeros(0, int), z, z.copy(), z.copy())

    def __len__(self) -> int:
        return len(self.i)


@dataclass
class Anchors:
    """Damped springs from a particle to a fixed point in space (the anchored form).

    i : ndarray of int, shape (m,)    the particle
    point : ndarray, shape (m, 3)     the anchor, m
    stiffness, damping, rest : ndarray, shape (m,)   N/m, N s/m, m
    """

    i: np.ndarray
    point: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    rest: np.ndarray

    @classmethod
    def empty(cls) -> Anchors:
        z = np.zeros(0)
        return cls(np.zeros(0, int), np.zeros((0, 3)), z, z.copy(), z.copy())

    def __len__(self) -> int:
        return len(self.i)


@dataclass
class Plane:
    """A collision plane ``(X - point) . normal = 0``; the free side is along ``normal``.

    point : ndarray, shape (3,), m;  normal : ndarray, shape (3,), unit length
    restitution : float   k_r in ``V' = V_T - k_r V_N``
    friction : float      Coulomb coefficient mu (0: the lecture's frictionless wall)
    thickness : float     m; 0: a half-space (nothing gets through); > 0: a wall of this
                          thickness behind the plane, which a particle that crosses it
                          within one step passes through (tunnelling)
    """

    point: np.ndarray
    normal: np.ndarray
    restitution: float = 1.0
    friction: float = 0.0
    thickness: float = 0.0


@dataclass
class ForceField:
    """A position- and time-dependent force field, by kind and parameters.

    kind : ``"vortex"`` (tangential swirl about an axis through ``center``) or ``"wind"``
    (a gusting uniform wind acting through drag). The evaluators live in
    :mod:`truestep.reference_impl.forces`.
    """

    kind: str
    params: dict[str, float | list[float]] = field(default_factory=dict)


@dataclass
class Gravitation:
    """Universal gravitation between all particle pairs, with Plummer softening ``eps``.

    Force on ``i`` toward ``j``: ``G m_i m_j r_ij / (r^2 + eps^2)^(3/2)`` (magnitude
    ``G m_i m_j / r^2`` when ``eps = 0``, the lecture's law); potential
    ``-G m_i m_j / sqrt(r^2 + eps^2)``. G in m^3 kg^-1 s^-2, eps in m.
    """

    G: float = G_UNIVERSAL
    softening: float = 0.0


@dataclass
class EmitterSpec:
    """A particle emitter on a mesh (cube or plane), as the lecture describes it.

    shape : ``"cube"`` or ``"plane"``; center (3,), size (m, edge length);
    normal (3,) for a plane; rate_n, rate_r: new particles per frame ``n + Rand() * r``
    (per unit area when ``per_area``); speed (m/s) along the face normal with
    ``spread`` (radians, cone half-angle); lifetime in frames ``lifetime +- lifetime_jitter``;
    frame_dt: seconds per frame; capacity: size of the particle pool; seed.
    speed_jitter: relative spread of the speed (uniform in ``speed * (1 +- jitter)``);
    particle_size (m) and size_jitter (relative): the shape parameter of each particle;
    color_birth, color_death (RGB in 0..1): colour at the start and end of a life;
    fade_height (m): particles grow transparent with height above the emitter.
    The pool's particles come after every other particle of the scene, one pool per
    emitter in the order the emitters are listed.
    """

    shape: str
    center: np.ndarray
    size: float
    rate_n: float
    rate_r: float
    speed: float
    spread: float
    lifetime: int
    lifetime_jitter: int = 0
    frame_dt: float = 1.0 / 30.0
    capacity: int = 10000
    per_area: bool = False
    normal: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    particle_mass: float = 1.0
    seed: int = 0
    speed_jitter: float = 0.0
    particle_size: float = 0.01
    size_jitter: float = 0.0
    color_birth: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.9, 0.5]))
    color_death: np.ndarray = field(default_factory=lambda: np.array([0.6, 0.1, 0.0]))
    fade_height: float = 1.0


@dataclass
class ParticleModel:
    """A particle scene as structure-of-arrays.

    mass : ndarray, shape (n,), kg       (``inf`` is not used; pinned particles set ``fixed``)
    x0, v0 : ndarray, shape (n, 3)       initial positions (m) and velocities (m/s)
    radius : ndarray, shape (n,), m      collision radius (0: a point)
    fixed : ndarray of bool, shape (n,)  pinned particles never move
    gravity : ndarray, shape (3,), m/s^2 uniform gravitational acceleration
    drag : float, N s/m                  viscous drag ``f = -drag * v`` on every particle
    springs, anchors                     damped springs (pairs, anchored)
    gravitation : Gravitation or None    universal gravitation between all pairs
    fields : list of ForceField          position/time-dependent force fields
    planes : list of Plane               collision planes (box walls are planes)
    emitters : list of EmitterSpec       particle sources (then n may be 0)
    impulses : list of (particle, force (3,), t_start, t_end)
        a force applied to one particle for a time window (the triangle example)
    dimension : 2 or 3                   2: all motion stays in the z = 0 plane
    surfaces : list of ndarray of int, shape (k, 3)
        closed triangle meshes (global particle indices, outward orientation), one per
        closed mass-spring object: their signed volume tells when one turned inside out
    """

    kind: ClassVar[str] = "particles"
    error_unit: ClassVar[str] = "m"

    mass: np.ndarray
    x0: np.ndarray
    v0: np.ndarray
    radius: np.ndarray
    fixed: np.ndarray
    gravity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    drag: float = 0.0
    springs: Springs = field(default_factory=Springs.empty)
    anchors: Anchors = field(default_factory=Anchors.empty)
    gravitation: Gravitation | None = None
    fields: list[ForceField] = field(default_factory=list)
    planes: list[Plane] = field(default_factory=list)
    emitters: list[EmitterSpec] = field(default_factory=list)
    impulses: list[tuple[int, np.ndarray, float, float]] = field(default_factory=list)
    dimension: int = 3
    surfaces: list[np.ndarray] = field(default_factory=list)

    @property
    def n(self) -> int:
        """Number of particles (the pool capacity when the scene has emitters)."""
        return len(self.mass)

    def features(self) -> set[str]:
        """The modelling features this scene needs, by the names adapters declare."""
        f: set[str] = {Feature.POINT_MASSES}
        f.add(Feature.PLANAR if self.dimension == 2 else Feature.SPATIAL)
        if np.any(self.gravity != 0):
            f.add(Feature.UNIFORM_GRAVITY)
        if self.drag:
            f.add(Feature.DRAG)
        if len(self.springs):
            f.add(Feature.SPRINGS)
            if np.any(self.springs.damping != 0):
                f.add(Feature.SPRING_DAMPING)
        if len(self.anchors):
            f.add(Feature.ANCHORED_SPRINGS)
            if np.any(self.anchors.damping != 0):
                f.add(Feature.SPRING_DAMPING)
        if self.gravitation is not None:
            f.add(Feature.UNIVERSAL_GRAVITATION)
        if self.fields:
            f.add(Feature.FORCE_FIELDS)
        if self.planes:
            f.add(Feature.PLANES)
            if any(p.friction for p in self.planes):
                f.add(Feature.FRICTION)
            if any(p.thickness for p in self.planes):
                f.add(Feature.THIN_WALLS)
        if self.emitters:
            f.add(Feature.EMITTERS)
        if np.any(self.fixed):
            f.add(Feature.PINNED_PARTICLES)
        if self.impulses:
            f.add(Feature.IMPULSES)
        return f
