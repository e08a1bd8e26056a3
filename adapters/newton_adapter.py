"""Newton behind the Adapter protocol (``pip install "truestep[newton]"``).

What runs
---------
Newton (``newton``) is the GPU physics engine NVIDIA, Google DeepMind and Disney Research
build on Warp. truestep runs its three particle solvers on one world, in float32, on
Warp's CPU device unless a device is asked:

* ``semi-implicit`` -- ``SolverSemiImplicit``: symplectic Euler on the summed forces
  (``v' = v + h a(x, v)``, ``x' = x + h v'``), springs and penalty contacts explicit;
* ``xpbd`` -- ``SolverXPBD``: extended position-based dynamics, springs as compliant
  distance constraints and contacts as position projections, :data:`XPBD_ITERATIONS`
  Gauss-Seidel iterations a step, velocities from the position change;
* ``vbd`` -- ``SolverVBD``: vertex block descent, an implicit (backward) Euler step
  minimised by per-particle Newton updates, :data:`VBD_ITERATIONS` sweeps a step.

The model is built with ``newton.ModelBuilder`` outside the timed region: each particle
with its mass (a pinned one with mass 0, Newton's kinematic particle), each spring with
``add_spring`` and its rest length set from the case (Newton's own is the initial
distance), each anchor as a kinematic particle with a spring to it, each plane as an
infinite ``add_shape_plane``. Each step is ``state.clear_forces()``, truestep's drag
kernel (below), the collision pipeline's ``collide`` and ``solver.step``, captured once as
a Warp graph in :func:`build` and launched once per step (the row's ``path`` says
``graph``; a test checks the graph's steps equal the calls made from Python bit for bit).

What truestep sets
------------------
* ``particle_max_velocity`` = inf: Newton clamps every particle's speed to 1e5 m/s by
  default, which would hide a blow-up; no clamp is left on.
* Particle-particle contact is off (``particle_grid`` = None and ``particle_max_radius``
  = 0, which only the particle-particle search reads): truestep's particles never
  collide with each other.
* Contact with a plane is Newton's penalty contact in ``semi-implicit`` and ``vbd``:
  a spring ``ke`` along the normal and a damper ``kd`` that acts only while the particle
  approaches. truestep scales both to the particles' mass ``m`` and the asked restitution
  ``e`` (Newton's defaults, ke = 1000 N/m and kd = 10 N s/m for any mass, launch 10 g
  particles at some 20 m/s): ``ke = m (pi / t_c)^2`` with a contact time ``t_c`` of
  :data:`~truestep.adapters.contact_law.CONTACT_STEPS` steps, as for MuJoCo, and
  ``kd = 2 zeta m pi / t_c`` with ``zeta`` from :func:`damping_ratio` (capped where the
  explicit damper does not overshoot: :data:`EXPLICIT_DAMPING`, e >= 0.26). Damped only while
  compressed, the spring returns the energy stored at the deepest point undamped, so
  ``e = exp(-zeta arccos(zeta) / sqrt(1 - zeta^2))`` (:func:`restitution_of`; half
  MuJoCo's exponent). Shape and particle constants are set alike (Newton averages them).
  ``xpbd`` ignores ``ke`` and ``kd``: its contact is a projection, and its restitution
  is Newton's ``soft_contact_restitution`` = ``e`` with ``enable_restitution``. What each
  solver gives is measured, not assumed (the restitution analysis).
* Drag ``f = -k v`` (the cloth cases) has no Newton element: a truestep kernel adds it to
  ``particle_f`` from the velocity at the start of each step, which every solver treats
  as an external force (explicit drag).

What it cannot run
------------------
Universal gravitation, force fields and impulses (no Newton element, and truestep adds
none), emitters, Coulomb friction (Newton's is a regularised slope truestep does not
normalise yet) and thin walls (Newton's planes are half-spaces) are ``unsupported``
rows with the reason. A 2-D scene runs in 3-D: its forces have no z component, so z stays
exactly 0.

Precision
---------
The state is float32: errors stall between 1e-6 and 1e-4 of a scene's size, and the
order fits and baselines use the float32 floor
(:func:`truestep.measures.metrics.round_off_floor`).
"""

