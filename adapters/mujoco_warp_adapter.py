"""MuJoCo Warp behind the Adapter protocol (``pip install "truestep[mujoco-warp]"``).

What runs
---------
MuJoCo Warp (``mujoco_warp``) is MuJoCo's pipeline rewritten as Warp kernels, built for
batches of worlds on a GPU. truestep runs it as a **correctness peer of MuJoCo C**: the
same MJCF model (:func:`truestep.adapters.mujoco_adapter.mjcf`, so the same slide
joints, tendons, contact pairs and the restitution-derived ``solref``), the same four
integrators, one world, stepped by Warp's kernels in float32 on Warp's CPU device
(:data:`DEVICE`) unless a device is asked. Its rows say whether the GPU pipeline computes
MuJoCo's physics; its CPU wall times are those of a GPU code run on a CPU (far slower
than MuJoCo C's), not a speed claim, and the row's message says so.

What truestep sets
------------------
* The model is MuJoCo C's, less ``autoreset="disable"`` (MuJoCo Warp has no autoreset:
  it never resets a diverged state, so the flag is not needed), and without MuJoCo's
  energy and sensor stages (``energy`` off, ``sensor="disable"``: nothing reads them
  here, and MuJoCo Warp launches their kernels at every step, about 10% of a cloth's
  launches; the steps are the same bits, tested).
* Contact capacity: one contact per (particle, plane) pair and the constraint rows they
  need (``condim`` rows each), so no contact is ever dropped for want of room (MuJoCo
  Warp drops contacts beyond its capacity, with only a printed warning).
* Stepping is a captured Warp graph of one ``mujoco_warp.step``, made in :meth:`build`
  (outside the timed region; the kernels compile there on first use and are cached on
  disk by Warp) and launched once per step: the same kernels, without Python's dispatch
  of some hundred launches a step. A test checks that the graph's steps equal plain
  ``step`` calls bit for bit.
* Nothing else: no clamp, no extra damping, the model's solver settings as MuJoCo C has
  them.

What it cannot run
------------------
MuJoCo Warp has no passive-force callback, so universal gravitation, force fields and
impulses (which the MuJoCo adapter adds through ``mjcb_passive``) are ``unsupported``
rows with that reason, as are 2-D and 3-D features MuJoCo itself lacks.

Precision
---------
The state is float32 (:data:`PRECISION`): positions carry about 7 significant digits, so
errors stall between 1e-6 and 1e-4 of a scene's size however small the step (more steps,
more rounding). The order fits and the
baselines judge this engine against what float32 can reach
(:func:`truestep.measures.metrics.round_off_floor`).
"""

from __future__ import annotations

import dataclasses
import functools
import time
from dataclasses import dataclass, field
from typing import Any, ClassVar

import mujoco
import numpy as np

from truestep.adapters import mujoco_adapter as mj
from truestep.adapters.base import FactsSpec
from truestep.adapters.quiet import without_banner
from truestep.adapters.warp_runtime import BANNER, DEVICE, WarpAdapter, host_copy, host_view, start, wp
from truestep.cases.case import Case
from truestep.reference_impl.features import Feature

with without_banner(BANNER):
    import mujoco_warp as mjw


def remember_versions() -> bool:
    """Let MuJoCo Warp look each package version up once per process; returns whether it
    now does.

    ``put_model`` and ``put_data`` ask ``util_pkg.check_version("mujoco>=...")`` several
    times a scene, and each asks ``importlib.metadata`` afresh (a scan of the installed
    distributions and a parse of one's metadata), at every scene a sweep or a stability
    search builds. The installed versions do not change while a process runs, so the
    answer to each question is kept. A MuJoCo Warp without that function is left as it
    is."""
    try:
        from mujoco_warp._src import util_pkg
    except ImportError:
        return False
    check = getattr(util_pkg, "check_version", None)
    if check is None or not callable(check):
        return False
    if not hasattr(check, "cache_info"):
        util_pkg.check_version = functools.cache(check)
    return True


