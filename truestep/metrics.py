"""Pure functions from a trajectory and its reference to numbers."""

from __future__ import annotations

import numpy as np

from truestep.adapters.base import Trajectory
from truestep.cases.case import Case
from truestep.cases.exact import Exact
from truestep.cases.plugins import exact_solution

_EXACT_CACHE: dict[tuple[int, bytes], tuple[Case, Exact]] = {}
_EXACT_CACHE_SIZE = 32


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
    exact = exact_solution(case.exact)(case, t)
    if len(_EXACT_CACHE) >= _EXACT_CACHE_SIZE:
        _EXACT_CACHE.pop(next(iter(_EXACT_CACHE)))
    _EXACT_CACHE[key] = (case, exact)
    return exact


def _matching(t: np.ndarray, t_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices into ``t`` and ``t_ref`` of times both contain (to 1e-9 relative)."""
    if len(t_ref) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    k = np.clip(np.searchsorted(t, t_ref), 0, len(t) - 1)
    k_lo = np.clip(k - 1, 0, len(t) - 1)
    k = np.where(np.abs(t[k_lo] - t_ref) < np.abs(t[k] - t_ref), k_lo, k)
    ok = np.abs(t[k] - t_ref) <= 1e-9 * np.maximum(1.0, np.abs(t_ref))
    return k[ok], np.nonzero(ok)[0]


def position_error(case: Case, traj: Trajectory, exact: Exact) -> float:
    """Distance between computed and exact positions, m (or state units for an ODE).

    ``final``: at the last time both share (which must be the end of the run);
    ``max``: the largest over every shared time. Per record, the largest distance over
    particles (Euclidean; for an ODE state, the largest component). Particles that are
    not alive in the run, or whose exact position is not known (NaN: not alive in a
    reference run), are not compared.
    """
    k, j = _matching(traj.t, exact.t)
    if len(k) == 0:
        return float("nan")
    d = traj.x[k] - exact.x[j]
    if traj.alive is not None and case.kind != "ode":
        d = np.where(traj.alive[k][..., None], d, np.nan)
    d = np.where(np.isnan(exact.x[j]), 0.0, np.nan_to_num(d, nan=0.0)) if np.isnan(d).any() else d
    per_record = np.max(np.abs(d), axis=(1, 2)) if case.kind == "ode" else np.max(
        np.linalg.norm(d, axis=2), axis=1
    )
    if case.error_norm == "final":
        if abs(traj.t[k[-1]] - case.duration) > 1e-9 * max(1.0, case.duration):
            return float("nan")
        return float(per_record[-1])
    return float(np.max(per_record))


def energy_drift(case: Case, traj: Trajectory, exact: Exact | None) -> tuple[float, float]:
    """Relative energy error: (largest over the run, at the end).

    Conservative scenes: ``|E(t) - E(0)| / |E(0)|``. Scenes whose exact solution gives the
    energy curve (damped oscillators): ``|E(t) - E_exact(t)| / |E_exact(0)|``. Otherwise NaN.
    """
    e = traj.energy
    if e is None or len(e) == 0:
        return float("nan"), float("nan")
    if case.conservative:
        scale = abs(e[0]) if e[0] != 0 else float(np.max(np.abs(e))) or 1.0
        dev = np.abs(e - e[0]) / scale
        return float(np.max(dev)), float(dev[-1])
    if exact is not None and exact.energy is not None and len(exact.t) == len(exact.energy):
        k, j = _matching(traj.t, exact.t)
        if len(k) == 0:
            return float("nan"), float("nan")
        scale = abs(exact.energy[0]) or 1.0
        dev = np.abs(e[k] - exact.energy[j]) / scale
        return float(np.max(dev)), float(dev[-1])
    return float("nan"), float("nan")


ENERGY_SOURCES = frozenset({"force-fields", "emitters", "impulses"})
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
    damped = (m.drag > 0 or np.any(m.springs.damping > 0) or np.any(m.anchors.damping > 0)
              or any(p.restitution < 1 or p.friction > 0 for p in m.planes))
    return "dissipative" if damped else "conservative"


def energy_blowup(case: Case, traj: Trajectory) -> float | None:
    """When a finite run blew up by its energy, or ``None``.

    Only in a scene without energy sources (:func:`energy_behaviour`), whose exact energy
    cannot rise, and with the run's energy moved by more than its start
    (``|E - E(0)| > |E(0)|``: a stable method can be that inaccurate only at steps near
    its limit): unstable when the energy keeps growing through every quarter of the run
    (:func:`truestep.stability.energy_keeps_growing`), or, in a dissipative scene, when it
    stays above its start (:func:`truestep.stability.energy_stays_up`), wherever in the
    run the rise happened. Returns the first time (s) the energy was that far from its
    start.
    """
    from truestep.stability import energy_keeps_growing, energy_stays_up

    e = traj.energy
    behaviour = energy_behaviour(case)
    if e is None or len(e) < 2 or behaviour == "source":
        return None
    if not (case.conservative or case.kind == "particles"):
        return None
    far = np.abs(e - e[0]) > (abs(e[0]) or float(np.max(np.abs(e))) or 1.0)
    if not far.any():
        return None
    if not energy_keeps_growing(traj.t, e) and not (
            behaviour == "dissipative" and energy_stays_up(traj.t, e)):
        return None
    return float(traj.t[np.argmax(far)])


def fit_order(dts: np.ndarray, errors: np.ndarray, *, scale: float = 1.0) -> float:
    """Order of convergence: the least-squares slope of log(error) against log(dt).

    Points outside the asymptotic range are left out: errors above ``0.1 * scale``
    (the method has not converged yet) and below ``1e-11 * scale`` (round-off).
    Returns NaN with fewer than two usable points.
    """
    dts, errors = np.asarray(dts, float), np.asarray(errors, float)
    ok = np.isfinite(errors) & (errors > 1e-11 * scale) & (errors < 0.1 * scale)
    if np.count_nonzero(ok) < 2:
        return float("nan")
    slope, _ = np.polyfit(np.log(dts[ok]), np.log(errors[ok]), 1)
    return float(slope)