from __future__ import annotations

import functools
import pickle
import time
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from truestep.adapters import contact_law
from truestep.adapters.base import Trajectory
from truestep.adapters.quiet import without_banner
from truestep.adapters.warp_runtime import BANNER, DEVICE, WarpAdapter, host_copy, host_view, start, wp
from truestep.cases.case import Case
from truestep.reference_impl.features import Feature
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.solvers import MethodFacts

with without_banner(BANNER):
    import newton

NARROW_PHASE_FACTORIES = ("create_narrow_phase_primitive_kernel", "create_narrow_phase_kernel_gjk_mpr")
"""The functions of Newton's ``geometry.narrow_phase`` module that make its collision
pipeline's kernels (:func:`share_narrow_phase_kernels`)."""


def share_narrow_phase_kernels() -> int:
    """Let every collision pipeline of this process share its narrow-phase kernels; returns
    how many of :data:`NARROW_PHASE_FACTORIES` it now shares.

    Each ``newton.CollisionPipeline`` makes its shape-against-shape kernels afresh: the
    same Warp code from the same arguments (the contact writer, the support function,
    flags), but new kernel objects, which Warp parses again and whose module it hashes and
    loads again at their first launch. A sweep builds a scene for every run, so on the
    scenes with a plane (a pipeline each) that was most of a run's cost. Made once per
    argument set and handed to every pipeline, the kernels are the same code, launched on
    each scene's own arrays: no number changes (tested against scenes built without the
    sharing, bit for bit). A Newton without these functions is left as it is."""
    try:
        from newton._src.geometry import narrow_phase
    except ImportError:
        return 0
    shared = 0
    for name in NARROW_PHASE_FACTORIES:
        make = getattr(narrow_phase, name, None)
        if make is None or not callable(make):
            continue
        if not hasattr(make, "cache_info"):
            setattr(narrow_phase, name, functools.cache(make))
        shared += 1
    return shared


SOLVERS = {
    "semi-implicit": "SolverSemiImplicit",
    "xpbd": "SolverXPBD",
    "vbd": "SolverVBD",
}
"""truestep's method name -> Newton's solver class."""

XPBD_ITERATIONS = 2
"""Constraint iterations per XPBD step: Newton's default."""

VBD_ITERATIONS = 10
"""Block-descent sweeps per VBD step: Newton's default."""

METHOD_FACTS: dict[str, MethodFacts | str] = {
    "semi-implicit": "symplectic-euler",
    "xpbd": MethodFacts.like("implicit-euler", evaluations_per_step=XPBD_ITERATIONS),
    "vbd": MethodFacts.like("implicit-euler", evaluations_per_step=VBD_ITERATIONS),
}
"""What each method is declared to be. semi-implicit is the reference's symplectic Euler.
XPBD and VBD are backward Euler steps solved by a fixed number of sweeps (each counted as
one force evaluation): on one linear spring a sweep solves the step exactly (XPBD's
compliant constraint update and VBD's Newton update are then the backward Euler step), so
they share implicit Euler's facts -- first order, stable at every step -- which the
order fits and stability searches then check on scenes where the sweeps do not converge
(cloth, chains)."""

CAPABILITIES = frozenset(
    {
        Feature.POINT_MASSES,
        Feature.PLANAR,
        Feature.SPATIAL,
        Feature.UNIFORM_GRAVITY,
        Feature.DRAG,
        Feature.SPRINGS,
        Feature.SPRING_DAMPING,
        Feature.ANCHORED_SPRINGS,
        Feature.PLANES,
        Feature.PINNED_PARTICLES,
    }
)

REASONS = {
    Feature.UNIVERSAL_GRAVITATION: "Newton has no force between particle pairs, and truestep adds none",
    Feature.FORCE_FIELDS: "Newton has no force field element, and truestep adds none",
    Feature.IMPULSES: "truestep does not add time-windowed forces to Newton",
    Feature.EMITTERS: "truestep does not spawn particles in Newton",
    Feature.FRICTION: "Newton's particle friction is a regularised slope truestep does not normalise yet",
    Feature.THIN_WALLS: "Newton's planes are half-spaces (nothing tunnels through them)",
}
"""Why each feature Newton lacks here is unsupported (the row's message)."""

