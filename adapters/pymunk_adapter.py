"""pymunk (Chipmunk2D, as the Munk2D fork) behind the Adapter protocol: 2-D particle scenes.

What the engine is asked to do, and what integration scheme results
--------------------------------------------------------------------
pymunk has one integrator, offered here as the method ``default``. Measured on pymunk
7.3.1 (Munk2D 2.0.1) and read in Munk2D's ``cpSpaceStep``, ``cpBodyUpdatePosition``,
``cpBodyUpdateVelocity``, ``cpArbiter.c`` and ``cpDampedSpring.c``, one ``space.step(h)``
does, in this order:

1. **positions**: ``x' = x + h (v + v_bias)`` for every dynamic and kinematic body
   (``v_bias`` is a contact's position-correction velocity, zero away from contacts);
2. collision detection at ``x'`` (discrete: no continuous collision detection);
3. constraint pre-step at ``x'``: each :class:`pymunk.DampedSpring` applies its spring
   impulse ``k (r - |d|) h`` along the spring, ``d`` the vector between its ends;
4. **velocities**: ``v' = v + h (g + f / m)``, ``f`` the force set on the body before the
   step (Chipmunk clears it afterwards);
5. ``space.iterations`` (default 10, left there) Gauss-Seidel sweeps of the contact and
   spring-damping impulses.

So the scheme is semi-implicit (symplectic) Euler **with the position update first**:
``x_{n+1} = x_n + h v_n``, ``v_{n+1} = v_n + h a(x_{n+1})``. It is the adjoint of the
reference's ``symplectic-euler`` (velocity first): first order, symplectic, energy error
bounded on an oscillator for ``omega h < 2``. From rest under gravity it gives
``y_n = y_0 - g h^2 n (n - 1) / 2`` and ``v_n = -g n h``: the position lags the exact
``g t^2 / 2`` by exactly ``g t h / 2``. ``space.damping`` stays 1.0 (no hidden velocity
damping) and bodies never sleep (``sleep_time_threshold`` stays infinite): both checked.

The model in pymunk
-------------------
- **Particles**: a dynamic :class:`pymunk.Body` of the particle's mass and infinite moment
  (a point mass never rotates). A pinned particle is a kinematic body: it keeps its
  initial velocity (zero in every sensible case) and no force moves it, as in the
  reference, where a pinned particle's acceleration is zero.
- **Gravity**: ``space.gravity``, added in step 4 above.
- **Springs** (pairs and anchors): :class:`pymunk.DampedSpring` with the case's rest length
  and stiffness; an anchored spring runs from ``space.static_body`` at the anchor point.
  Its damping is *not* the lecture's explicit force ``-k_d (dv . u) u``: in every step the
  relative velocity of the ends along the spring is multiplied by
  ``exp(-k_d h (1/m_a + 1/m_b))`` after the velocity update, i.e. the damper alone is
  integrated exactly (unconditionally stable), split from the spring (Munk2D's
  ``v_coef = 1 - exp(-damping dt k)``): ``v_{n+1} = exp(-k_d h / m) (v_n + h a(x_{n+1}))``
  along the spring for one particle on one anchored spring, still first order overall;
  with several springs on a particle the Gauss-Seidel sweeps couple them. A spring
  between two pinned particles moves nothing and is left out.
- **Drag, universal gravitation, force fields, impulses**: summed per step in numpy by the
  same functions the reference uses (:mod:`truestep.reference_impl.forces`) and handed to the
  bodies in one batched call (``pymunk.batch.set_space_bodies``, pymunk >= 6.7) as
  ``body.force`` before each ``space.step``. They are evaluated at the position the step
  is about to move to, ``x_n + h v_n``, at the velocity ``v_n`` and at the step's start
  time ``t_n`` (impulses act in the steps with ``t_on <= t_n < t_off``, as in the
  reference). Position-dependent forces (gravitation, vortex) are therefore integrated
  by the same position-first symplectic Euler as the springs; velocity-dependent ones
  (drag, wind) explicitly in ``v``. Near a contact the step also moves the body by
  ``h v_bias``, which this evaluation point does not see (a lag of one step in the
  contact's position correction, not in the motion).
- **Planes**: a plane is a static :class:`pymunk.Segment` on ``space.static_body`` with a
  thickness: its core line lies ``PLANE_THICKNESS`` (10 m) behind the plane and its radius
  is the same 10 m, so its surface is exactly the plane for ``PLANE_HALF_LENGTH`` (1 km)
  on either side of the scene's centre. Particles keep their own radius (0 is allowed):
  a radius-0 segment would let a point particle through between two steps, and padding
  the particle's radius would move the contact surface. A particle penetrating 10 m in
  one step would come out of the far side; nothing near that speed is a sensible scene.
  Only free particles have circle shapes, all in one shape group, so particles never
  collide with each other (the lecture's particles collide with planes only).
- **Restitution and friction**: Chipmunk uses the *product* of the two shapes'
  elasticities (and frictions), so a particle's circle has elasticity 1 and friction 1
  and the plane's segment carries the case's restitution ``k_r`` and Coulomb ``mu``.
  Chipmunk's bounce law: the target normal velocity after a contact step is
  ``-e`` times the normal velocity at the *start* of that step (before its gravity kick);
  a single contact with a static plane is solved in the first sweep, so one recorded
  velocity ratio across a bounce is ``e`` to rounding, while the rebound is up to
  ``e g h`` short of ``e`` times the speed the ball would have reached at the surface.
  There is no restitution threshold (slow impacts bounce with the same ``e``). Contact is
  found only after a step has penetrated, by up to one step's travel ``|v| h``.
  Friction clamps the tangential impulse by ``mu`` times the normal impulse of the step.
- **Contact slop and bias**: penetration up to ``space.collision_slop`` is left alone;
  deeper penetration is pushed out through ``v_bias`` (a position correction that does not
  change the velocity) at the rate ``1 - collision_bias^h`` per step (pymunk's default
  bias: 10 % per step at 60 Hz). pymunk's default slop of 0.1 is sized for pixels; here it
  is ``collision_slop`` = 1e-4 m.

Reading back
------------
The stepping loop, recording and blow-up checks are :class:`FixedStepAdapter`'s.
Positions and velocities come back through one batched ``pymunk.batch.get_space_bodies``
call at the recorded steps (and every 64 steps to catch a blow-up early); ``z`` is 0.
Energy is :func:`truestep.reference_impl.particles.total_energy` of that read-back state; ``nfev``
and ``steps`` count ``space.step`` calls. A non-finite or runaway state (beyond
:data:`truestep.reference_impl.integrate.BLOWUP`) ends the run with status ``unstable``.

Not modelled: 3-D scenes (``3d``, and a 2-D scene's plane whose normal leaves the x-y
plane), emitters, plain ODE cases.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pymunk
import pymunk.batch

from truestep.adapters.base import FixedStepAdapter
from truestep.cases.case import Case
from truestep.reference_impl import forces
from truestep.reference_impl.features import Feature
from truestep.reference_impl.integrate import BLOWUP
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.solvers import MethodFacts, Stability

PLANE_HALF_LENGTH = 1.0e3
"""Half-length of a plane's segment, m, centred on the scene's centre projected onto it."""
PLANE_THICKNESS = 10.0
"""Radius of a plane's segment, m; its core line lies this far behind the plane."""
_STATE = pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.VELOCITY
_PARTICLES = pymunk.ShapeFilter(group=1)


