"""MuJoCo behind the Adapter protocol: a particle case as an MJCF model.

The model
---------
Every case is written out as an MJCF string (:func:`mjcf`) and compiled once per run,
outside the timed region.

* **Particles.** Each free particle is a body at the origin with three slide joints
  along the world axes x, y, z (only x and y in a ``2d`` scene), so ``qpos`` *is* the
  particle's position and ``qvel`` its velocity. Slide joints make the point-mass
  dynamics exact in generalized coordinates: the mass matrix is ``m I``, there is no
  rotation and no Coriolis term. The body carries its mass in an explicit
  ``<inertial>`` (``inertiafromgeom="false"``), a sphere geom of the case's radius (a
  radius of 0, a point, becomes :data:`POINT_RADIUS`, 1 um, rather than a visible 1 cm
  that would move the contact surface) and a site that springs attach to.
  Pinned particles are sites on the world body: no joints, no degrees of freedom.
* **Defaults that would distort a comparison are zeroed**: joint armature,
  frictionloss and stiffness are written as 0 in the default class (joint damping is
  the drag, below); joint limits are off; contact margin and gap are 0.
  ``autoreset`` is disabled so that MuJoCo does not silently reset a diverging state
  to ``qpos0``: its bad-qpos/qvel/qacc warnings mark the run ``unstable`` instead
  (counted over the run in :meth:`MujocoAdapter.step_and_record`).
* **Gravity** is ``<option gravity>``; the step is ``<option timestep>`` =
  ``case.steps_for(dt)[1]``; the integrator is ``<option integrator>``, one of the
  adapter's methods. ``<flag energy="enable"/>`` makes MuJoCo compute its own
  ``mjData.energy`` (potential, kinetic), which the tests compare with
  :func:`truestep.reference_impl.particles.total_energy`; the Trajectory's energy is
  ``total_energy`` on the read-back state, as for every engine.
  A scene without planes is written with ``contact`` and ``constraint`` disabled: it can
  make no constraint, and MuJoCo skips the collision and solver stages that had nothing
  to do (:data:`NEEDS_NO_CONSTRAINTS`; the same trajectory, bit for bit).
* **Springs** (between particles and anchored) are two-site spatial tendons with
  ``stiffness`` = k_s, ``damping`` = k_d and ``springlength`` = r. A tendon of length L
  between sites produces the force ``k_s (L - r) + k_d dL/dt`` along it, which is the
  lecture's spring-damper (``dL/dt = dv . dx / |dx|``); anchors are sites on the world
  body. The test checks the force against :func:`truestep.reference_impl.forces.spring_forces`.
* **Drag** ``f = -k v`` is the slide joints' ``damping`` = k: with axis-aligned slide
  joints, joint damping is exactly a viscous force on the particle, and MuJoCo
  evaluates it at every RK4 stage.
* **Universal gravitation, force fields, impulses** have no MJCF element. They are
  computed with the reference force functions (:mod:`truestep.reference_impl.forces`) on the
  engine's own state and handed to MuJoCo in one of two ways (``stage_forces``):

  - ``True`` (default): a passive-force callback (``mujoco.set_mjcb_passive``), which
    MuJoCo calls inside every force evaluation, so RK4 sees the force at each of its
    four stages and their stage times;
  - ``False``: ``mjData.qfrc_applied`` set from the state before each ``mj_step``. The
    force is then held constant through the RK4 stages, which lowers RK4 to first order
    for position-dependent forces (a two-body circular orbit, one period: error 0.38 at
    h = 0.02 s and 0.052 at h = 0.0025 s, against 5.4e-8 and 1.1e-11 with the callback).

* **Planes** are ``<geom type="plane">`` with ``zaxis`` = the plane normal (planes are
  infinite for collision; ``size="0 0 1"``). Every (particle, plane) pair is an explicit
  ``<contact><pair>`` with its own ``solref``/``solimp`` (no mixing rules); particle
  geoms have ``contype = conaffinity = 0`` so particles never collide with each other.
  Frictionless planes use ``condim="1"``. Planes with a Coulomb coefficient mu use
  ``condim="3"``, ``friction`` mu and an elliptic cone, whose friction rows take their
  own ``solreffriction``: ``"2h 1"``, the stiffest MuJoCo allows, removes the tangential
  velocity in one step while the force stays inside the cone (sticking) and otherwise
  decelerates at mu times the normal force. (A pyramidal cone mixes normal and
  friction rows, and the direct-form normal damping, zero for ``e = 1``, would also be
  the friction rows' damping: a sliding particle would never slow down.)

Stepping and read-back
----------------------
``round(duration / dt)`` steps, recorded at the steps of
:func:`truestep.reference_impl.integrate.record_indices`. Without a Python force inside the
step (no gravitation, fields or impulses), MuJoCo steps in C with ``mujoco.rollout``
(one call takes up to 64 steps, from one record to a later one, and stores every
step's state, from which the records are picked): with a record at every step it took
0.56-0.63 (``Euler``) and 0.78-0.86 (``RK4``) of the time of a Python loop of ``mj_step``
calls on the one-ball ``bouncing-ball``, and the time of ``mj_step(m, d, nstep=k)``
(within 2 %) on the 1000 particles of ``particle-rain``
(``benchmarks/test_adapter_overhead.py``). Longer gaps between records, and scenes with
applied forces (the passive callback), step with ``mj_step(m, d, nstep=k)``, at most 64
steps per call so that a diverged state stops the run early; with
``stage_forces=False`` and applied forces the loop is per step in Python. Positions
and velocities are ``qpos``/``qvel`` at the records; pinned particles are their sites'
``site_xpos``. ``autoreset`` is off: a bad-state warning (qpos, qvel or qacc NaN or
beyond 1e10) ends the run as ``unstable`` at the time of the check that saw it, as does
:func:`truestep.adapters.base.finite_until` on the recorded positions. (Rollout stops at any
warning; the stretch it was on is then replayed with ``mj_step``, so the run ends at
the same step either way.)

Integrators and damping
-----------------------
``Euler`` is semi-implicit Euler (``v' = v + h a(q, v)``, ``q' = q + h v'``), except that
joint damping -- here the drag -- is integrated implicitly ("eulerdamp": backward Euler
on the drag, ``v' = v / (1 + h k / m)`` for drag alone); tendon damping (the spring
dampers) stays explicit in ``Euler``. ``implicit`` and ``implicitfast`` are
implicit-in-velocity Euler, ``(M + h D) (v' - v) = h M a(q, v)`` then ``q' = q + h v'``,
with ``D`` the velocity derivative of the passive forces: joint damping (drag) and
tendon damping (spring dampers); stiffness, a position derivative, stays explicit in
all of them. The documentation says ``implicit`` restricts ``D`` to the sparsity of
``M`` (dropping the damping of a tendon between two kinematic trees) and
``implicitfast`` drops the Coriolis/centripetal derivatives (there are none with slide
joints) and symmetrises ``D``; measured in 4.0.0, both integrate the damper between two
particles implicitly (a spring with k = 100 N/m, k_d = 50 N s/m between two 1 kg
particles stays stable at h = 0.05 s under both, where ``Euler`` and ``RK4`` diverge).
With no velocity-dependent force (a free fall) the three are the same semi-implicit
Euler: ``y_n = y_0 + v_0 n h + g h^2 n (n + 1) / 2``. ``RK4`` is the classical
fourth-order Runge-Kutta method, fully explicit, four force evaluations per step at the
stage times ``t, t + h/2, t + h/2, t + h`` (``nfev`` counts all four); it is exact for
constant gravity. Forces from the passive callback are never
in ``D``: they are explicit in every integrator.

Contacts and restitution
------------------------
MuJoCo's contact is soft. A contact row obeys approximately
``a + d (b v + k r) = (1 - d) a_u`` (r: signed distance, v: normal velocity, a_u: the
unconstrained acceleration, d: the impedance from ``solimp``, b and k from ``solref``).
With the "direct" ``solref = (-K, -B)`` MuJoCo sets ``b = B / d_w`` and
``k = K d(r) / d_w^2``; a constant impedance ``d(r) = d_0 = d_w = d`` (:data:`SOLIMP`:
``0.9999 0.9999``, MuJoCo's maximum impedance, so the width, midpoint and power of the
sigmoid do not matter) turns this into a unit-mass spring-damper, independent of the
particle's mass, that overrides gravity during the contact up to the term
``(1 - d) a_u = 1e-4 a_u``::

    r'' + B r' + K r = 0       while the contact pushes (a_ref >= a_u)

MuJoCo has no coefficient of restitution, so ``K`` and ``B`` are derived from the
case's ``e``. Write ``omega = sqrt(K)``, ``zeta = B / (2 omega)``,
``omega_d = omega sqrt(1 - zeta^2)``. From ``r(0) = 0``, ``r'(0) = -v``:
``r = -(v / omega_d) exp(-zeta omega t) sin(omega_d t)``. The contact is unilateral: it
releases when its force ``-(B r' + K r)`` reaches zero, i.e. at ``r'' = 0``, which
happens at ``omega_d t* = 2 arccos(zeta)`` (before ``r`` returns to 0; the half period
would be ``pi``). There ``r'(t*) = v exp(-zeta omega t*)``, so::

    e = exp(-2 zeta arccos(zeta) / sqrt(1 - zeta^2))        (zeta < 1)
    e = exp(-2 zeta arccosh(zeta) / sqrt(zeta^2 - 1))       (zeta > 1, overdamped)

(the linear spring-dashpot result of Schwager and Poeschel, 2007). It is not the
textbook ``exp(-zeta pi / sqrt(1 - zeta^2))`` of a full half oscillation, which holds
only if the contact could pull. ``e = 1`` gives ``zeta = 0`` (no damping); critical
damping gives ``e = exp(-2) = 0.135`` -- the restitution of MuJoCo's default critically
damped contact in fast impacts -- and smaller ``e`` needs overdamping,
``e ~ 1 / (4 zeta^2)``; ``e = 0`` would need infinite damping. :func:`damping_ratio`
inverts the relation. The stiffness follows from a contact time ``t_c`` (the undamped
half period): ``omega = pi / t_c``, ``K = omega^2``, ``B = 2 zeta omega``, with
``t_c = contact_steps * h`` (default :data:`CONTACT_STEPS` = 10 steps; MuJoCo's own rule
asks for a time constant of at least two steps). Tying ``t_c`` to the step keeps the
contact resolved by the same number of steps at every ``h``, so the relative error of
the restitution hardly depends on ``h`` and the trajectory converges to the rigid
bounce of the reference as ``h -> 0``; the price is a penetration of about
``v t_c / pi``. An explicit damper with ``h B > 1`` reverses the normal velocity within
a step (``h B > 2`` diverges), so ``zeta`` is capped at ``h B = 1``
(:func:`max_damping_ratio`, 1.59 at 10 steps, continuous-contact ``e = 0.069``); the
run's message names the cap when it applies (always for ``e = 0``). The remaining
discrete-time errors come from the step resolution of the contact and from contact
detection at step starts: a contact begins up to one step of travel deep, and the
energy the spring finds stored there, up to ``(omega h)^2 = (pi / contact_steps)^2`` of
the impact energy, comes back out in the rebound.

Measured with a ball (r = 0.05 m) dropped from 1 m, first three bounces, h = 1/240 and
1/1000 s: the rebound/impact speed ratio lands within 0.03 of ``e`` for e = 0.8 to 1 and
within 0.07 for e = 0.5 under ``Euler``/``implicit``/``implicitfast`` (identical: the
contact is not in ``D``), and within 0.03 under ``RK4`` (0.01 at h = 1/1000); the ball
penetrates 9-14 mm at 1/1000 and 41-58 mm at 1/240 (more than its radius). For e = 0
the Euler family keeps the ball on the floor; ``RK4`` lets it rebound once at 0.05 of
the impact speed at h = 1/1000 s.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, ClassVar, cast

import mujoco
import numpy as np
from mujoco import rollout

from truestep.adapters.base import FactsSpec, FixedStepAdapter, Recording, resolve_facts
from truestep.adapters.contact_law import (
    CONTACT_STEPS,
    contact_solref,
    max_damping_ratio,
    restitution_of,
)
from truestep.cases.case import Case
from truestep.reference_impl import forces
from truestep.reference_impl.features import Feature
from truestep.reference_impl.integrate import CHECK_EVERY, record_indices
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.solvers import MethodFacts, Stability

INTEGRATORS: dict[str, int] = {
    "Euler": int(mujoco.mjtIntegrator.mjINT_EULER),
    "implicit": int(mujoco.mjtIntegrator.mjINT_IMPLICIT),
    "implicitfast": int(mujoco.mjtIntegrator.mjINT_IMPLICITFAST),
    "RK4": int(mujoco.mjtIntegrator.mjINT_RK4),
}
"""Method name (the MJCF ``<option integrator>`` value) -> ``mjtIntegrator``."""


def implicit_damper_step(a: float, b: float) -> np.ndarray:
    """``implicit``/``implicitfast`` on the linear test system: the velocity update is
    implicit in the velocity derivatives of the forces (the damper), explicit in the
    positions, then ``q' = q + h v'``: ``h v' = (h v - a q) / (1 + b)``."""
    return np.array([[1.0 - a / (1.0 + b), 1.0 / (1.0 + b)], [-a / (1.0 + b), 1.0 / (1.0 + b)]])