PATH = "graph"
"""The ``path`` column of Newton's rows: each step is one launch of a captured Warp graph."""

CPU_NOTE = "Warp CPU device, float32"
"""The note of a row on the CPU device."""


@wp.kernel
def add_drag(v: wp.array[wp.vec3], k: float, f: wp.array[wp.vec3]) -> None:
    """``f[i] -= k v[i]``: viscous drag (N) from velocities (m/s) and ``k`` (N s/m)."""
    i = wp.tid()
    # Warp's stubs type tid() as a launch of any rank, and arrays as read-only.
    f[i] = f[i] - k * v[i]  # type: ignore[index]


def restitution_of(zeta: float) -> float:
    """Restitution of a contact spring damped only while compressed (unit mass).

    The damped half reaches its deepest point ``|r| = (v / omega) exp(-zeta arccos(zeta)
    / sqrt(1 - zeta^2))``, and the undamped release returns ``omega |r|``:
    ``e = exp(-zeta arccos(zeta) / sqrt(1 - zeta^2))``, the square root of
    :func:`truestep.adapters.contact_law.restitution_of`.
    """
    return float(np.sqrt(contact_law.restitution_of(zeta)))


def damping_ratio(e: float) -> float:
    """The damping ratio that gives restitution ``e`` (inverts :func:`restitution_of`)."""
    return contact_law.damping_ratio(e * e)


EXPLICIT_DAMPING = 1.0
"""The most ``kd h / m`` the contact damper is given. ``semi-implicit`` applies it
explicitly: at 1 one step takes the whole approach speed away, and beyond it a step
reverses the speed (at 1.8 a ball asked for e = 0 leaves at 0.9 of it). With a contact
of ``CONTACT_STEPS`` = 10 steps this caps ``zeta`` at 1.59, so the contact law gives at
least e = 0.26, whatever smaller ``e`` is asked (the restitution table shows what each
``e`` gives)."""


def contact_constants(model: ParticleModel, e: float, h: float) -> tuple[float, float]:
    """Penalty stiffness (N/m) and approach damping (N s/m) for restitution ``e`` at step
    ``h`` (s), scaled to the lightest free particle's mass (every contact case's
    particles weigh the same); the damping ratio is capped where an explicit damper would
    overshoot (:data:`EXPLICIT_DAMPING`)."""
    m = float(np.min(model.mass[~model.fixed])) if np.any(~model.fixed) else 1.0
    omega = np.pi / (contact_law.CONTACT_STEPS * h)
    zeta = min(damping_ratio(e), EXPLICIT_DAMPING / (2.0 * omega * h))
    return m * omega**2, 2.0 * zeta * m * omega


UNDERFLOW_LENGTH = 1e-18
"""m. Newton's spring kernels divide by a spring's length, computed in float32 as the
square root of a sum of squares: below about 1e-19 m (the square root of float32's
smallest normal number) the square underflows, the length is 0 and the force NaN."""


def underflowed(model: ParticleModel, traj: Trajectory) -> str:
    """Why a run went non-finite if a spring's length underflowed, else ``""``.

    Reads the last finite record before the first non-finite one: a spring (or anchor)
    shorter than :data:`UNDERFLOW_LENGTH` there, with every position finite and small, is
    Newton's arithmetic failing (a damped spring of rest length 0 decaying onto its
    anchor), not a blow-up. Runs recorded sparsely, whose last finite record may be far
    from the failure, are left as they are."""
    finite = np.isfinite(traj.x).all(axis=(1, 2))
    if finite.all() or not finite[0]:
        return ""
    k = int(np.argmin(finite)) - 1
    if traj.steps and len(traj.t) < traj.steps:
        return ""
    x = traj.x[k]
    lengths = [
        np.linalg.norm(x[model.springs.i] - x[model.springs.j], axis=1),
        np.linalg.norm(x[model.anchors.i] - model.anchors.point, axis=1),
    ]
    shortest = min((float(v.min()) for v in lengths if len(v)), default=np.inf)
    if shortest >= UNDERFLOW_LENGTH:
        return ""
    return (
        f"non-finite after t = {traj.t[k]:.4g} s with a spring {shortest:.2g} m long: Newton divides "
        "by its length, 0 in float32 below ~1e-19 m"
    )