APPLIED = (Feature.UNIVERSAL_GRAVITATION, Feature.FORCE_FIELDS, Feature.IMPULSES)
"""Features the MuJoCo adapter adds through MuJoCo C's passive-force callback."""

CAPABILITIES = mj.MujocoAdapter.capabilities - frozenset(APPLIED)

MAX_CPU_PARTICLES = 500
"""The most particles a scene may have for a run on the CPU device. Warp's CPU device
runs each kernel's threads one after another, and MuJoCo Warp's constraint solver is
written for a GPU's thousands of threads: a step of particle-rain's 1000 particles costs
orders of magnitude more than MuJoCo C's, far too long for a sweep. Larger scenes are
``skipped`` rows that say so; on a GPU (``device="cuda:0"``) there is no bound."""

CPU_NOTE = "Warp CPU device, float32: a correctness peer of MuJoCo C; its wall time is no speed claim"
"""The note every row on the CPU device carries."""


@dataclass
class Scene:
    """A compiled case on a Warp device: MuJoCo's host model, the device model and data,
    the particle layout and the captured one-step graph."""

    host: mujoco.MjModel
    model: Any
    data: Any
    layout: mj.Layout
    graph: Any
    pinned_x: np.ndarray
    """Positions of the pinned particles (site_xpos from MuJoCo C), shape (n_pin, 3), m."""
    n: int
    device: str
    notes: list[str] = field(default_factory=list)
    views: tuple[Any, Any] = (None, None)
    """``qpos`` and ``qvel`` as numpy views of the device's memory on the CPU, else ``None``
    (:func:`truestep.adapters.warp_runtime.host_view`)."""


def capacity(host: mujoco.MjModel) -> tuple[int, int]:
    """Contacts and constraint rows the scene can need at once: one contact per explicit
    pair (a particle touches a plane at one point), ``condim`` rows each (an elliptic
    cone's rows), at least one of each (MuJoCo Warp allocates no empty arrays; and with
    ``njmax = 0`` MuJoCo Warp 4.0.0 skips its solver for ``qacc_smooth``, a path that
    steps otherwise: a spring chain 1.29 m from MuJoCo C after 500 Euler steps of 0.7 ms,
    against 2e-7 m with ``njmax = 1``, measured 2026-12-07)."""
    pairs = int(host.npair)
    rows = int(np.sum(host.pair_dim)) if pairs else 0
    return max(pairs, 1), max(rows, 1)


def build(case: Case, method: str, dt: float, *, device: str = DEVICE, reuse: bool = False) -> Scene:
    """Compile ``case`` for ``method`` at nominal step ``dt`` on ``device`` and capture one step.

    ``reuse`` (the adapter's runs, one scene at a time): a scene whose model differs from
    the last one built so in this process by its time step alone (the same MJCF but for
    ``timestep``, the same start: a sweep's or a stability search's runs of a scene
    without contact) is that scene again, its device model's step set and its device data
    put back as built (:func:`_again`): the same arrays, so the scene built before is
    that one, reset. It steps the same bits as a scene built afresh, without MuJoCo
    Warp's ``put_model`` and the graph capture, a cost at every run on the CPU device. A
    scene with plane contacts has its step in the contacts' ``solref`` too, so it is
    built afresh at every step. MuJoCo Warp's version checks are answered once per process
    (:func:`remember_versions`)."""
    start()
    remember_versions()
    model = case.particles
    h = case.steps_for(dt)[1]
    xml, layout = mj.mjcf(model, method, h, autoreset_flag=False, energy=False, sensors=False)
    host = mujoco.MjModel.from_xml_string(xml)
    hd = mujoco.MjData(host)
    hd.qpos[:] = model.x0[layout.free, : layout.dim].ravel()
    hd.qvel[:] = model.v0[layout.free, : layout.dim].ravel()
    mujoco.mj_forward(host, hd)
    pinned_x = np.array([hd.site(s).xpos for s in layout.pinned_sites]).reshape(-1, 3)
    key = (xml.replace(f'timestep="{h:.17g}"', 'timestep=""'), hd.qpos.tobytes(), hd.qvel.tobytes(), device)
    if reuse and _LAST.get("key") == key:
        return _again(_LAST["scene"], _LAST["built"], host, layout, pinned_x)
    contacts, rows = capacity(host)
    with wp.ScopedDevice(device):
        m = mjw.put_model(host)
        d = mjw.put_data(host, hd, naconmax=contacts, njmax=rows)
        built = [wp.clone(a) for a in _arrays(d)] if reuse else []
        with wp.ScopedCapture(device=device) as capture:
            mjw.step(m, d)
    views = (host_view(d.qpos), host_view(d.qvel))
    scene = Scene(host, m, d, layout, capture.graph, pinned_x, model.n, device, list(layout.notes), views)
    if reuse:
        _LAST.clear()
        _LAST.update(key=key, scene=scene, built=built)
    return scene