IMPLICIT_FACTS = MethodFacts(
    order=1,
    evaluations_per_step=1,
    symplectic=True,
    stability=Stability(imaginary=2.0, real=float("inf"), step_matrix=implicit_damper_step),
)
"""``implicit`` and ``implicitfast``: the velocity update is implicit in the forces'
velocity derivatives (every damper); without dampers it is the same step as ``Euler``."""

METHOD_FACTS: dict[str, FactsSpec] = {
    "Euler": "symplectic-euler",
    "implicit": IMPLICIT_FACTS,
    "implicitfast": IMPLICIT_FACTS,
    "RK4": "rk4",
}
"""The facts of each integrator (MuJoCo's documentation, "Numerical integration").
``Euler`` is semi-implicit Euler, velocity first: the reference's ``symplectic-euler``
for springs and their dampers (tendon damping is explicit in it; only joint damping, the
drag here, is implicit). ``RK4`` is the classical RK4, with every force at every stage."""

EVALUATIONS_PER_STEP = {
    m: cast(MethodFacts, resolve_facts(f)).evaluations_per_step for m, f in METHOD_FACTS.items()
}
"""Force evaluations MuJoCo makes per step (from :data:`METHOD_FACTS`): ``nfev`` is steps
times this."""

POINT_RADIUS = 1e-6
"""Sphere radius (m) for a point particle (radius 0): small enough that the contact
surface sits where the point's plane would be, 1 um being far below any penetration."""

