"""The reference's independent particles on a Warp device (a GPU, or Warp's CPU device).

One thread per particle takes it through every step of a run, its state held in registers
(the GPU twin of the compiled path's temporal blocking, :mod:`~truestep.reference_impl.tiles`):
the lecture's update or symplectic Euler (a kick and drift, :class:`~truestep.reference_impl.
solvers.splitting_kernels.KickDrift`) under uniform gravity and viscous drag, then the
collision and contact pass of :class:`~truestep.reference_impl.collisions.PlaneCollisions`
against the scene's planes (restitution, Coulomb friction, thin walls). Those are the
formulas of the compiled path's fused layout (:func:`~truestep.reference_impl.tiles.fused_step`,
:func:`~truestep.reference_impl.collisions_kernels.collide`), term for term and in its
order, in float64; the numpy system (:mod:`~truestep.reference_impl.particles`) stays the
spec, and the tests hold this kernel to the compiled path's records bit for bit on Warp's
CPU device (compiled for a generic target, :func:`truestep.numerics.configure_warp`, and
without floating-point contraction on any device, :mod:`~truestep.reference_impl.warp_kernels`),
so that a GPU run can give the same bits; whether it does is measured where a GPU is
(``benchmarks/gpu_checks.py``).

Modelled, and nothing else (:func:`device_reason` names what a scene needs beyond it): a
scene whose particles do not act on one another (no springs, anchors, gravitation,
force fields, impulses, emitters or pinned particles), up to :data:`MAX_PLANES` planes,
methods :data:`KICK_DRIFT`. A particle that runs away (non-finite, or beyond
:data:`~truestep.reference_impl.integrate.BLOWUP` at a check every
:data:`~truestep.reference_impl.integrate.CHECK_EVERY` steps) stops its thread and says at
which step; the caller then makes the run again on the CPU, whose records and stop are the
run's (:func:`run`).
"""

import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from truestep.reference_impl.integrate import record_indices
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.warp_kernels import steps

KICK_DRIFT: dict[str, tuple[float, float]] = {"lecture": (0.5, 0.5), "symplectic-euler": (0.0, 1.0)}
"""The methods the kernel steps, with the weights of their drift ``x' = x + h (old v + new v')``
(:class:`~truestep.reference_impl.solvers.splitting.LectureUpdate`,
:class:`~truestep.reference_impl.solvers.splitting.SymplecticEuler`)."""

MAX_PLANES = 30
"""The most planes a scene may have here: a particle's contacts are the bits of an int32."""


def device_reason(model: ParticleModel | None, method: str) -> str | None:
    """Why the kernel cannot run ``method`` on ``model``, or ``None`` if it can."""
    if model is None:
        return "an ODE case: the device kernel steps particles"
    if method not in KICK_DRIFT:
        return f"{method}: the device kernel steps {' and '.join(KICK_DRIFT)} only"
    needs = [
        words
        for present, words in (
            (len(model.springs), "springs"),
            (len(model.anchors), "anchored springs"),
            (model.gravitation is not None, "gravitation"),
            (model.fields, "force fields"),
            (model.impulses, "impulses"),
            (model.emitters, "emitters"),
            (np.any(model.fixed), "pinned particles"),
            (len(model.planes) > MAX_PLANES, f"more than {MAX_PLANES} planes"),
        )
        if present
    ]
    return f"{', '.join(needs)}: the device kernel steps independent particles" if needs else None


@dataclass
class DeviceRun:
    """A run on a Warp device: records ``t`` (T,) s, ``x``, ``v`` (T, n, 3) m and m/s, the
    stepping's wall time (s: the kernel launched and waited for, nothing copied), ``steps``
    and ``nfev``; ``blew_up``: the first step at which a particle's check failed (the run
    is then to be made on the CPU), else ``None``."""

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    steps: int
    nfev: int
    wall_s: float
    blew_up: int | None


def run(
    model: ParticleModel, method: str, h: float, n_steps: int, *, device: str, max_records: int = 2000
) -> DeviceRun:
    """``model`` through ``n_steps`` steps of ``h`` s of ``method`` on the Warp ``device``
    (``cpu``, ``cuda:N``), recording the steps :func:`record_indices` picks. Everything is
    allocated and copied to the device before the timed launch, and the records copied
    back after it. Raises ``ValueError`` for a scene or method the kernel does not model
    (:func:`device_reason`)."""
    why = device_reason(model, method)
    if why is not None:
        raise ValueError(why)
    n = model.n
    marks = record_indices(n_steps, max_records)
    record = np.zeros(n_steps + 1, dtype=np.int32)
    record[marks] = 1
    fixed = np.asarray(model.fixed, dtype=bool)
    mass = np.ascontiguousarray(model.mass, dtype=np.float64)
    planes = model.planes

    def on(a: Any, dtype: Any = wp.float64) -> Any:
        return wp.array(a, dtype=dtype, device=device)

    vectors = [np.asarray(p.point, float) for p in planes], [np.asarray(p.normal, float) for p in planes]
    xs, vs = on(np.full((len(marks), n, 3), np.nan)), on(np.full((len(marks), n, 3), np.nan))
    bad = on(np.zeros(n, np.int32), wp.int32)
    args = [
        on(np.asarray(model.x0, float).reshape(n, 3)),
        on(np.asarray(model.v0, float).reshape(n, 3)),
        on(mass),
        on(np.where(fixed, 0.0, 1.0 / mass)),
        on(np.ascontiguousarray(model.radius, dtype=np.float64)),
        wp.vec3d(*(float(c) for c in model.gravity)),
        wp.float64(float(model.drag)),
        int(bool(np.any(model.gravity != 0))),
        int(bool(model.drag)),
        wp.float64(KICK_DRIFT[method][0]),
        wp.float64(KICK_DRIFT[method][1]),
        on(np.array(vectors[0]).reshape(-1, 3), wp.vec3d),
        on(np.array(vectors[1]).reshape(-1, 3), wp.vec3d),
        on(np.array([p.restitution for p in planes], float)),
        on(np.array([p.friction for p in planes], float)),
        on(np.array([p.thickness for p in planes], float)),
        wp.float64(h),
        int(n_steps),
        on(record, wp.int32),
        xs,
        vs,
        bad,
    ]
    wp.load_module(sys.modules[steps.__module__], device=device)  # compiled or loaded, not timed
    wp.synchronize_device(device)
    start = time.perf_counter()
    wp.launch(steps, dim=n, inputs=args, device=device)
    wp.synchronize_device(device)
    wall = time.perf_counter() - start
    t_all = np.empty(n_steps + 1)
    t = 0.0
    for i in range(n_steps + 1):  # the driver's time, t = t + h at every step
        t_all[i] = t
        t += h
    blew = bad.numpy()
    blew = blew[blew > 0]
    # a kick and drift evaluates the force once a step
    return DeviceRun(
        t_all[marks], xs.numpy(), vs.numpy(), n_steps, n_steps, wall, int(blew.min()) if len(blew) else None
    )


__all__ = ["KICK_DRIFT", "DeviceRun", "device_reason", "run"]