_LAST: dict[str, Any] = {}
"""The last scene :func:`build` made in this process: its key (the MJCF without its time
step, the start state, the device), the scene, and its device data's arrays as built."""


def _arrays(data: Any) -> list[Any]:
    """Every Warp array of MuJoCo Warp's ``Data`` (its nested parts included), in field order."""
    out = []
    for f in dataclasses.fields(data):
        value = getattr(data, f.name)
        if isinstance(value, wp.array):
            out.append(value)
        elif dataclasses.is_dataclass(value):
            out.extend(_arrays(value))
    return out


def _again(scene: Scene, built: list[Any], host: mujoco.MjModel, layout: mj.Layout, pinned_x) -> Scene:
    """``scene`` at ``host``'s time step (set as ``put_model`` sets it: float32), its data's
    arrays copied back from ``built`` (what ``put_data`` made), its captured graph kept: a
    run from it steps what a scene built afresh steps (tested bit for bit)."""
    scene.model.opt.timestep.fill_(float(np.float32(host.opt.timestep)))
    for array, saved in zip(_arrays(scene.data), built, strict=True):
        wp.copy(array, saved)
    return dataclasses.replace(scene, host=host, layout=layout, pinned_x=pinned_x, notes=list(layout.notes))


class MujocoWarpAdapter(WarpAdapter):
    """MuJoCo Warp's four integrators on particle scenes (see the module docstring).

    Parameters
    ----------
    device : str
        Warp device to run on (``"cpu"``, ``"cuda:0"``, ...). Default :data:`DEVICE`.
    """

    name = "mujoco-warp"
    methods = tuple(mj.INTEGRATORS)
    cpu_note: ClassVar[str] = CPU_NOTE
    kernel_package: ClassVar[str] = "mujoco_warp"
    correctness_peer_of: ClassVar[str] = "mujoco"
    """The engine whose physics this one reimplements (compared in the tests, not timed)."""
    method_notes: ClassVar = {
        "Euler": "MuJoCo Warp's semi-implicit Euler (float32)",
        "implicit": "MuJoCo Warp's implicit-in-velocity Euler (float32)",
        "implicitfast": "MuJoCo Warp's implicit Euler without Coriolis derivatives (float32)",
        "RK4": "MuJoCo Warp's classical Runge-Kutta 4 (float32)",
    }
    """One line per method, for the report's glossary."""
    method_facts: ClassVar[dict[str, FactsSpec]] = mj.METHOD_FACTS
    peers: ClassVar[dict[str, str]] = {"Euler": "symplectic-euler", "RK4": "rk4"}
    """The reference method each names as its scheme (compared in the report)."""
    unsupported_notes: ClassVar[dict[Feature, str]] = {
        feature: "MuJoCo Warp has no passive-force callback, through which truestep adds this force to MuJoCo"
        for feature in APPLIED
    }
    capabilities = CAPABILITIES

    @staticmethod
    def warm(cases: list[Case], *, say: Any = print) -> int:
        """``truestep compile``'s hook: this module's :func:`warm`."""
        return warm(cases, say=say)

    @property
    def speed_claim(self) -> bool:
        """On Warp's CPU device a row's wall time is no speed claim (:data:`CPU_NOTE`): its
        rows run once, untimed (:func:`truestep.execution.runner.makes_speed_claim`)."""
        return self.device != "cpu"

    def skip(self, case: Case, method: str) -> str | None:
        """Why a scene is left unrun: over :data:`MAX_CPU_PARTICLES` particles on the CPU."""
        n = case.particles.n if case.model is not None else 0
        if self.device == "cpu" and n > MAX_CPU_PARTICLES:
            return (
                f"{n} particles: over the {MAX_CPU_PARTICLES} MuJoCo Warp runs on the CPU device "
                "(a GPU pipeline stepping one thread at a time; run it with device='cuda:0')"
            )
        return None

    def build(self, case: Case, method: str, h: float) -> Scene:
        """The run's scene (:func:`build`, reusing the last one where only its step differs)."""
        return build(case, method, h, device=self.device, reuse=True)

    def same_steps(self, case: Case, method: str) -> tuple[str, str] | None:
        """The method whose steps ``method`` repeats bit for bit: MuJoCo's rule
        (:func:`truestep.adapters.mujoco_adapter.same_steps`), which holds here too (tested)."""
        return mj.same_steps(case, method)

    def read(self, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities (n, 3), float64 copies of the device's float32 state."""
        lay = scene.layout
        x, v = np.zeros((scene.n, 3)), np.zeros((scene.n, 3))
        x[lay.free, : lay.dim] = scene.data.qpos.numpy().reshape(-1, lay.dim)
        x[lay.pinned] = scene.pinned_x
        v[lay.free, : lay.dim] = scene.data.qvel.numpy().reshape(-1, lay.dim)
        return x, v

    def snapshot(self, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
        """The float32 state now (the device arrays' host copies)."""
        (qpos, qvel), data = scene.views, scene.data
        return host_copy(data.qpos, qpos), host_copy(data.qvel, qvel)

    def unpack(self, scene: Scene, snaps: list[Any]) -> tuple[np.ndarray, np.ndarray]:
        lay, t = scene.layout, len(snaps)
        x, v = np.zeros((t, scene.n, 3)), np.zeros((t, scene.n, 3))
        x[:, lay.free, : lay.dim] = np.stack([s[0] for s in snaps]).reshape(t, -1, lay.dim)
        x[:, lay.pinned] = scene.pinned_x
        v[:, lay.free, : lay.dim] = np.stack([s[1] for s in snaps]).reshape(t, -1, lay.dim)
        return x, v

    def notes(self, case: Case, method: str, scene: Scene) -> list[str]:
        return [
            f"{mj.EVALUATIONS_PER_STEP[method]} force evaluation(s) per step",
            self.device_note(scene),
            *scene.notes,
        ]


def warm(cases: list[Case], *, say: Any = print) -> int:
    """Build every scene of ``cases`` MuJoCo Warp runs on the CPU, with every method: Warp
    compiles the kernels each needs into its on-disk cache (a build step; a later run only
    loads them). Returns the scenes built."""
    adapter = MujocoWarpAdapter()
    built = 0
    for case in cases:
        for method in adapter.methods:
            if case.model is None or adapter.missing(case, method) or adapter.skip(case, method):
                continue
            began = time.perf_counter()
            build(case, method, case.sweep(adaptive=False, quick=True)[0])
            built += 1
            say(f"mujoco-warp kernels: {case.name} {method} ({time.perf_counter() - began:.1f} s)")
    return built