@dataclass
class PymunkScene:
    """A particle scene built in a pymunk space.

    space : the pymunk space (bodies, circle shapes, plane segments, springs)
    bodies : one body per particle, in the model's order
    rows : ndarray of int, shape (n,)
        where the particles' bodies come in pymunk's batch order, which also holds
        ``space.static_body`` once a spring is anchored to it
    slot : ndarray of int, shape (n,)
        the particle of each of those rows: ``x[slot] = batch_state[rows]``
    n_batch : number of bodies in pymunk's batch order
    forced : whether per-step forces (drag, gravitation, fields, impulses) are applied
    """

    space: pymunk.Space
    bodies: list[pymunk.Body]
    rows: np.ndarray
    slot: np.ndarray
    n_batch: int
    forced: bool


def _planar(v: np.ndarray) -> tuple[float, float]:
    return float(v[0]), float(v[1])


def build_scene(model: ParticleModel, *, collision_slop: float) -> PymunkScene:
    """Build ``model`` (a 2-D particle scene) in a new pymunk space; see the module docstring."""
    space = pymunk.Space()
    if space.damping != 1.0:
        raise RuntimeError(f"pymunk space.damping is {space.damping}, expected 1.0 (no damping)")
    if space.sleep_time_threshold != float("inf"):
        raise RuntimeError("pymunk bodies would sleep (space.sleep_time_threshold is finite)")
    space.gravity = _planar(model.gravity)
    space.collision_slop = collision_slop

    bodies = []
    for i in range(model.n):
        if model.fixed[i]:
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        else:
            body = pymunk.Body(float(model.mass[i]), float("inf"))
        body.position = _planar(model.x0[i])
        body.velocity = _planar(model.v0[i])
        space.add(body)
        bodies.append(body)

    if model.planes:
        for i, body in enumerate(bodies):
            if model.fixed[i]:
                continue
            circle = pymunk.Circle(body, float(model.radius[i]))
            circle.elasticity, circle.friction, circle.filter = 1.0, 1.0, _PARTICLES
            space.add(circle)
        centre = model.x0[:, :2].mean(axis=0)
        for plane in model.planes:
            space.add(
                _plane_segment(
                    space,
                    plane.point[:2],
                    plane.normal[:2],
                    centre,
                    plane.restitution,
                    plane.friction,
                    0.5 * plane.thickness or PLANE_THICKNESS,
                )
            )

    s = model.springs
    for i, j, k, c, r in zip(s.i, s.j, s.stiffness, s.damping, s.rest, strict=True):
        if not (model.fixed[i] and model.fixed[j]):
            space.add(
                pymunk.DampedSpring(
                    bodies[i], bodies[j], (0.0, 0.0), (0.0, 0.0), float(r), float(k), float(c)
                )
            )
    a = model.anchors
    for i, p, k, c, r in zip(a.i, a.point, a.stiffness, a.damping, a.rest, strict=True):
        if not model.fixed[i]:
            space.add(
                pymunk.DampedSpring(
                    space.static_body, bodies[i], _planar(p), (0.0, 0.0), float(r), float(k), float(c)
                )
            )

    ids = pymunk.batch.Buffer()
    pymunk.batch.get_space_bodies(space, pymunk.batch.BodyFields.BODY_ID, ids)
    index = {body.id: i for i, body in enumerate(bodies)}
    batch = [index.get(int(b), -1) for b in np.frombuffer(ids.int_buf(), dtype=np.uintp)]
    rows = np.array([r for r, i in enumerate(batch) if i >= 0], dtype=int)
    slot = np.array([i for i in batch if i >= 0], dtype=int)
    if len(slot) != model.n or len(np.unique(slot)) != model.n:
        raise RuntimeError("pymunk's batch order does not hold every particle exactly once")
    forced = bool(model.drag or model.gravitation is not None or model.fields or model.impulses)
    return PymunkScene(space, bodies, rows, slot, len(batch), forced)


