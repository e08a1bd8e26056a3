"""Pure functions from a trajectory and its reference to numbers."""

from __future__ import annotations

import numpy as np

from truestep.adapters.base import Trajectory
from truestep.cases.case import Case, OdeSpec, ode_states
from truestep.cases.exact import Exact, exact_named
from truestep.reference_impl.features import Feature
from truestep.reference_impl.model import ParticleModel

_EXACT_CACHE: dict[tuple[int, bytes], tuple[Case, Exact]] = {}
_EXACT_CACHE_SIZE = 32
_EXACT_CACHE_BYTES = 2**30
"""The most bytes of exact paths kept (the newest is kept whatever its size): a million
balls' path at 21 records is 1 GB, and engines' record times differ in their last bits
(``k h`` or an accumulated ``t += h``), so a large scene's sweep asks for several."""


def exact_for(case: Case, t: np.ndarray) -> Exact | None:
    """The case's exact solution at times ``t`` (s), or ``None`` if it has none.

    Rows of one case at the same step share their record times: the solution is kept for
    the last few (case object, times) pairs asked (the entry holds the case, so its id
    cannot be reused while cached).
    """
    if case.exact is None:
        return None
    key = (id(case), np.asarray(t, float).tobytes())
    hit = _EXACT_CACHE.get(key)
    if hit is not None and hit[0] is case:
        return hit[1]
    solution = exact_named(case.exact) if case.exact is not None else None
    if solution is None:
        raise ValueError(f"{case.name}: no exact solution named {case.exact!r}")
    exact = solution(case, t)
    _EXACT_CACHE[key] = (case, exact)
    while len(_EXACT_CACHE) > 1 and (
        len(_EXACT_CACHE) > _EXACT_CACHE_SIZE
        or sum(_bytes(e) for _, e in _EXACT_CACHE.values()) > _EXACT_CACHE_BYTES
    ):
        _EXACT_CACHE.pop(next(iter(_EXACT_CACHE)))
    return exact


def _bytes(exact: Exact) -> int:
    """The bytes of an exact path's arrays."""
    arrays = (exact.t, exact.x, exact.v, exact.energy, exact.y)
    return sum(a.nbytes for a in arrays if isinstance(a, np.ndarray))