@dataclass
class Scene:
    """A Newton model on a Warp device, its two states, and the step (a graph or a call)."""

    model: Any
    states: tuple[Any, Any]
    run_step: Any
    graph: Any
    n: int
    device: str
    notes: list[str] = field(default_factory=list)
    views: tuple[Any, Any] = (None, None)
    """The first state's ``particle_q`` and ``particle_qd`` as numpy views of the device's
    memory on the CPU, else ``None`` (:func:`truestep.adapters.warp_runtime.host_view`)."""


def _builder(model: ParticleModel) -> Any:
    gx, gy, gz = (float(g) for g in model.gravity)
    builder = newton.ModelBuilder(gravity=(gx, gy, gz))
    for i in range(model.n):
        mass = 0.0 if model.fixed[i] else float(model.mass[i])
        builder.add_particle(tuple(model.x0[i]), tuple(model.v0[i]), mass, radius=float(model.radius[i]))
    springs = model.springs
    pairs = zip(springs.i, springs.j, springs.stiffness, springs.damping, springs.rest, strict=True)
    for i, j, ks, kd, rest in pairs:
        builder.add_spring(int(i), int(j), float(ks), float(kd), 0.0)
        builder.spring_rest_length[-1] = float(rest)
    anchors = model.anchors
    for i, point, ks, kd, rest in zip(
        anchors.i, anchors.point, anchors.stiffness, anchors.damping, anchors.rest, strict=True
    ):
        anchor = builder.add_particle(tuple(point), (0.0, 0.0, 0.0), 0.0, radius=0.0)
        builder.add_spring(int(i), anchor, float(ks), float(kd), 0.0)
        builder.spring_rest_length[-1] = float(rest)
    return builder


def build(case: Case, method: str, dt: float, *, device: str = DEVICE, reuse: bool = False) -> Scene:
    """Build ``case`` for ``method`` at nominal step ``dt`` on ``device`` and capture one step
    (its collision pipeline sharing the process's narrow-phase kernels:
    :func:`share_narrow_phase_kernels`).

    ``reuse`` (the adapter's runs, one scene at a time): a scene of the same particles,
    method, step and device as the last one built so in this process (a row's warm-up,
    measured and timed runs) is that scene again, every Warp array of its states, solver
    and collision pipeline put back as built (:func:`_again`): its captured graph then
    steps what a scene built afresh steps (tested bit for bit), without the model's
    ``finalize``, the solver's set-up and the capture, 5-20 ms a run on the CPU."""
    start()
    share_narrow_phase_kernels()
    model = case.particles
    h = case.steps_for(dt)[1]
    key = (pickle.dumps(model, protocol=pickle.HIGHEST_PROTOCOL), method, h, device)
    if reuse and _LAST.get("key") == key:
        return _again(_LAST["scene"], _LAST["arrays"], _LAST["built"])
    builder = _builder(model)
    ke, kd = (0.0, 0.0)
    e = model.planes[0].restitution if model.planes else 1.0
    if model.planes:
        ke, kd = contact_constants(model, e, h)
        config = newton.ModelBuilder.ShapeConfig(ke=ke, kd=kd, mu=0.0, restitution=e)
        for plane in model.planes:
            normal = np.asarray(plane.normal, float)
            d = -float(normal @ np.asarray(plane.point, float))
            builder.add_shape_plane(plane=(*map(float, normal), d), width=0.0, length=0.0, cfg=config)
    if method == "vbd":
        builder.color()
    with wp.ScopedDevice(device):
        sim = builder.finalize(device=device)
    sim.particle_max_velocity = float("inf")
    sim.particle_grid, sim.particle_max_radius = None, 0.0
    sim.soft_contact_ke, sim.soft_contact_kd, sim.soft_contact_mu = ke, kd, 0.0
    sim.soft_contact_restitution = e
    solver = _solver(sim, method)
    states = (sim.state(), sim.state())
    pipeline = contacts = None
    if model.planes:
        pipeline = newton.CollisionPipeline(
            sim, soft_contact_max=max(model.n * len(model.planes), 1), soft_contact_gap=1e4
        )
        contacts = pipeline.contacts()
    s0, s1 = states
    drag, n_all = float(model.drag), sim.particle_count

    def run_step() -> None:
        s0.clear_forces()
        if drag:
            wp.launch(add_drag, dim=n_all, inputs=[s0.particle_qd, drag], outputs=[s0.particle_f])
        if pipeline is not None and contacts is not None:
            pipeline.collide(s0, contacts)
        solver.step(s0, s1, None, contacts, h)
        wp.copy(s0.particle_q, s1.particle_q)
        wp.copy(s0.particle_qd, s1.particle_qd)

    with wp.ScopedDevice(device):
        run_step()  # compiles the kernels (Warp caches them on disk) before the capture
        with wp.ScopedCapture(device=device) as capture:
            run_step()
    _reset(sim, s0, s1)
    views = (host_view(s0.particle_q), host_view(s0.particle_qd))
    scene = Scene(sim, states, run_step, capture.graph, model.n, device, views=views)
    if reuse:
        arrays = warp_arrays((s0, s1, solver, pipeline, contacts))
        _LAST.clear()
        _LAST.update(key=key, scene=scene, arrays=arrays, built=[wp.clone(a) for a in arrays])
    return scene


