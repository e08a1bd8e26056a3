"""pybullet (Bullet 3, double precision) behind the Adapter protocol: 2-D and 3-D particle scenes.

What the engine is asked to do, and what integration scheme results
--------------------------------------------------------------------
Each :meth:`PybulletAdapter.simulate` builds its scene in the process's own
``p.connect(p.DIRECT)`` client, emptied first by ``resetSimulation``, which makes Bullet's
world anew (bodies, broad phase, solver and their parameters), so no engine state set in
one run can reach the next (tested bit for bit against a new client).
The step is ``setPhysicsEngineParameter(fixedTimeStep=h, numSubSteps=0)`` with
``h = case.steps_for(dt)[1]``, and the run is ``round(duration / h)`` calls of
``p.stepSimulation()``. One call integrates semi-implicit (symplectic) Euler with the
**velocity update first**: ``v_{n+1} = v_n + h (g + f_n / m) + contact impulses / m``,
``x_{n+1} = x_n + h v_{n+1}`` (the reference's ``symplectic-euler``). From rest under
gravity this gives ``y_n = y_0 - g h^2 n (n + 1) / 2`` exactly (checked in the tests to
1e-9 m; pybullet is built in double precision).

The model in pybullet
---------------------
- **Particles**: one body per particle, ``createMultiBody`` with a ``GEOM_SPHERE`` of the
  particle's radius (``POINT_RADIUS`` = 0.01 m for a radius-0 particle, see planes) and its
  mass. A point mass must not rotate, so ``changeDynamics`` sets
  ``localInertiaDiagonal = (0, 0, 0)``, which Bullet treats as infinite inertia (its inverse
  is set to 0): friction torques never spin a particle up, and a particle never rolls.
  ``linearDamping`` and ``angularDamping`` are set to 0: a pybullet multibody's default is
  0.04 for both (Bullet's ``btMultiBody`` constructor, ``m_linearDamping(0.04f)``), applied
  as a force ``m v (0.04 + 0.04 |v|)``; left there it takes 0.35 m off a 1 s free fall at
  ``h`` = 1/240 s (measured). ``maxJointVelocity`` is set to infinity: a ``btMultiBody``
  clamps every velocity coordinate, its base's included, to ``m_maxCoordinateVelocity``
  = 100 (``btClamp`` in ``applyDeltaVeeMultiDof``); left there a free fall stops
  accelerating at 100 m/s and a blow-up is silently held at 100 m/s (measured), both
  hidden clamps. A pinned particle is a static body (mass 0) that collides with nothing;
  as in the reference, no force moves it but it keeps its initial velocity, so one with a
  non-zero initial velocity is moved along ``x0 + v0 t`` in numpy (it is a kinematic
  point the forces read; a static Bullet body cannot move).
- **Gravity**: ``p.setGravity``.
- **Springs, anchored springs, drag, universal gravitation, force fields, impulses**:
  summed per step in numpy by the functions the reference uses
  (:mod:`truestep.reference_impl.forces`) from the state read back at the start of the step
  (``x_n``, ``v_n``, ``t_n``; impulses act in the steps with ``t_on <= t_n < t_off``, as in
  the reference), and handed to each body with
  ``p.applyExternalForce(body, -1, f, x, p.WORLD_FRAME)`` at the body's own position
  before each ``p.stepSimulation()`` (Bullet clears external forces after every step).
  Springs thus get exactly the reference's ``symplectic-euler`` (spring damping included,
  explicit in ``v_n``). Only what the forces need is read: the positions (and, for damped
  springs, drag and wind, the velocities) of the particles the forces touch, one
  ``getBasePositionAndOrientation`` / ``getBaseVelocity`` call per body (pybullet has no
  batched read of base states); a state read at a recorded step is reused. These calls,
  and ``applyExternalForce``, cost a Python call per body per step: a cloth with damped
  springs steps many times slower than the reference's numpy ``symplectic-euler``, with
  the same trajectory to 1e-15 m. Mass-spring cloth goes through the same path:
  pybullet's deformable world (``loadSoftBody`` with mass-spring) is not used, since it
  needs a mesh file and its own implicit integrator and damping would not be the
  lecture's springs.
- **Planes**: a static ``GEOM_PLANE`` body per plane, with ``planeNormal`` the plane's
  normal, placed at the plane's point: a half-space (no tunnelling through it however
  fast a particle moves). Radius-0 particles collide, in their own collision group, with a
  copy of each plane moved ``POINT_RADIUS`` back against its normal, so the centre of
  their small sphere touches exactly the case's plane. Collision filter groups keep particles
  from colliding with each other (the lecture's particles collide with planes only).
- **Restitution and friction**: Bullet combines the two bodies' coefficients by product
  (``btManifoldResult::calculateCombinedRestitution`` returns
  ``body0->getRestitution() * body1->getRestitution()``; friction likewise, clamped to
  +-10), so each particle gets ``restitution = 1`` and ``lateralFriction = 1`` and the plane
  the case's ``k_r`` and Coulomb ``mu`` (pybullet's default ``lateralFriction`` is 0.5, its
  default restitution 0). Spinning and rolling friction stay 0.

Methods: ``default`` and ``clean``
----------------------------------
pybullet's contact solver (sequential impulses) gives a contact a target normal velocity
made of a restitution term and a penetration-correction term. Measured on a ball hitting
a plane (normal velocity ``v_n < 0`` before the contact step, depth ``d`` at its start),
to rounding:

- ``btMultiBody`` bodies (``default``):
  ``v_out = e (|v_n| + g h) + contactERP (d - contactSlop) / h`` (restitution of the
  velocity *after* the step's gravity kick, plus a Baumgarte push in the velocity);
- ``btRigidBody`` bodies with split impulse (``clean``): ``v_out = e |v_n|``, the push
  moving the position only.

So ``default``'s rebound depends on how deep (or, within the contact margin, how far
above the plane) the ball is at the start of its contact step, that is on where in a
step it arrives: the restitution sweep's impact-phase drops (16 balls whose contacts
begin at evenly spaced points of a step), asked 0.5 at 1 ms, read 0.16 to 0.55 with
``default`` and 0.498 to 0.501 with ``clean`` (``restitution.csv``, ``e_phase_min`` and
``e_phase_max``; a raw pybullet script of the same drops agrees, in
``tests/reporting/test_restitution_phases.py``).

What each ``setPhysicsEngineParameter`` setting does (the pybullet quickstart guide's
descriptions, checked against Bullet's ``btSequentialImpulseConstraintSolver::
setupContactConstraint`` and pybullet's ``PhysicsServerCommandProcessor``, which sets
contact ERP 0.08, friction ERP 0.2, contact slop 1e-5, 50 solver iterations and
warm-starting factor 0.1 at start-up):

- ``contactBreakingThreshold``: contact points farther apart than this are not processed
  by the solver, and AABBs are grown by it (Bullet's ``gContactBreakingThreshold``, 0.02,
  scaled by the shape's size: a 5 cm sphere 2.2 mm above a plane had no contact point,
  one 1.2 mm above had a speculative one, measured). Left at its default.
- ``erp`` / ``contactERP`` / ``frictionERP``: Baumgarte error-reduction fractions for
  joints, contacts and friction anchors. A contact at depth ``d`` gets the velocity target
  ``contactERP * (d - contactSlop) / h`` *added to its velocity* unless split impulse
  handles it: the default 0.08 turns 15.8 mm of penetration at ``h`` = 1/240 s into
  +0.30 m/s of rebound. ``frictionERP`` only acts with friction anchors (off here).
- ``restitutionVelocityThreshold`` (default 0.2 m/s): below this relative normal speed
  the restitution is zero, so slow bounces die.
- ``useSplitImpulse`` / ``splitImpulsePenetrationThreshold`` (default on / -0.04 m): a
  contact deeper than the threshold is pushed out by a separate pseudo-velocity that moves
  the position without entering the velocity; shallower contacts use the Baumgarte term
  above. pybullet only applies a threshold >= 0. It works for ``btRigidBody`` contacts
  only: pybullet's default ``createMultiBody`` bodies are ``btMultiBody`` objects, whose
  contacts (``btMultiBodyConstraintSolver``) always feed the correction into the velocity
  (measured: the same bounces with split impulse on and off).
- ``contactSlop`` (1e-5 m): penetration not corrected, so a resting particle sits 10 um
  deep.
- ``enableConeFriction`` (on): implicit cone (isotropic Coulomb) friction in the
  multibody solver; off, the pyramid approximation lets a multibody point mass sliding
  diagonally feel sqrt(2) mu (measured at 2 m/s, mu = 0.5: it slid 0.287 m instead of
  0.407 m). ``btRigidBody`` friction (``clean``) takes its first direction along the
  sliding velocity and is exact Coulomb either way.
- ``allowedCcdPenetration``: continuous collision detection (per body,
  ``ccdSweptSphereRadius``) is not used when the penetration is below this. CCD is off
  here (Bullet's CCD stops a fast body at its time of impact within the step, which is
  not the lecture's collision response), so it has no effect.

``default`` is the engine as a user gets it, apart from the scene's own parameters and
the point-mass settings above: ``createMultiBody``'s default ``btMultiBody`` bodies,
``fixedTimeStep = h``, ``numSubSteps = 0``, every solver and contact setting at pybullet's
defaults. ``clean`` changes only the contact treatment, each change justified by
measurements on a 5 cm ball dropped from 1 m onto a plane (``h`` = 1/240 and 1/1000 s)
and on a particle sliding with friction:

- bodies created with ``useMaximalCoordinates=True`` (``btRigidBody``, for particles and
  planes): required for split impulse, see above (with ``btMultiBody`` bodies the
  ``clean`` parameters gave the default's rebound of 0.878 for ``e`` = 0.8);
- ``useSplitImpulse = 1``, ``splitImpulsePenetrationThreshold = 0``: every penetration is
  pushed out without touching the velocity. The rebound ratio becomes ``e`` to rounding
  (default at ``h`` = 1/240, ``e`` = 0.8: 0.878; at ``e`` = 0: 0.070 instead of 0);
- ``restitutionVelocityThreshold = 0``: slow bounces keep their restitution (a ball
  hitting at 0.198 m/s with ``e`` = 0.8 at ``h`` = 1 ms: 0.8 instead of 0);
- ``contactProcessingThreshold = 0`` on every body (``changeDynamics``): the solver
  ignores *speculative* contacts (points still apart). Left on, a particle within a
  contact distance of the plane at the start of a step is stopped short and bounced from
  above the plane with ``e v - gap / h``: at ``h`` = 1 ms and ``e`` = 0.5 the second
  bounce measured 0.25 instead of 0.5, and the 0.198 m/s impact above 0.016;
- ``contactERP`` stays 0.08: it now only sets how fast the push removes a penetration;
  larger values lift the particle by more of its depth in one step and add potential
  energy (``e`` = 1, ``h`` = 1/240: apex ratio 1.0006 at 0.08, 1.0016 at 0.2, 1.0041 at
  0.5);
- ``contactSlop`` stays 1e-5 m: at 0 a particle sliding on a plane with friction loses
  its contact every few steps once slow and keeps sliding at about 1 cm/s (measured);
- ``enableConeFriction``, ``warmStartingFactor``, ``contactBreakingThreshold``,
  ``allowedCcdPenetration`` stay at their defaults (no measurable effect on these scenes).

Reading back
------------
The stepping loop, recording and blow-up checks are :class:`FixedStepAdapter`'s.
At each recorded step (``truestep.reference_impl.integrate.record_indices``) the positions and
velocities of every movable particle are read with ``getBasePositionAndOrientation`` and
``getBaseVelocity``; pinned particles are at ``x0 + v0 t`` with velocity ``v0``.
Energy is :func:`truestep.reference_impl.particles.total_energy` of that state; ``nfev`` and
``steps`` count ``stepSimulation`` calls. A recorded state that is non-finite or beyond
:data:`truestep.reference_impl.integrate.BLOWUP` ends the run with status ``unstable``.

Not modelled: emitters, plain ODE cases.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from truestep.adapters.base import FixedStepAdapter
from truestep.adapters.quiet import import_quietly
from truestep.cases.case import Case
from truestep.reference_impl import forces
from truestep.reference_impl.features import Feature
from truestep.reference_impl.model import ParticleModel

p = import_quietly("pybullet", banner=r"^pybullet build time:")  # its greeting, on stderr

POINT_RADIUS = 0.01
"""Radius (m) of the sphere standing in for a radius-0 particle; its planes move back as much."""
WALL_HALF_SIZE = 1e3
"""Half the side (m) of the box that stands for a thin wall (a plane with thickness)."""


def _z_to(normal: np.ndarray) -> list[float]:
    """The quaternion (x, y, z, w) turning the z axis onto the unit vector ``normal``."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, normal)
    s, c = float(np.linalg.norm(axis)), float(z @ normal)
    if s < 1e-12:
        return [0.0, 0.0, 0.0, 1.0] if c > 0 else [1.0, 0.0, 0.0, 0.0]
    half = 0.5 * np.arctan2(s, c)
    return [*(np.sin(half) * axis / s).tolist(), float(np.cos(half))]