WALL_HALF_SIZE = 1e3
"""Half the side (m) of the box that stands for a thin wall (a plane with thickness)."""

SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)
"""Constant impedance d = 0.9999 (MuJoCo's maximum): the contact follows the reference
spring-damper and only 1e-4 of the unconstrained acceleration leaks through."""

_BAD_STATE = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)
ROLLOUT_STEPS = 64
"""The most steps one ``mujoco.rollout`` call takes (it stores the state of every step)."""


@dataclass
class Layout:
    """Where each particle lives in the compiled model.

    free : ndarray of int, shape (n_free,)   particle indices that have joints
    pinned : ndarray of int, shape (n_pin,)  particle indices that are world sites
    dim : 2 or 3                             slide joints per free particle
    pinned_sites : list of str               site names of the pinned particles
    notes : list of str                      modelling compromises, for the run's message
    """

    free: np.ndarray
    pinned: np.ndarray
    dim: int
    pinned_sites: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _check_method(method: str) -> None:
    if method not in INTEGRATORS:
        known = ", ".join(INTEGRATORS)
        raise ValueError(f"method: unknown MuJoCo integrator {method!r}; known: {known}")


def _vec(a: np.ndarray) -> str:
    return " ".join(f"{float(v):.17g}" for v in a)


def mjcf(
    model: ParticleModel,
    method: str,
    h: float,
    *,
    contact_steps: float = CONTACT_STEPS,
    autoreset_flag: bool = True,
    only_what_it_needs: bool = True,
    energy: bool = True,
    sensors: bool = True,
) -> tuple[str, Layout]:
    """The MJCF text of a particle scene, and where its particles are in the model.

    ``method`` is one of :data:`INTEGRATORS`, ``h`` the time step (s); plane contacts
    last about ``contact_steps`` steps (``t_c = contact_steps * h``). ``autoreset_flag``
    writes ``autoreset="disable"``; MuJoCo Warp, which never resets a state and has no
    such flag, takes the model without it. ``only_what_it_needs``: a scene without planes
    (so no contact pair, and no joint limit or equality either) is written with
    ``contact`` and ``constraint`` disabled (:data:`NEEDS_NO_CONSTRAINTS`). ``energy``
    writes ``energy="enable"`` (MuJoCo computes ``mjData.energy``, which the tests compare
    with truestep's); ``sensors=False`` writes ``sensor="disable"`` (the model has no
    sensor; MuJoCo Warp launches its sensor kernels without one). Neither changes a step.
    """
    _check_method(method)
    dim = 2 if model.dimension == 2 else 3
    fixed = np.asarray(model.fixed, bool)
    layout = Layout(np.flatnonzero(~fixed), np.flatnonzero(fixed), dim)
    radius = np.where(model.radius > 0, model.radius, POINT_RADIUS)
    axes = ("1 0 0", "0 1 0", "0 0 1")[:dim]

    world: list[str] = []
    for k, plane in enumerate(model.planes):
        if plane.thickness > 0:  # a thin wall: a box whose face is the plane
            half = 0.5 * plane.thickness
            world.append(
                f'<geom name="plane{k}" type="box" pos="{_vec(plane.point - half * plane.normal)}" '
                f'zaxis="{_vec(plane.normal)}" size="{WALL_HALF_SIZE} {WALL_HALF_SIZE} {half!r}"/>'
            )
            continue
        world.append(
            f'<geom name="plane{k}" type="plane" pos="{_vec(plane.point)}" '
            f'zaxis="{_vec(plane.normal)}" size="0 0 1"/>'
        )
    for i in layout.pinned:
        world.append(f'<site name="s{i}" pos="{_vec(model.x0[i])}"/>')
        layout.pinned_sites.append(f"s{i}")
    a: Any  # an anchor's index, then (below) the anchors
    for a, (point, i) in enumerate(zip(model.anchors.point, model.anchors.i, strict=True)):
        if not fixed[i]:
            world.append(f'<site name="anchor{a}" pos="{_vec(point)}"/>')
    for i in layout.free:
        joints = "".join(
            f'<joint name="p{i}{c}" type="slide" axis="{ax}"/>' for c, ax in zip("xyz", axes, strict=False)
        )
        # rotational inertia plays no part (no rotational joints) but must be positive
        inertia = _vec(np.full(3, max(0.4 * model.mass[i] * radius[i] ** 2, 1e-12)))
        world.append(
            f'<body name="p{i}">'
            f'<inertial pos="0 0 0" mass="{model.mass[i]:.17g}" diaginertia="{inertia}"/>'
            f'{joints}<geom name="g{i}" type="sphere" size="{radius[i]:.17g}"/>'
            f'<site name="s{i}"/></body>'
        )

    tendons: list[str] = []
    s = model.springs
    for i, j, k, c, r in zip(s.i, s.j, s.stiffness, s.damping, s.rest, strict=True):
        if fixed[i] and fixed[j]:
            continue
        tendons.append(_tendon(f"s{i}", f"s{j}", k, c, r))
    a = model.anchors
    for n, (i, k, c, r) in enumerate(zip(a.i, a.stiffness, a.damping, a.rest, strict=True)):
        if not fixed[i]:
            tendons.append(_tendon(f"anchor{n}", f"s{i}", k, c, r))

    pairs: list[str] = []
    t_c = contact_steps * h
    solimp = _vec(np.array(SOLIMP))
    for k, plane in enumerate(model.planes):
        stiffness, damping, capped = contact_solref(plane.restitution, t_c, h)
        if capped:
            zeta = max_damping_ratio(t_c, h)
            layout.notes.append(
                f"plane {k}: restitution {plane.restitution:g} needs more contact damping than "
                f"a step of {h:.3g} s can integrate; damping ratio capped at {zeta:.3g} "
                f"(h B = 1), continuous-contact restitution {restitution_of(zeta):.3f}"
            )
        if plane.friction > 0:
            mu = f"{plane.friction:.17g}"
            # friction rows: positive (timeconst) form; timeconst = 2 h kills the
            # tangential velocity in one step inside the cone: Coulomb friction
            rest = f'condim="3" friction="{mu} {mu} 0 0 0" solreffriction="{2 * h:.17g} 1"'
        else:
            rest = 'condim="1"'
        for i in layout.free:
            pairs.append(
                f'<pair geom1="plane{k}" geom2="g{i}" {rest} margin="0" gap="0" '
                f'solref="{-stiffness:.17g} {-damping:.17g}" solimp="{solimp}"/>'
            )

    flags = (' energy="enable"' if energy else "") + ("" if sensors else ' sensor="disable"')
    reset = ' autoreset="disable"' if autoreset_flag else ""
    reset += NEEDS_NO_CONSTRAINTS if only_what_it_needs and not pairs else ""
    text = "\n".join(
        [
            '<mujoco model="truestep">',
            '  <compiler inertiafromgeom="false" angle="radian"/>',
            f'  <option timestep="{h:.17g}" integrator="{method}" gravity="{_vec(model.gravity)}" '
            'cone="elliptic">',
            f"    <flag{flags}{reset}/>",
            "  </option>",
            "  <default>",
            f'    <joint armature="0" damping="{model.drag:.17g}" frictionloss="0" stiffness="0" '
            'limited="false"/>',
            '    <geom contype="0" conaffinity="0"/>',
            "  </default>",
            "  <worldbody>",
            *("    " + w for w in world),
            "  </worldbody>",
            *(["  <tendon>", *("    " + t for t in tendons), "  </tendon>"] if tendons else []),
            *(["  <contact>", *("    " + p for p in pairs), "  </contact>"] if pairs else []),
            "</mujoco>",
        ]
    )
    return text, layout


