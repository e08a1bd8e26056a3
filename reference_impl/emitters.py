"""Particle systems with emitters: the lecture's "simulation stage", run once per frame.

An emitter is a mesh (a cube or a square plane) that sprays particles from its faces
along the face normals. Each frame of animation (``EmitterSpec.frame_dt`` seconds, which
may span several solver steps) begins with the simulation stage, between solver steps:

1. every live particle's lifetime is decremented by 1; a particle whose lifetime reaches
   0 is removed;
2. the number of new particles is ``n + Rand() * r`` (or ``n(A) + Rand() * r`` with
   ``n(A) = n * A``, ``n`` per unit area and ``A`` the emitter's area), a real number that
   is rounded down or up at random with the probability of its fractional part, so that
   the count's expectation is exactly ``n + r / 2``;
3. each new particle gets, from the emitter's seeded :class:`numpy.random.Generator`
   and in a fixed order: a face (by area), a position uniform on it, a direction in the
   cone of half-angle ``spread`` about the face normal (uniform in solid angle), a speed
   ``speed * (1 +- speed_jitter)``, a size ``particle_size * (1 +- size_jitter)`` and a
   lifetime ``lifetime +- lifetime_jitter`` frames.

Between frames the particles move under the scene's forces like any other particle.
Colour and transparency are functions of age and height (:meth:`Emitter.colors`), the
shape an ellipsoid stretched along the velocity (:meth:`Emitter.shapes`).

The particles live in a fixed pool of ``capacity`` slots of the system's arrays (the
``alive`` mask says which are in use). Free slots wait in a first-in first-out ring, so
spawning fills dead slots without searching, a freed slot is reused as late as possible,
and a frame allocates nothing proportional to the number of particles. When the pool is
full, the particles that do not fit are not spawned and are counted in ``dropped``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from truestep.reference_impl.model import EmitterSpec, ParticleModel

if TYPE_CHECKING:
    from truestep.reference_impl.particles import ParticleSystem

CUBE_NORMALS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)


def tangents(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors ``u, w`` (3,) with ``(u, w, normal)`` right-handed and orthonormal."""
    normal = normal / np.linalg.norm(normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(helper, normal)
    u /= np.linalg.norm(u)
    return u, np.cross(normal, u)


def emitter_faces(spec: EmitterSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The square faces of an emitter: centres, normals, and tangents ``u``, ``w``, each (k, 3).

    A cube of edge ``size`` has six faces; a plane emitter is one square of side ``size``
    facing ``normal``.
    """
    if spec.shape == "cube":
        normals = CUBE_NORMALS
    elif spec.shape == "plane":
        normals = (spec.normal / np.linalg.norm(spec.normal))[None, :]
    else:
        raise ValueError(f"emitter: unknown shape {spec.shape!r} (known: cube, plane)")
    centers = (
        spec.center + 0.5 * spec.size * normals if spec.shape == "cube" else (spec.center[None, :].copy())
    )
    us, ws = zip(*(tangents(n) for n in normals), strict=True)
    return centers, normals, np.array(us), np.array(ws)


def emitter_area(spec: EmitterSpec) -> float:
    """Total emitting area ``A`` of the emitter, m^2."""
    return (6.0 if spec.shape == "cube" else 1.0) * spec.size**2


def spawn_mean(spec: EmitterSpec) -> float:
    """``n`` (or ``n(A) = n A``) per frame, before the random part."""
    return spec.rate_n * emitter_area(spec) if spec.per_area else spec.rate_n


def spawn_count_moments(n: float, r: float) -> tuple[float, float]:
    """Mean and variance of the number of new particles per frame, ``n + Rand() * r`` rounded.

    With ``X = n + U r`` (``U`` uniform on [0, 1)) rounded to ``floor(X + U')``: the mean
    is ``n + r / 2`` and the variance ``r^2 / 12 + E[f (1 - f)]`` with ``f = frac(X)``,
    the last term integrated exactly (``H`` is an antiderivative of ``f (1 - f)``).
    """

    def antiderivative(s: float) -> float:
        fl = math.floor(s)
        fr = s - fl
        return fl / 6.0 + fr**2 / 2.0 - fr**3 / 3.0

    if r > 0:
        rounding = (antiderivative(n + r) - antiderivative(n)) / r
    else:
        fr = n - math.floor(n)
        rounding = fr * (1.0 - fr)
    return n + r / 2.0, r**2 / 12.0 + rounding


def lifetime_values(spec: EmitterSpec) -> np.ndarray:
    """The equally likely lifetimes (frames): ``lifetime - jitter .. lifetime + jitter``."""
    return np.arange(spec.lifetime - spec.lifetime_jitter, spec.lifetime + spec.lifetime_jitter + 1)


def pool_starts(model: ParticleModel) -> list[int]:
    """Index of the first pool slot of each emitter: pools close the particle list in order."""
    first = model.n - sum(e.capacity for e in model.emitters)
    starts = []
    for e in model.emitters:
        starts.append(first)
        first += e.capacity
    return starts


class Emitter:
    """The per-frame simulation stage of one emitter, as a between-steps pass.

    Parameters
    ----------
    spec : EmitterSpec
    first : int
        Index of the pool's first slot in the system's arrays.
    up : ndarray, shape (3,)
        Unit vector along which "height" is measured (against gravity).

    Attributes
    ----------
    life, age : ndarray of int, shape (capacity,)
        Frames left and frames lived, per pool slot (meaningless for dead slots).
    lifespan : ndarray of int, shape (capacity,)   lifetime given at birth, frames
    size : ndarray, shape (capacity,)              shape parameter, m
    frame : int                                    frames begun so far
    spawned, removed, population : list of int     per frame: new, expired, alive after
    dropped : int                                  new particles that found the pool full
    """

    def __init__(self, spec: EmitterSpec, first: int, up: np.ndarray | None = None) -> None:
        if spec.lifetime - spec.lifetime_jitter < 1:
            raise ValueError("emitter: lifetime - lifetime_jitter must be at least 1 frame")
        self.spec = spec
        self.pool = slice(first, first + spec.capacity)
        self.first = first
        self.up = np.array([0.0, 1.0, 0.0]) if up is None else up / np.linalg.norm(up)
        self.rng = np.random.default_rng(spec.seed)
        self.faces = emitter_faces(spec)
        cap = spec.capacity
        self.life = np.zeros(cap, dtype=np.int64)
        self.age = np.zeros(cap, dtype=np.int64)
        self.lifespan = np.ones(cap, dtype=np.int64)
        self.size = np.zeros(cap)
        self._queue = np.arange(cap, dtype=np.int64)  # free slots, a ring buffer
        self._head = 0
        self._free = cap
        self._expired = np.zeros(cap, dtype=bool)
        self.frame = 0
        self._next_frame_t = 0.0
        self.spawned: list[int] = []
        self.removed: list[int] = []
        self.population: list[int] = []
        self.dropped = 0

    # -- the pass ----------------------------------------------------------------------
    def start(self, system: ParticleSystem) -> None:
        """The pool starts empty; frame 0 begins with the initial state."""
        system.alive[self.pool] = False
        system.velocities[self.pool] = 0.0
        self(system, 0.0)

    def __call__(self, system: ParticleSystem, dt: float) -> None:
        """Run the simulation stage of every frame that began by the system's time.

        With fixed steps a frame begins at the end of the step that reaches its start time
        (exactly, when ``frame_dt`` is a multiple of the step); an adaptive step ends at the
        next frame's start (:attr:`next_time`,
        :meth:`~truestep.reference_impl.system.System.next_pass_time`). A step that spans
        several frame starts (a fixed step longer than a frame) runs their stages one after
        another at the end of the step.
        """
        t = system.get_time()
        slack = 1e-9 * self.spec.frame_dt
        while t >= self._next_frame_t - slack:
            self.begin_frame(system)
            self.frame += 1
            self._next_frame_t = self.frame * self.spec.frame_dt

    @property
    def next_time(self) -> float:
        """When the next frame begins (s): an adaptive step ends there (the simulation stage
        acts at that instant, as it does at the end of a fixed step that reaches it)."""
        return self._next_frame_t

    def begin_frame(self, system: ParticleSystem) -> None:
        """Expire particles whose lifetime reaches 0, then spawn this frame's new ones."""
        alive = system.alive[self.pool]  # a view
        self.removed.append(self._expire(system, alive))
        mean = spawn_mean(self.spec)
        exact = mean + self.rng.random() * self.spec.rate_r
        count = math.floor(exact + self.rng.random())
        self.spawned.append(self._spawn(system, count))
        self.population.append(self.spec.capacity - self._free)

    # -- stages ------------------------------------------------------------------------
    def _expire(self, system: ParticleSystem, alive: np.ndarray) -> int:
        np.subtract(self.life, 1, out=self.life, where=alive)
        np.add(self.age, 1, out=self.age, where=alive)
        np.less_equal(self.life, 0, out=self._expired)
        np.logical_and(self._expired, alive, out=self._expired)
        dead = np.flatnonzero(self._expired)
        if len(dead):
            alive[dead] = False
            system.velocities[self.first + dead] = 0.0
            tail = (self._head + self._free + np.arange(len(dead))) % self.spec.capacity
            self._queue[tail] = dead
            self._free += len(dead)
        return len(dead)

    def _spawn(self, system: ParticleSystem, count: int) -> int:
        spec, rng = self.spec, self.rng
        k = min(count, self._free)
        self.dropped += count - k
        if k == 0:
            return 0
        slots = self._queue[(self._head + np.arange(k)) % spec.capacity]
        self._head = (self._head + k) % spec.capacity
        self._free -= k

        centers, normals, us, ws = self.faces
        face = rng.integers(0, len(normals), k)  # equal squares: uniform by area
        a, b = rng.random(k) - 0.5, rng.random(k) - 0.5
        pos = centers[face] + spec.size * (a[:, None] * us[face] + b[:, None] * ws[face])
        cos_t = 1.0 - rng.random(k) * (1.0 - math.cos(spec.spread))
        sin_t = np.sqrt(1.0 - cos_t**2)
        phi = 2.0 * math.pi * rng.random(k)
        direction = (
            cos_t[:, None] * normals[face]
            + (sin_t * np.cos(phi))[:, None] * us[face]
            + (sin_t * np.sin(phi))[:, None] * ws[face]
        )
        speed = spec.speed * (1.0 + spec.speed_jitter * (2.0 * rng.random(k) - 1.0))
        size = spec.particle_size * (1.0 + spec.size_jitter * (2.0 * rng.random(k) - 1.0))
        life = spec.lifetime + rng.integers(-spec.lifetime_jitter, spec.lifetime_jitter + 1, k)

        idx = self.first + slots
        system.positions[idx] = pos
        system.velocities[idx] = speed[:, None] * direction
        system.alive[idx] = True
        self.life[slots] = life
        self.lifespan[slots] = life
        self.age[slots] = 0
        self.size[slots] = size
        return k

    # -- attributes for rendering -------------------------------------------------------
    def colors(self, system: ParticleSystem) -> np.ndarray:
        """RGBA (capacity, 4) of the pool: colour by age, transparency by age and height.

        The colour goes linearly from ``color_birth`` to ``color_death`` over a life; the
        opacity ``(1 - age / lifespan) * exp(-h / fade_height)`` falls with age and with
        the height ``h >= 0`` above the emitter's centre. Dead slots are fully transparent.
        """
        spec = self.spec
        frac = np.clip(self.age / self.lifespan, 0.0, 1.0)
        rgb = spec.color_birth + frac[:, None] * (spec.color_death - spec.color_birth)
        height = np.maximum((system.positions[self.pool] - spec.center) @ self.up, 0.0)
        alpha = (1.0 - frac) * np.exp(-height / spec.fade_height)
        alpha = np.where(system.alive[self.pool], alpha, 0.0)
        return np.concatenate([rgb, alpha[:, None]], axis=1)

    def shapes(self, system: ParticleSystem) -> np.ndarray:
        """Ellipsoid semi-axes (capacity, 2), m: ``size + |v| frame_dt / 2`` along the
        velocity (the streak of one frame) and ``size`` across it."""
        speed = np.linalg.norm(system.velocities[self.pool], axis=1)
        return np.stack([self.size + 0.5 * speed * self.spec.frame_dt, self.size], axis=1)