def _plane_segment(
    space: pymunk.Space,
    point: np.ndarray,
    normal: np.ndarray,
    centre: np.ndarray,
    restitution: float,
    friction: float,
    half_thickness: float,
) -> pymunk.Segment:
    """A thick static segment whose surface is the plane ``(X - point) . normal = 0``.

    ``point``, ``normal`` (unit, in the x-y plane) and ``centre`` (where the scene is) are
    shape (2,), m; its core line lies ``half_thickness`` (m) behind the plane, which is
    also its radius: ``PLANE_THICKNESS`` for a half-space, half the wall for a thin wall.
    """
    n = normal / np.linalg.norm(normal)
    foot = centre - float((centre - point) @ n) * n
    core = foot - half_thickness * n
    along = np.array([-n[1], n[0]]) * PLANE_HALF_LENGTH
    seg = pymunk.Segment(space.static_body, _planar(core - along), _planar(core + along), half_thickness)
    seg.elasticity, seg.friction = float(restitution), float(friction)
    return seg


def exact_damper_step(a: float, b: float) -> np.ndarray:
    """One ``space.step`` on the linear test system (one particle on one anchored damped
    spring, along it; see the module docstring): ``q' = q + h v``, then
    ``h v' = exp(-b) (h v - a q')``, the damper's decay applied exactly after the kick."""
    decay = np.exp(-b)
    return np.array([[1.0, 1.0], [-decay * a, decay * (1.0 - a)]])