SPHERES, PLANES, POINTS, POINT_PLANES = 1, 2, 4, 8
"""Collision filter groups: spheres hit planes, points hit the shifted planes, nothing else."""

CLEAN_PARAMETERS: dict[str, float] = {
    "useSplitImpulse": 1,
    "splitImpulsePenetrationThreshold": 0.0,
    "restitutionVelocityThreshold": 0.0,
}
"""``setPhysicsEngineParameter`` settings of the ``clean`` method (see the module docstring)."""

CLEAN_CONTACT_PROCESSING_THRESHOLD = 0.0
"""m, per body: contacts still this far apart or farther are not handed to the solver."""


@dataclass
class BulletScene:
    """A particle scene built in one pybullet client.

    client : the physicsClientId
    bodies : ndarray of int, shape (n,)     body id of each particle
    movable : ndarray of int                particles that move (not pinned)
    read_x, read_v : ndarray of int         particles whose position / velocity the per-step
                                             forces need (movable ones only)
    forced : ndarray of int                 movable particles that may receive a force
    drifting : ndarray of int               pinned particles with an initial velocity
    """

    client: int
    bodies: np.ndarray
    movable: np.ndarray
    read_x: np.ndarray
    read_v: np.ndarray
    forced: np.ndarray
    drifting: np.ndarray