_LAST: dict[str, Any] = {}
"""The last scene :func:`build` made with ``reuse`` in this process: its key (the particle
model's bytes, the method, the step, the device), the scene, and every Warp array its step
reaches with a copy of each as built."""


def warp_arrays(roots: tuple[Any, ...]) -> list[Any]:
    """Every Warp array reachable from ``roots`` through the attributes of the objects that
    hold a scene's data (:func:`_holds_data`) and the lists, tuples and dicts they hold (the
    model's included), each once, in the order first met."""
    found: dict[int, Any] = {}
    seen: set[int] = set()
    stack = list(reversed(roots))
    while stack:
        obj = stack.pop()
        if obj is None or id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, wp.array):
            found.setdefault(id(obj), obj)
        elif isinstance(obj, list | tuple):
            stack.extend(reversed(obj))
        elif isinstance(obj, dict):
            stack.extend(reversed(list(obj.values())))
        elif _holds_data(obj) and hasattr(obj, "__dict__"):
            stack.extend(reversed(list(vars(obj).values())))
    return list(found.values())


def _holds_data(obj: Any) -> bool:
    """Whether :func:`warp_arrays` looks inside ``obj``: Newton's objects, Warp's struct
    instances and Warp's data types (``warp.types``: BVHs, meshes, grids); not Warp's code
    and runtime (kernels, functions and their compiled forms, modules, devices), which hold
    no array of a scene: walking them took 20-50 ms a scene built (the same arrays found,
    in the same order, on every case and solver: tested)."""
    module = type(obj).__module__
    return (
        module.split(".")[0] == "newton"
        or wp.types.is_struct(obj)
        or module in ("warp.types", "warp._src.types")
    )


def _again(scene: Scene, arrays: list[Any], built: list[Any]) -> Scene:
    """``scene`` with every array of its step copied back from ``built`` (what :func:`build`
    left): a run from it steps what a run from a scene built afresh steps."""
    for array, saved in zip(arrays, built, strict=True):
        wp.copy(array, saved)
    return scene


def _reset(sim: Any, s0: Any, s1: Any) -> None:
    """Put both states back at the model's initial positions and velocities."""
    for state in (s0, s1):
        wp.copy(state.particle_q, sim.particle_q)
        wp.copy(state.particle_qd, sim.particle_qd)


def _solver(sim: Any, method: str) -> Any:
    cls = getattr(newton.solvers, SOLVERS[method])
    if method == "xpbd":
        return cls(sim, iterations=XPBD_ITERATIONS, enable_restitution=True)
    if method == "vbd":
        return cls(sim, iterations=VBD_ITERATIONS)
    return cls(sim)


