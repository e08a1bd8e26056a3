"""Particles a run never moved although the scene moves them: updates lost to round-off.

An engine whose state is float32 adds ``v h`` to a position every step; where that is
below half a unit in the last place of the position (a 1e4 kg particle pulled at 2e-3
m/s^2 at x = 1 m, stepped at 5 ms: ``v h`` about 5e-8 m against float32's 6e-8), the sum
rounds back to the position, and a position-based solver, whose velocity is the change of
position over the step, then holds its velocity at zero too: the particle never moves.
Such a run ends ``ok`` and its error is that of a frozen particle, whatever the method; its
row is ``stalled`` instead (:func:`stalled`), and it enters no order fit and no pick.
"""

from __future__ import annotations

import numpy as np

from truestep.adapters.base import Trajectory
from truestep.cases.case import Case
from truestep.reference_impl.model import ParticleModel

STALL_ULPS = 1000
"""A coordinate the run left at its start bit for bit is stalled when the exact motion moves
it by more than this many units in the last place of the run's precision (of the
coordinate's size, at least 1 m): far more than any rounding of a motion that stays put."""


def stalled(case: Case, traj: Trajectory, exact, precision: str = "float64") -> str | None:
    """Why a finished run's particles stalled, or ``None``: a coordinate of a free particle
    equal to its start at every record, bit for bit (its velocity too, where recorded), while
    the case's exact (or reference) motion ``exact`` (an :class:`~truestep.cases.exact.Exact`
    at the run's record times) moves it by more than :data:`STALL_ULPS` of the run's
    ``precision`` (``"float32"`` or ``"float64"``)."""
    if not isinstance(case.scene, ParticleModel) or exact is None or getattr(exact, "x", None) is None:
        return None
    x, ex = np.asarray(traj.x, float), np.asarray(exact.x, float)
    if x.ndim != 3 or ex.shape != x.shape or len(x) < 2:
        return None
    still = np.all(x == x[:1], axis=0)  # (n, 3)
    if traj.v is not None and np.shape(traj.v) == x.shape:
        v = np.asarray(traj.v, float)
        still &= np.all(v == v[:1], axis=0)
    still &= ~np.asarray(case.particles.fixed, bool)[:, None]
    if not still.any():
        return None
    with np.errstate(invalid="ignore"):
        moved = np.nanmax(np.abs(ex - ex[:1]), axis=0)  # (n, 3)
    eps = float(np.finfo(np.float32 if precision == "float32" else np.float64).eps)
    ulp = eps * np.maximum(np.abs(x[0]), 1.0)
    stuck = still & np.isfinite(moved) & (moved > STALL_ULPS * ulp)
    if not stuck.any():
        return None
    p, c = (int(i) for i in np.argwhere(stuck)[0])
    axis = "xyz"[c]
    others = int(stuck.any(axis=1).sum()) - 1
    more = f" (and {others} more particle{'s' * (others != 1)})" if others > 0 else ""
    return (
        f"stalled: particle {p}{more} never moved along {axis} from {x[0, p, c]:.6g} m, where the "
        f"exact motion moves it by {moved[p, c]:.3g} m: its updates are below the {precision} "
        "precision of its position"
    )