def _needs(model: ParticleModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Masks (n,) of particles whose x, whose v the forces read, and which may get a force."""
    n = model.n
    need_x, need_v, forced = np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, bool)
    s, a = model.springs, model.anchors
    if len(s):
        for ends in (s.i, s.j):
            need_x[ends] = forced[ends] = True
            need_v[ends[s.damping != 0]] = True
    if len(a):
        need_x[a.i] = forced[a.i] = True
        need_v[a.i[a.damping != 0]] = True
    if model.drag:
        need_v[:] = forced[:] = True
    if model.gravitation is not None:
        need_x[:] = forced[:] = True
    for fld in model.fields:
        forced[:] = True
        if fld.kind == "wind":
            need_v[:] = True
        else:
            need_x[:] = True
    for i, _, _, _ in model.impulses:
        forced[i] = True
    movable = ~model.fixed
    forced &= movable
    need_x = (need_x | forced) & movable
    return need_x, need_v & movable, forced


def build_scene(model: ParticleModel, h: float, *, clean: bool, reuse: bool = False) -> BulletScene:
    """Build ``model`` in a new DIRECT client with step ``h`` (s); see the module docstring.

    ``reuse`` (the adapter's runs, one scene at a time): in this process's client, emptied
    by ``resetSimulation`` (which makes Bullet's world anew: its bodies, broad phase,
    solver and their parameters; tested bit for bit against a new client, after a run of
    the other method), not in a new one: opening a client costs 3-20 ms a run."""
    cid = _reset_client() if reuse else p.connect(p.DIRECT)
    try:
        p.setPhysicsEngineParameter(fixedTimeStep=h, numSubSteps=0, physicsClientId=cid)
        if clean:
            p.setPhysicsEngineParameter(**CLEAN_PARAMETERS, physicsClientId=cid)
        p.setGravity(*(float(g) for g in model.gravity), physicsClientId=cid)
        maximal = bool(clean)
        extra = {"contactProcessingThreshold": CLEAN_CONTACT_PROCESSING_THRESHOLD} if clean else {}

        movable = ~model.fixed
        point = movable & (model.radius <= 0)
        sphere = movable & (model.radius > 0)
        shapes: dict[float, int] = {}
        bodies = np.zeros(model.n, dtype=int)
        for i in range(model.n):
            radius = float(model.radius[i]) if model.radius[i] > 0 else POINT_RADIUS
            if radius not in shapes:
                shapes[radius] = p.createCollisionShape(p.GEOM_SPHERE, radius=radius, physicsClientId=cid)
            mass = 0.0 if model.fixed[i] else float(model.mass[i])
            body = p.createMultiBody(
                mass,
                shapes[radius],
                -1,
                model.x0[i].tolist(),
                useMaximalCoordinates=maximal,
                physicsClientId=cid,
            )
            bodies[i] = body
            if model.fixed[i]:
                p.setCollisionFilterGroupMask(body, -1, 0, 0, physicsClientId=cid)
                continue
            p.changeDynamics(
                body,
                -1,
                mass=mass,
                localInertiaDiagonal=[0.0, 0.0, 0.0],
                linearDamping=0.0,
                angularDamping=0.0,
                maxJointVelocity=np.inf,
                restitution=1.0,
                lateralFriction=1.0,
                **extra,
                physicsClientId=cid,
            )
            group, mask = (POINTS, POINT_PLANES) if point[i] else (SPHERES, PLANES)
            if not model.planes:
                group = mask = 0
            p.setCollisionFilterGroupMask(body, -1, group, mask, physicsClientId=cid)
            p.resetBaseVelocity(body, model.v0[i].tolist(), [0.0, 0.0, 0.0], physicsClientId=cid)

        for plane in model.planes:
            for present, shift, group, mask in (
                (sphere, 0.0, PLANES, SPHERES),
                (point, -POINT_RADIUS, POINT_PLANES, POINTS),
            ):
                if not np.any(present):
                    continue
                at = plane.point + shift * plane.normal
                orientation = [0.0, 0.0, 0.0, 1.0]
                if plane.thickness > 0:  # a thin wall: a box whose face is the plane
                    half = 0.5 * plane.thickness
                    shape = p.createCollisionShape(
                        p.GEOM_BOX, halfExtents=[WALL_HALF_SIZE, WALL_HALF_SIZE, half], physicsClientId=cid
                    )
                    at = at - half * plane.normal
                    orientation = _z_to(plane.normal)
                else:
                    shape = p.createCollisionShape(
                        p.GEOM_PLANE, planeNormal=plane.normal.tolist(), physicsClientId=cid
                    )
                body = p.createMultiBody(
                    0.0,
                    shape,
                    -1,
                    at.tolist(),
                    orientation,
                    useMaximalCoordinates=maximal,
                    physicsClientId=cid,
                )
                p.changeDynamics(
                    body,
                    -1,
                    restitution=float(plane.restitution),
                    lateralFriction=float(plane.friction),
                    **extra,
                    physicsClientId=cid,
                )
                p.setCollisionFilterGroupMask(body, -1, group, mask, physicsClientId=cid)
    except BaseException:
        _CLIENT.pop(os.getpid(), None)
        p.disconnect(cid)
        raise
    need_x, need_v, forced = _needs(model)
    drifting = model.fixed & np.any(model.v0 != 0, axis=1)
    return BulletScene(
        cid,
        bodies,
        np.flatnonzero(movable),
        np.flatnonzero(need_x),
        np.flatnonzero(need_v),
        np.flatnonzero(forced),
        np.flatnonzero(drifting),
    )


_CLIENT: dict[int, int] = {}
"""The client :func:`build_scene` reuses, by the process that opened it (a forked process
opens its own)."""


def _reset_client() -> int:
    """This process's DIRECT client, emptied (``resetSimulation``), or a new one."""
    cid = _CLIENT.get(os.getpid())
    if cid is not None and p.isConnected(physicsClientId=cid):
        p.resetSimulation(physicsClientId=cid)
        return cid
    cid = p.connect(p.DIRECT)
    _CLIENT[os.getpid()] = cid
    return cid


def external_forces(
    model: ParticleModel, f: np.ndarray, x: np.ndarray, v: np.ndarray, t: float
) -> np.ndarray:
    """Every force but gravity into ``f`` (n, 3), N, at ``x``, ``v`` (n, 3) and time ``t`` (s)."""
    return forces.add_model_forces(f, model, x, v, t, gravity=False)


def _read_moving(cid: int, bodies: list[int]) -> tuple[list, list]:
    """Positions and velocities of ``bodies`` as pybullet returns them (lists of tuples)."""
    get_x, get_v = p.getBasePositionAndOrientation, p.getBaseVelocity
    return [get_x(b, cid)[0] for b in bodies], [get_v(b, cid)[0] for b in bodies]


class _Run:
    """A built scene and the work around ``stepSimulation`` for one run.

    ``x``, ``v``, ``f`` (n, 3) hold the state the forces read and the forces (model order);
    ``fresh`` says ``x`` and ``v`` of the movable particles were read after the last step
    (at a record), so the next step's forces need not read them again. A snapshot is the
    pair of lists pybullet returns for the movable particles, made arrays after the loop.
    """

    def __init__(self, model: ParticleModel, scene: BulletScene) -> None:
        self.model, self.scene = model, scene
        self.x, self.v, self.f = model.x0.copy(), model.v0.copy(), np.zeros((model.n, 3))
        self.x0_drift, self.v0_drift = model.x0[scene.drifting], model.v0[scene.drifting]
        self.moving = scene.bodies[scene.movable].tolist()
        self.bx = scene.bodies[scene.read_x].tolist()
        self.bv = scene.bodies[scene.read_v].tolist()
        self.bf = scene.bodies[scene.forced].tolist()
        self.forcing, self.drifting = len(scene.forced) > 0, len(scene.drifting) > 0
        self.fresh, self.t = False, 0.0
        self.latest: tuple[float, list, list] | None = None

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """Every particle's position and velocity now, (n, 3) each."""
        if self.fresh and self.latest is not None:
            _, xk, vk = self.latest
        else:
            xk, vk = _read_moving(self.scene.client, self.moving)
        x, v, sc = self.x, self.v, self.scene
        x[sc.movable], v[sc.movable] = xk, vk
        if self.drifting:
            x[sc.drifting] = self.x0_drift + self.t * self.v0_drift
        return x, v

    def unpack(self, snaps: list[tuple[float, list, list]]) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities (T, n, 3) of ``T`` snapshots; pinned particles at
        ``x0 + v0 t``."""
        m, movable, n = self.model, self.scene.movable, len(snaps)
        t = np.array([s[0] for s in snaps])
        xr = np.repeat(m.x0[None], n, axis=0)
        vr = np.repeat(m.v0[None], n, axis=0)
        xr[:, movable] = np.array([s[1] for s in snaps], dtype=float).reshape(n, len(movable), 3)
        vr[:, movable] = np.array([s[2] for s in snaps], dtype=float).reshape(n, len(movable), 3)
        if self.drifting:
            xr[:, self.scene.drifting] = self.x0_drift + t[:, None, None] * self.v0_drift
        return xr, vr


class PybulletAdapter(FixedStepAdapter):
    """pybullet's own step on particle scenes, as shipped and with clean contacts.

    See the module docstring for the model, the scheme and what ``clean`` changes.
    """

    name = "pybullet"
    methods = ("default", "clean")
    method_notes: ClassVar = {
        "default": "Bullet as a user gets it: multibody particles, its contact settings at their defaults",
        "clean": "the same step with the contact treatment that would distort a comparison normalised "
        "(split impulse, no restitution threshold): see docs/engines/pybullet.md",
    }
    """One line per method, for the report's glossary."""
    method_facts: ClassVar[dict[str, str]] = {"default": "symplectic-euler", "clean": "symplectic-euler"}
    """Bullet steps velocity then position (semi-implicit Euler) with the numpy forces,
    dampers included, held at the start of the step: the reference's symplectic Euler."""
    capabilities = frozenset(
        {
            Feature.PLANAR,
            Feature.SPATIAL,
            Feature.POINT_MASSES,
            Feature.UNIFORM_GRAVITY,
            Feature.DRAG,
            Feature.SPRINGS,
            Feature.SPRING_DAMPING,
            Feature.ANCHORED_SPRINGS,
            Feature.UNIVERSAL_GRAVITATION,
            Feature.FORCE_FIELDS,
            Feature.PLANES,
            Feature.THIN_WALLS,
            Feature.FRICTION,
            Feature.PINNED_PARTICLES,
            Feature.IMPULSES,
        }
    )

    def duplicate(self, case: Case, method: str) -> str | None:
        """``clean`` changes only contact handling (and uses maximal coordinates, which
        step a free body the same way): without planes its trajectory is ``default``'s,
        bit for bit (tested)."""
        if method == "clean" and not case.particles.planes:
            return (
                "no contacts: the same trajectory as pybullet/default bit for bit "
                "(clean changes only contact handling)"
            )
        return None

    def build(self, case: Case, method: str, h: float) -> _Run:
        """The run's scene, in this process's client emptied (:func:`build_scene`)."""
        return _Run(case.particles, build_scene(case.particles, h, clean=method == "clean", reuse=True))

    def close(self, run: _Run) -> None:
        """Nothing: the client is emptied when the next scene is built in it."""

    def advance(self, run: _Run, k: int, steps: int, h: float) -> None:
        """``stepSimulation`` ``steps`` times; before each, with per-step forces, read
        what they need (unless just read at a record) and apply them at the step's start."""
        cid, sc = run.scene.client, run.scene
        run.t = (k + steps) * h
        step = p.stepSimulation
        if not run.forcing:
            for _ in range(steps):
                step(cid)
            run.fresh = False
            return
        x, v, f = run.x, run.v, run.f
        get_x, get_v, apply, world = (
            p.getBasePositionAndOrientation,
            p.getBaseVelocity,
            p.applyExternalForce,
            p.WORLD_FRAME,
        )
        for j in range(k, k + steps):
            if not run.fresh:
                if run.bx:
                    x[sc.read_x] = [get_x(b, cid)[0] for b in run.bx]
                if run.bv:
                    v[sc.read_v] = [get_v(b, cid)[0] for b in run.bv]
            if run.drifting:
                x[sc.drifting] = run.x0_drift + (j * h) * run.v0_drift
            external_forces(run.model, f, x, v, j * h)
            for b, fi, xi in zip(run.bf, f[sc.forced].tolist(), x[sc.forced].tolist(), strict=True):
                apply(b, -1, fi, xi, world, cid)
            step(cid)
            run.fresh = False

    def snapshot(self, run: _Run) -> tuple[float, list, list]:
        """The time and the movable particles' positions and velocities as pybullet gives
        them (kept as lists in the timed loop); the forces of the next step reuse them."""
        cid, get_x, get_v = run.scene.client, p.getBasePositionAndOrientation, p.getBaseVelocity
        xk = [get_x(b, cid)[0] for b in run.moving]
        vk = [get_v(b, cid)[0] for b in run.moving]
        if run.forcing:
            run.x[run.scene.movable], run.v[run.scene.movable] = xk, vk
        run.fresh, run.latest = True, (run.t, xk, vk)
        return run.latest

    def read(self, run: _Run) -> tuple[np.ndarray, np.ndarray]:
        return run.read()

    def unpack(self, run: _Run, snaps: list) -> tuple[np.ndarray, np.ndarray]:
        return run.unpack(snaps)