NEEDS_NO_CONSTRAINTS = ' contact="disable" constraint="disable"'
"""The flags of a scene that cannot make a constraint (no plane, so no contact pair; joint
limits are off and there are no equalities): MuJoCo then skips its collision pipeline and
its constraint solver, which had nothing to do. The trajectory is the same bit for bit
(a test compares it with the model without the flags, for MuJoCo C and MuJoCo Warp and
every integrator); MuJoCo Warp's CPU steps of the cloths cost 10-20% less."""


def _tendon(site1: str, site2: str, k: float, c: float, rest: float) -> str:
    return (
        f'<spatial stiffness="{k:.17g}" damping="{c:.17g}" springlength="{rest:.17g}" '
        f'frictionloss="0"><site site="{site1}"/><site site="{site2}"/></spatial>'
    )


def has_applied_forces(model: ParticleModel) -> bool:
    """Whether the scene needs forces MJCF cannot express (gravitation, fields, impulses)."""
    return model.gravitation is not None or bool(model.fields) or bool(model.impulses)


class AppliedForces:
    """Universal gravitation, force fields and impulses on MuJoCo's state, as generalized forces.

    Parameters
    ----------
    model : ParticleModel
    layout : Layout
        Which particles have joints.

    Calling it with ``(qpos, qvel, t)`` returns the generalized force (shape ``(nv,)``, N)
    of :mod:`truestep.reference_impl.forces` at that state: the same functions the reference
    implementation accumulates, with pinned particles at their fixed positions.
    """

    def __init__(self, model: ParticleModel, layout: Layout) -> None:
        self.model = model
        self.layout = layout
        self.x = np.array(model.x0, float)
        self.v = np.zeros_like(self.x)
        self.f = np.zeros_like(self.x)

    def __call__(self, qpos: np.ndarray, qvel: np.ndarray, t: float) -> np.ndarray:
        m, lay = self.model, self.layout
        self.x[lay.free, : lay.dim] = qpos.reshape(-1, lay.dim)
        self.v[lay.free, : lay.dim] = qvel.reshape(-1, lay.dim)
        f = self.f
        f[:] = 0.0
        if m.gravitation is not None:
            forces.add_gravitation(f, self.x, m.mass, m.gravitation)
        if m.fields:
            forces.add_fields(f, m.fields, self.x, self.v, m.mass, t)
        forces.add_impulses(f, m.impulses, t)
        return f[lay.free, : lay.dim].ravel()