class NewtonAdapter(WarpAdapter):
    """Newton's particle solvers on particle scenes (see the module docstring).

    Parameters
    ----------
    device : str
        Warp device to run on (``"cpu"``, ``"cuda:0"``, ...). Default: the CPU.
    """

    name = "newton"
    methods = tuple(SOLVERS)
    cpu_note: ClassVar[str] = CPU_NOTE
    kernel_package: ClassVar[str] = "newton"
    method_notes: ClassVar = {
        "semi-implicit": "Newton's SolverSemiImplicit: symplectic Euler, penalty contact (float32)",
        "xpbd": f"Newton's SolverXPBD: position-based, {XPBD_ITERATIONS} iterations a step (float32)",
        "vbd": f"Newton's SolverVBD: vertex block descent, {VBD_ITERATIONS} sweeps a step (float32)",
    }
    """One line per method, for the report's glossary."""
    method_facts: ClassVar = METHOD_FACTS
    peers: ClassVar[dict[str, str]] = {
        "semi-implicit": "symplectic-euler",
        "xpbd": "implicit-euler",
        "vbd": "implicit-euler",
    }
    """The reference method each names as its scheme (compared in the report)."""
    unsupported_notes: ClassVar[dict[Feature, str]] = REASONS
    capabilities = CAPABILITIES

    @staticmethod
    def warm(cases: list[Case], *, say: Any = print) -> int:
        """``truestep compile``'s hook: this module's :func:`warm`."""
        return warm(cases, say=say)

    def build(self, case: Case, method: str, h: float) -> Scene:
        """The run's scene (:func:`build`, the last one again where only the run's length differs)."""
        return build(case, method, h, device=self.device, reuse=True)

    def read(self, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities (n, 3), float64 copies of the float32 state."""
        state = scene.states[0]
        n = scene.n
        return state.particle_q.numpy()[:n].astype(float), state.particle_qd.numpy()[:n].astype(float)

    def snapshot(self, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
        """The float32 state now (host copies of the device arrays)."""
        state, (q, qd), n = scene.states[0], scene.views, scene.n
        return host_copy(state.particle_q, q, n), host_copy(state.particle_qd, qd, n)

    def unpack(self, scene: Scene, snaps: list[Any]) -> tuple[np.ndarray, np.ndarray]:
        return (
            np.stack([s[0] for s in snaps]).astype(float),
            np.stack([s[1] for s in snaps]).astype(float),
        )

    def simulate(self, case: Case, method: str, dt: float, *, monitor: bool = False) -> Trajectory:
        """The fixed-step run (:meth:`FixedStepAdapter.simulate`); its ``path`` is ``graph``
        (one captured step, launched per step). A run that turned non-finite right after a
        spring's length fell below :data:`UNDERFLOW_LENGTH` is ``solver-failed``, not
        ``unstable`` (:func:`underflowed`)."""
        traj = super().simulate(case, method, dt, monitor=monitor)
        traj.path = PATH
        if traj.status == "unstable" and case.model is not None:
            why = underflowed(case.particles, traj)
            if why:
                traj.status, traj.message = "solver-failed", "; ".join([why, traj.message])
        return traj

    def notes(self, case: Case, method: str, scene: Scene) -> list[str]:
        return [self.device_note(scene), "one captured Warp graph per step", *scene.notes]


def warm(cases: list[Case], *, say: Any = print) -> int:
    """Build one scene per method for each kind of scene Newton runs, so that Warp compiles
    the kernels into its on-disk cache (a build step). Returns the scenes built."""
    adapter = NewtonAdapter()
    built = 0
    for case in cases:
        for method in adapter.methods:
            if case.model is None or adapter.missing(case, method):
                continue
            began = time.perf_counter()
            build(case, method, case.sweep(adaptive=False, quick=True)[0])
            built += 1
            say(f"newton kernels: {case.name} {method} ({time.perf_counter() - began:.1f} s)")
    return built