def _matching(t: np.ndarray, t_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices into ``t`` and ``t_ref`` of times both contain (to 1e-9 relative)."""
    if len(t_ref) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    k = np.clip(np.searchsorted(t, t_ref), 0, len(t) - 1)
    k_lo = np.clip(k - 1, 0, len(t) - 1)
    k = np.where(np.abs(t[k_lo] - t_ref) < np.abs(t[k] - t_ref), k_lo, k)
    ok = np.abs(t[k] - t_ref) <= 1e-9 * np.maximum(1.0, np.abs(t_ref))
    return k[ok], np.nonzero(ok)[0]


def _parts(case: Case, traj: Trajectory, exact: Exact, part: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The run's and the exact solution's positions (``part = "x"``) or velocities
    (``"v"``) at their shared times: particles (K, n, 3); an ODE's states (K, dim), of
    which a second-order system's half (its positions or its velocities) is kept, a
    first-order system's whole (its state is its position; it has no velocity)."""
    k, j = _matching(traj.t, exact.t)
    if len(k) == 0:
        return None
    match case.scene:
        case OdeSpec() as ode:
            mine, theirs = ode_states(traj)[k], ode_states(exact)[j]
            if ode.is_second_order:
                half = mine.shape[-1] // 2
                cut = slice(0, half) if part == "x" else slice(half, None)
                return mine[:, cut], theirs[:, cut]
            return (mine, theirs) if part == "x" else None
        case ParticleModel():
            if part == "x":
                return traj.x[k], exact.x[j]
            if traj.v is None or exact.v is None:
                return None
            return traj.v[k], exact.v[j]


def position_error(
    case: Case, traj: Trajectory, exact: Exact, *, norm: str | None = None, part: str = "x"
) -> float:
    """Distance between computed and exact positions, m (or state units for an ODE).

    ``norm`` (default the case's ``error_norm``): ``max``, the largest over every shared
    time (the worst of the run); ``final``, at the last time both share (which must be
    the end of the run). Per record, the largest distance over particles (Euclidean; for
    an ODE, the largest component of its positions: the first half of a second-order
    system's state, a first-order system's whole state). ``part = "v"``: velocities
    instead (m/s; NaN where the exact solution gives none). Particles that are not alive
    in the run, or whose exact position is not known (NaN: not alive in a reference
    run), are not compared.
    """
    pair = _parts(case, traj, exact, part)
    if pair is None:
        return float("nan")
    mine, theirs = pair
    k, _ = _matching(traj.t, exact.t)
    d = mine - theirs
    particles = isinstance(case.scene, ParticleModel)
    if particles and traj.alive is not None:
        d = np.where(traj.alive[k][..., None], d, np.nan)
    d = np.where(np.isnan(theirs), 0.0, np.nan_to_num(d, nan=0.0)) if np.isnan(d).any() else d
    per_record = np.max(np.linalg.norm(d, axis=2), axis=1) if particles else np.max(np.abs(d), axis=1)
    if (norm or case.error_norm) == "final":
        if abs(traj.t[k[-1]] - case.duration) > 1e-9 * max(1.0, case.duration):
            return float("nan")
        return float(per_record[-1])
    return float(np.max(per_record))


def energy_drift(
    case: Case, traj: Trajectory, exact: Exact | None, *, scale: float | None = None
) -> tuple[float, float]:
    """Energy error over the case's energy scale: (largest over the run, at the end).

    ``S`` is the case's energy scale (:func:`truestep.measures.energy_scale.energy_scale`: the
    energy the motion exchanges, the same wherever the potential's zero lies).
    Conservative scenes: ``|E(t) - E(0)| / S``, over every step where the run was watched
    at every step (``traj.extremes``), else over the records. Scenes whose exact solution
    gives the energy curve (damped oscillators): ``|E(t) - E_exact(t)| / S`` at the
    records. Otherwise NaN. ``scale`` overrides the case's (J).
    """
    from truestep.measures.energy_scale import energy_scale

    e = traj.energy
    if e is None or len(e) == 0:
        return float("nan"), float("nan")
    scale = energy_scale(case) if scale is None else scale
    if not np.isfinite(scale):
        return float("nan"), float("nan")
    if case.conservative:
        dev = np.abs(e - e[0]) / scale
        worst = float(np.max(dev))
        top = traj.extremes
        if top is not None:
            worst = max(worst, abs(top.e_max - e[0]) / scale, abs(top.e_min - e[0]) / scale)
        return worst, float(dev[-1])
    if exact is not None and exact.energy is not None and len(exact.t) == len(exact.energy):
        k, j = _matching(traj.t, exact.t)
        if len(k) == 0:
            return float("nan"), float("nan")
        dev = np.abs(e[k] - exact.energy[j]) / scale
        return float(np.max(dev)), float(dev[-1])
    return float("nan"), float("nan")


ENERGY_SOURCES = frozenset({Feature.FORCE_FIELDS, Feature.EMITTERS, Feature.IMPULSES})
"""Scene features that may put energy in: without them a scene's energy can only fall."""


def energy_behaviour(case: Case) -> str:
    """What the exact energy of a case does: ``source`` (it may rise: force fields,
    emitters, impulses), ``dissipative`` (it only falls: damping, drag, inelastic or
    frictional contact) or ``conservative`` (it stays)."""
    if case.features & ENERGY_SOURCES:
        return "source"
    m = case.model
    if m is None:
        return "conservative"
    damped = (
        m.drag > 0
        or np.any(m.springs.damping > 0)
        or np.any(m.anchors.damping > 0)
        or any(p.restitution < 1 or p.friction > 0 for p in m.planes)
    )
    return "dissipative" if damped else "conservative"


PRE_ASYMPTOTIC = 0.5
"""Errors above this fraction of the case's scale are not fitted: the run is wrong
altogether there, not converging."""
ROUND_OFF = 1e-11
"""Errors below this fraction of the case's scale are round-off, which has no order."""
ROUND_OFF_FLOAT32 = 1e-4
"""The same for an engine whose state is float32 (``precision = "float32"``): float32 keeps
about 7 digits, and its rounding adds up over a run's steps. MuJoCo Warp's RK4 stalls at
1.1e-6 of the amplitude on the oscillator (2000 steps) and at 2e-5 of the scale on
spring-chain (8000 steps of a chain) however small the step; a floor 5 times the larger
keeps the stall out of the fit (at 1e-5 spring-chain's plateau was fitted as order 0.32)."""


RECORDED_PRECISION: dict[str, str] = {}
"""Engine -> the precision its run recorded (``run.json`` ``precision``, set by
:func:`recorded_precision` where a run's tables are judged): a verdict reads the facts
the run was made with, not the adapters installed where it is judged."""


def recorded_precision(record: dict | None) -> None:
    """Take the engines' precisions a run recorded (its ``run.json``), over what the
    adapters installed here say."""
    for engine, precision in ((record or {}).get("precision") or {}).items():
        if precision in ("float32", "float64"):
            RECORDED_PRECISION[str(engine)] = precision


def precision_of(engine: str) -> str:
    """The precision of ``engine``'s state: as its run recorded it
    (:data:`RECORDED_PRECISION`), else its adapter's ``precision`` (``"float32"`` or
    ``"float64"``, the default, also for an engine not installed or not known here)."""
    from truestep.adapters import EngineNotInstalled, UnknownEngine, adapter_class

    if engine in RECORDED_PRECISION:
        return RECORDED_PRECISION[engine]
    try:
        return str(getattr(adapter_class(engine), "precision", "float64"))
    except (EngineNotInstalled, UnknownEngine):
        return "float64"


def round_off_floor(engine: str) -> float:
    """The round-off floor (a fraction of a case's scale) of ``engine``'s errors:
    :data:`ROUND_OFF_FLOAT32` for an adapter that declares ``precision = "float32"``,
    else :data:`ROUND_OFF` (also for an engine not installed here)."""
    return ROUND_OFF_FLOAT32 if precision_of(engine) == "float32" else ROUND_OFF


AGREE = 0.3
"""Local orders within this of the finest one belong to the asymptotic range (a method whose
error is ``C dt^p (1 + c dt)`` changes its local order by less, once converging; one that
is not yet converging, or whose error term changes, by more)."""


RISING = 0.1
"""How much a local order must grow from one halving of the step to the next for a method
below its order to be taken as still converging (a wrong method's error stays flat: its
local order does not rise). :mod:`truestep.execution.refine` stops halving, and a
declared-order gate fails, where it does not."""


CONVERGING = 0.5
"""The least local order (:func:`local_orders`) at the finest steps of a
sweep that shows a method converging: every consistent method's error falls at least as
``dt^1`` once it converges, so a slower fall means the sweep has not reached that regime
(implicit Euler damping a stiff cloth's motion away at every swept step)."""


def local_orders(dts: np.ndarray, errors: np.ndarray) -> np.ndarray:
    """``log(e_i / e_(i+1)) / log(dt_i / dt_(i+1))`` between successive steps, the steps
    sorted from the largest; shape (len - 1,)."""
    order = np.argsort(-np.asarray(dts, float))
    d, e = np.log(np.asarray(dts, float)[order]), np.log(np.asarray(errors, float)[order])
    return np.diff(e) / np.diff(d)


def finest_local_order(dts: np.ndarray, errors: np.ndarray) -> float:
    """The local order (:func:`local_orders`) between the two finest steps whose error is
    finite and positive, NaN with fewer than two: below :data:`CONVERGING`, the error does
    not yet fall with the step there, and a declared-order gate is not evaluated on such a
    sweep (``truestep.ci.gates``)."""
    dts, errors = np.asarray(dts, float), np.asarray(errors, float)
    usable = np.isfinite(errors) & (errors > 0)
    local = local_orders(dts[usable], errors[usable])
    return float(local[-1]) if len(local) else float("nan")


ABOVE_FLOOR = 100.0
"""How far above the round-off floor (:func:`round_off_floor`, a fraction of the case's
scale) a flat error must lie to say something about the method: there, an error that does
not fall with the step is the method's (a wrong rest length, a lost term), not rounding."""


def flat_above_floor(dts: np.ndarray, errors: np.ndarray, *, scale: float, floor: float) -> bool:
    """Whether the error does not fall with the step at the finest steps (a
    :func:`finest_local_order` below :data:`CONVERGING`) while both of those errors lie
    :data:`ABOVE_FLOOR` times the round-off ``floor`` (a fraction of ``scale``) or more
    above zero: a method that stopped converging, or has not started to, well above its
    rounding. Which of the two it is, only finer steps tell
    (:mod:`truestep.execution.refine`)."""
    dts, errors = np.asarray(dts, float), np.asarray(errors, float)
    usable = np.isfinite(errors) & (errors > 0) & np.isfinite(dts)
    if usable.sum() < 2:
        return False
    d, e = dts[usable], errors[usable]
    finest = e[np.argsort(d)[:2]]
    return bool(finest_local_order(d, e) < CONVERGING and np.all(finest > ABOVE_FLOOR * floor * scale))


def fit_order(dts: np.ndarray, errors: np.ndarray, *, scale: float = 1.0, floor: float = ROUND_OFF) -> float:
    """Order of convergence, fitted where the asymptotic regime holds.

    Points whose error is above :data:`PRE_ASYMPTOTIC` of ``scale`` (not converging) or
    below ``floor`` of it (round-off: :func:`round_off_floor` of the engine) are left
    out. Of the rest, sorted by step, the local orders between successive steps
    (:func:`local_orders`) are read from the finest pair up: the range extends to a
    coarser step while its local order is within :data:`AGREE` of the finest pair's. The
    order is the least-squares slope of log(error) against log(dt) over that range.
    NaN with fewer than two usable points.
    """
    dts, errors = np.asarray(dts, float), np.asarray(errors, float)
    ok = (
        np.isfinite(errors)
        & np.isfinite(dts)
        & (dts > 0)
        & (errors > floor * scale)
        & (errors < PRE_ASYMPTOTIC * scale)
    )
    dts, errors = dts[ok], errors[ok]
    if len(dts) < 2:
        return float("nan")
    order = np.argsort(-dts)
    dts, errors = dts[order], errors[order]
    local = local_orders(dts, errors)
    start = len(local) - 1  # the finest pair
    while start > 0 and abs(local[start - 1] - local[-1]) <= AGREE:
        start -= 1
    keep = slice(start, None)
    slope, _ = np.polyfit(np.log(dts[keep]), np.log(errors[keep]), 1)
    return float(slope)