@dataclass
class Scene:
    """A compiled case: MuJoCo's model and data, the particle layout and the applied forces."""

    model: mujoco.MjModel
    data: mujoco.MjData
    layout: Layout
    xml: str
    applied: AppliedForces | None
    pinned_x: np.ndarray
    """Positions of the pinned particles read from MuJoCo (site_xpos), shape (n_pin, 3), m."""
    warnings: list[str] = field(default_factory=list)
    """MuJoCo's warnings during the run, in order."""

    def positions(self, n: int) -> np.ndarray:
        """All particle positions, shape (n, 3), m, from ``qpos`` and the pinned sites."""
        x = np.zeros((n, 3))
        x[self.layout.free, : self.layout.dim] = self.data.qpos.reshape(-1, self.layout.dim)
        x[self.layout.pinned] = self.pinned_x
        return x

    def velocities(self, n: int) -> np.ndarray:
        """All particle velocities, shape (n, 3), m/s (pinned particles: 0)."""
        v = np.zeros((n, 3))
        v[self.layout.free, : self.layout.dim] = self.data.qvel.reshape(-1, self.layout.dim)
        return v


def build(
    case: Case, method: str, dt: float, *, contact_steps: float = CONTACT_STEPS, reuse: bool = False
) -> Scene:
    """Compile ``case`` for ``method`` at nominal step ``dt`` and set the initial state.

    ``reuse`` (the adapter's runs, one scene at a time): a model compiled from the same
    MJCF as the last one compiled so in this process (a row's warm-up, measured and timed
    runs) is that model again, with data made afresh: MuJoCo compiles the same text to the
    same model, and no run changes its model (tested bit for bit). The compile, 1-2 ms
    for a small scene and 70 ms for the rain's 1000 bodies, is then paid once a row, not
    once a run."""
    model = case.particles
    h = case.steps_for(dt)[1]
    xml, layout = mjcf(model, method, h, contact_steps=contact_steps)
    if reuse and _LAST_MODEL.get("xml") == xml:
        m = _LAST_MODEL["model"]
    else:
        m = mujoco.MjModel.from_xml_string(xml)
        if reuse:
            _LAST_MODEL.update(xml=xml, model=m)
    d = mujoco.MjData(m)
    d.qpos[:] = model.x0[layout.free, : layout.dim].ravel()
    d.qvel[:] = model.v0[layout.free, : layout.dim].ravel()
    mujoco.mj_forward(m, d)
    pinned_x = np.array([d.site(s).xpos for s in layout.pinned_sites]).reshape(-1, 3)
    applied = AppliedForces(model, layout) if has_applied_forces(model) else None
    return Scene(m, d, layout, xml, applied, pinned_x)