class PymunkAdapter(FixedStepAdapter):
    """pymunk's own integrator on 2-D particle scenes (see the module docstring)."""

    name = "pymunk"
    methods = ("default",)
    adaptive_methods = ()
    method_notes: ClassVar = {
        "default": "Chipmunk2D's step (symplectic Euler with an impulse contact solver), as shipped"
    }
    """One line per method, for the report's glossary."""
    method_facts: ClassVar[dict[str, MethodFacts]] = {
        "default": MethodFacts(
            order=1,
            evaluations_per_step=1,
            symplectic=True,
            stability=Stability(imaginary=2.0, real=float("inf"), step_matrix=exact_damper_step),
        )
    }
    """Position first, then velocity from forces at the new position: the adjoint of the
    reference's symplectic Euler, first order and symplectic, stable for ``omega h < 2``
    undamped; a spring's damper is integrated exactly (:func:`exact_damper_step`)."""
    capabilities = frozenset(
        {
            Feature.POINT_MASSES,
            Feature.PLANAR,
            Feature.UNIFORM_GRAVITY,
            Feature.DRAG,
            Feature.SPRINGS,
            Feature.SPRING_DAMPING,
            Feature.ANCHORED_SPRINGS,
            Feature.PLANES,
            Feature.THIN_WALLS,
            Feature.FRICTION,
            Feature.PINNED_PARTICLES,
            Feature.IMPULSES,
            Feature.FORCE_FIELDS,
            Feature.UNIVERSAL_GRAVITATION,
        }
    )
    collision_slop = 1e-4
    """m: penetration Chipmunk leaves uncorrected (pymunk's default 0.1 is for pixels)."""

    def missing(self, case: Case, method: str) -> set[str]:
        missing = case.features - self.capabilities
        model = case.model
        if model is not None and any(abs(p.normal[2]) > 0 for p in model.planes):
            missing.add(Feature.SPATIAL)
        return missing

    def build(self, case: Case, method: str, h: float) -> _Stepper:
        return _Stepper(case.particles, build_scene(case.particles, collision_slop=self.collision_slop), h)

    def advance(self, scene: _Stepper, k: int, steps: int, h: float) -> None:
        """``steps`` calls of ``space.step(h)``, each after the numpy forces of its start."""
        step = scene.step
        if scene.forced:
            apply_forces = scene.apply_forces
            for j in range(k, k + steps):
                apply_forces(j * h)
                step(h)
        elif steps == 1:
            step(h)
        else:
            for _ in range(steps):
                step(h)

    def read(self, scene: _Stepper) -> tuple[np.ndarray, np.ndarray]:
        return scene.read()

    def snapshot(self, scene: _Stepper) -> bytes:
        """One batched read as raw bytes (called at every record: kept to one frame)."""
        buffer = scene.get
        buffer.clear()
        pymunk.batch.get_space_bodies(scene.space, _STATE, buffer)
        return bytes(buffer.float_buf())

    def unpack(self, scene: _Stepper, snaps: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
        return scene.unpack(snaps)

    def is_sane(self, scene: _Stepper) -> bool:
        """One reduction over the batched read (see :func:`_sane`)."""
        return _sane(scene.snapshot())


class _Stepper:
    """The work around ``space.step``: batched reads and writes, and the numpy forces.

    A recorded state is kept as the raw bytes of one batched read (a *snapshot*: for each
    body in pymunk's batch order ``x, y, vx, vy``, float64) and unpacked into arrays after
    the timed loop.

    Buffers are allocated once: ``x``, ``v``, ``f`` (n, 3) in the model's order (z stays 0),
    ``x_next`` (n, 3) for the evaluation point ``x + h v``, ``force`` (n_batch, 2) in
    pymunk's batch order, shared with the batch buffer that sets ``body.force``.
    """

    def __init__(self, model: ParticleModel, scene: PymunkScene, h: float) -> None:
        self.model, self.scene, self.h = model, scene, h
        self.space, self.step, self.forced = scene.space, scene.space.step, scene.forced
        n = model.n
        self.x, self.v = np.zeros((n, 3)), np.zeros((n, 3))
        self.f, self.x_next = np.zeros((n, 3)), np.zeros((n, 3))
        self.movable = ~model.fixed[scene.slot]
        self.get = pymunk.batch.Buffer()
        self.force = np.zeros((scene.n_batch, 2))
        self.put = pymunk.batch.Buffer()
        self.put.set_float_buf(self.force)

    def _batch(self) -> Any:
        """One batched read of every body's ``x, y, vx, vy`` (a cffi buffer, reused)."""
        self.get.clear()
        pymunk.batch.get_space_bodies(self.scene.space, _STATE, self.get)
        return self.get.float_buf()

    def snapshot(self) -> bytes:
        """The state of every body now, as raw bytes (see the class docstring)."""
        return bytes(self._batch())

    def unpack(self, snaps: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities (T, n, 3), m and m/s, from ``T`` snapshots."""
        raw = np.frombuffer(b"".join(snaps), dtype=float).reshape(len(snaps), -1, 4)
        x, v = np.zeros((len(snaps), self.model.n, 3)), np.zeros((len(snaps), self.model.n, 3))
        x[:, self.scene.slot, :2] = raw[:, self.scene.rows, :2]
        v[:, self.scene.slot, :2] = raw[:, self.scene.rows, 2:]
        return x, v

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities of every particle now, (n, 3) each, m and m/s (reused)."""
        state = np.frombuffer(self._batch(), dtype=float).reshape(-1, 4)
        rows, slot = self.scene.rows, self.scene.slot
        self.x[slot, :2] = state[rows, :2]
        self.v[slot, :2] = state[rows, 2:]
        return self.x, self.v

    def apply_forces(self, t: float) -> None:
        """Set ``body.force`` for the coming step from the state now (start time ``t``, s)."""
        m = self.model
        x, v = self.read()
        np.multiply(v, self.h, out=self.x_next)
        self.x_next += x
        f = self.f
        f[:] = 0.0
        if m.drag:
            forces.add_drag(f, v, m.drag)
        if m.gravitation is not None:
            forces.add_gravitation(f, self.x_next, m.mass, m.gravitation)
        if m.fields:
            forces.add_fields(f, m.fields, self.x_next, v, m.mass, t)
        forces.add_impulses(f, m.impulses, t)
        self.force[self.scene.rows] = f[self.scene.slot, :2] * self.movable[:, None]
        pymunk.batch.set_space_bodies(self.scene.space, pymunk.batch.BodyFields.FORCE, self.put)


def _sane(snap: bytes) -> bool:
    """Whether every number of a snapshot is finite and below :data:`BLOWUP` in magnitude.

    The largest magnitude is NaN if any number is (``max`` propagates NaN), and a NaN
    compares false: one reduction, cheaper than ``all(abs(s) < BLOWUP)``.
    """
    return bool(np.abs(np.frombuffer(snap, dtype=float)).max(initial=0.0) < BLOWUP)