_LAST_MODEL: dict[str, Any] = {}
"""The last model :func:`build` compiled with ``reuse`` in this process, and its MJCF."""


def same_steps(case: Case, method: str) -> tuple[str, str] | None:
    """The method whose steps ``method`` repeats bit for bit on ``case``, and why, or ``None``.

    ``implicitfast`` differs from ``Euler`` only by the velocity derivatives of the passive
    and actuator forces (``M - h D`` in place of ``M``): a scene with no drag, no spring or
    anchor damping, no plane, and no force MuJoCo takes from truestep's callback has
    ``D = 0``, and MuJoCo (C and Warp) then computes Euler's steps (tested on every case of
    the repository where this holds)."""
    if method != "implicitfast" or case.model is None:
        return None
    model = case.particles
    damped = model.drag != 0 or np.any(model.springs.damping) or np.any(model.anchors.damping)
    if damped or model.planes or has_applied_forces(model):
        return None
    return "Euler", "no velocity-dependent force: implicitfast's M - h D is M, and its steps are Euler's"


class MujocoAdapter(FixedStepAdapter):
    """MuJoCo's four integrators on particle scenes (see the module docstring for the model).

    Parameters
    ----------
    stage_forces : bool
        Evaluate gravitation, force fields and impulses at every force evaluation of
        the integrator (passive callback; default) rather than once per step
        (``qfrc_applied`` held through the RK4 stages).
    contact_steps : float
        Plane contacts last about this many time steps (see the module docstring).
    """

    name = "mujoco"
    methods = tuple(INTEGRATORS)
    method_notes: ClassVar = {
        "Euler": "MuJoCo's semi-implicit Euler (velocity first)",
        "implicit": "MuJoCo's implicit-in-velocity Euler (damping and its derivatives implicit)",
        "implicitfast": "MuJoCo's implicit Euler without the Coriolis terms' derivatives",
        "RK4": "MuJoCo's classical Runge-Kutta 4",
    }
    """One line per method, for the report's glossary."""
    method_facts: ClassVar[dict[str, FactsSpec]] = METHOD_FACTS
    peers: ClassVar[dict[str, str]] = {"Euler": "symplectic-euler", "RK4": "rk4"}
    """The reference method each names as its scheme (compared in the report)."""
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

    def __init__(self, *, stage_forces: bool = True, contact_steps: float = CONTACT_STEPS) -> None:
        if contact_steps <= 0:
            raise ValueError(f"contact_steps: must be positive, got {contact_steps}")
        self.stage_forces = stage_forces
        self.contact_steps = contact_steps

    def build(self, case: Case, method: str, h: float) -> Scene:
        """The run's scene (:func:`build`, its model reused where its MJCF is the last one's)."""
        return build(case, method, h, contact_steps=self.contact_steps, reuse=True)

    def same_steps(self, case: Case, method: str) -> tuple[str, str] | None:
        """The method whose steps ``method`` repeats bit for bit (:func:`same_steps`)."""
        return same_steps(case, method)

    def read(self, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
        n = len(scene.layout.free) + len(scene.layout.pinned)
        return scene.positions(n), scene.velocities(n)

    def step_and_record(self, case: Case, scene: Scene, n_steps: int, h: float) -> Recording:
        """MuJoCo's own stepping (:func:`_step`: rollout where no Python force acts), with
        its warnings collected and the staged-force callback installed for the run."""
        marks = record_indices(n_steps, case.max_records)
        previous_warning = mujoco.get_mju_user_warning()
        previous_passive = mujoco.get_mjcb_passive()
        mujoco.set_mju_user_warning(scene.warnings.append)
        try:
            if scene.applied is not None and self.stage_forces:
                applied = scene.applied

                def passive(m: mujoco.MjModel, d: mujoco.MjData) -> None:
                    d.qfrc_passive += applied(d.qpos, d.qvel, d.time)

                mujoco.set_mjcb_passive(passive)
            held = scene.applied is not None and not self.stage_forces
            t, x, v, steps, wall, bad = _step(case, scene, marks, held=held)
        finally:
            mujoco.set_mjcb_passive(previous_passive)
            mujoco.set_mju_user_warning(previous_warning)
        return Recording(t, x, v, steps, wall, "MuJoCo flagged a diverged state" if bad else "")

    def notes(self, case: Case, method: str, scene: Scene) -> list[str]:
        notes = [f"{EVALUATIONS_PER_STEP[method]} force evaluation(s) per step", *scene.layout.notes]
        if scene.applied is not None and not self.stage_forces and method == "RK4":
            notes.append("applied forces held constant through the RK4 stages")
        if scene.warnings:
            notes.append(scene.warnings[0].strip())
        return notes


def _step(
    case: Case, scene: Scene, marks: np.ndarray, *, held: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float, bool]:
    """Step to the end, reading the state back at the step indices ``marks``.

    With no Python force inside a step (``scene.applied`` is None) the steps go to
    :func:`mujoco.rollout.rollout` in stretches of at most :data:`ROLLOUT_STEPS` steps
    from one record to a later one, the records picked out of its per-step states;
    a gap between records longer than that goes to ``mj_step(m, d, nstep=k)``. Rollout
    stops at any MuJoCo warning; then the stretch is replayed from its first record
    (state and warm start restored, warning counters cleared: the state and counters
    the ``mj_step`` path would have there) by ``mj_step``, which takes the rest of the
    run, so a run that warns ends exactly as it would without rollout.
    ``mj_step`` goes from record to record in chunks of at most :data:`CHECK_EVERY` steps,
    one step at a time with ``held`` (``qfrc_applied`` set from the state before every
    step, a Python loop). Stops at the first check that finds MuJoCo's bad-state
    warning, recording the state there. The state at a record is MuJoCo's own
    ``mjSTATE_FULLPHYSICS`` vector (time, qpos, qvel, ...), kept as is in the timed
    region and turned into particle arrays after it.

    Returns ``t`` (T,), ``x`` and ``v`` (T, n, 3), the steps taken, the wall time (s)
    of the stepping and reading back, and whether it stopped on a warning.
    """
    applied: Any  # scene.applied: AppliedForces or None (never None where ``held``)
    m, d, lay, applied = scene.model, scene.data, scene.layout, scene.applied
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    nstate = mujoco.mj_stateSize(m, spec)
    states = np.empty((len(marks), nstate))
    mujoco.mj_getState(m, d, states[0], spec)
    steps_at = marks.tolist()
    # reach[i]: the last record one rollout from record i can get to (i: the gap is too long)
    reach = (np.searchsorted(marks, marks + ROLLOUT_STEPS, side="right") - 1).tolist()
    warnings = d.warning.number  # a view: MuJoCo's warning counters
    roll = applied is None and not warnings.any()
    roller = rollout.Rollout(nthread=0)
    out = np.empty(min(ROLLOUT_STEPS, steps_at[-1]) * nstate)
    warmstart = np.empty((1, m.nv))
    bad_state = np.array(_BAD_STATE, dtype=int)
    get_state, mj_step = mujoco.mj_getState, mujoco.mj_step
    i, last, step, bad = 0, len(marks) - 1, 0, False
    start = time.perf_counter()
    while i < last:
        j = reach[i]
        if roll and j > i:
            span = steps_at[j] - step
            warmstart[0] = d.qacc_warmstart
            roller.rollout(
                [m],
                [d],
                states[i : i + 1],
                nstep=span,
                initial_warmstart=warmstart,
                state=out[: span * nstate],
                skip_checks=True,
            )
            if warnings.any():
                mujoco.mj_setState(m, d, states[i], spec)
                d.qacc_warmstart[:] = warmstart[0]
                warnings[:] = 0
                roll = False
                continue
            states[i + 1 : j + 1] = out.reshape(-1, nstate)[marks[i + 1 : j + 1] - step - 1]
            i, step = j, steps_at[j]
            continue
        target = steps_at[i + 1]
        while step < target:
            chunk = min(target - step, CHECK_EVERY)
            if held:
                for _ in range(chunk):
                    d.qfrc_applied[:] = applied(d.qpos, d.qvel, d.time)
                    mj_step(m, d)
            else:
                mj_step(m, d, chunk)
            step += chunk
            if warnings[bad_state].any():
                bad = True
                break
        i += 1
        get_state(m, d, states[i], spec)
        if bad:
            break
    wall = time.perf_counter() - start

    states = states[: i + 1]
    n, dim = case.particles.n, lay.dim
    x, v = np.zeros((len(states), n, 3)), np.zeros((len(states), n, 3))
    x[:, lay.free, :dim] = states[:, 1 : 1 + m.nq].reshape(len(states), -1, dim)
    x[:, lay.pinned] = scene.pinned_x
    v[:, lay.free, :dim] = states[:, 1 + m.nq : 1 + m.nq + m.nv].reshape(len(states), -1, dim)
    return states[:, 0].copy(), x, v, step, wall, bad
