"""The spring-dashpot contact law the penalty-contact engines are set up with (MuJoCo,
MuJoCo Warp, Newton): a unit-mass linear spring and damper that release at zero force,
and the damping that gives an asked coefficient of restitution. Plain numpy: an engine's
adapter may use it without importing another engine."""

from __future__ import annotations

import numpy as np

CONTACT_STEPS = 10.0
"""Default contact time t_c in time steps (the undamped half period of the contact spring)."""


def restitution_of(zeta: float) -> float:
    """Restitution of a unit-mass spring-dashpot contact that releases at zero force.

    ``e = exp(-2 zeta arccos(zeta) / sqrt(1 - zeta^2))`` for ``zeta < 1``, its analytic
    continuation with ``arccosh`` for ``zeta > 1``, and ``exp(-2)`` at ``zeta = 1``.
    """
    if zeta < 0:
        raise ValueError(f"zeta: must be non-negative, got {zeta}")
    if abs(zeta - 1.0) < 1e-9:
        return float(np.exp(-2.0))
    if zeta < 1.0:
        return float(np.exp(-2.0 * zeta * np.arccos(zeta) / np.sqrt(1.0 - zeta**2)))
    return float(np.exp(-2.0 * zeta * np.arccosh(zeta) / np.sqrt(zeta**2 - 1.0)))


def damping_ratio(e: float) -> float:
    """The contact damping ratio zeta that gives restitution ``e``; inverts :func:`restitution_of`.

    ``e = 0`` needs infinite damping and returns ``inf``; :func:`contact_solref` caps it.
    """
    if not 0.0 <= e <= 1.0:
        raise ValueError(f"e: restitution must lie in [0, 1], got {e}")
    if e == 0.0:
        return float("inf")
    if e == 1.0:
        return 0.0
    lo, hi = 0.0, 1.0
    while restitution_of(hi) > e:
        lo, hi = hi, 2.0 * hi
    for _ in range(200):  # bisection: restitution_of decreases monotonically in zeta
        mid = 0.5 * (lo + hi)
        if restitution_of(mid) > e:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def max_damping_ratio(t_c: float, h: float) -> float:
    """The largest contact damping ratio at contact time ``t_c`` and step ``h``: ``h B = 1``.

    An explicit damper with ``h B > 1`` reverses the normal velocity within a step (and
    for ``h B > 2`` it diverges), so the contact would throw the particle out.
    """
    return t_c / (2.0 * np.pi * h)


def contact_solref(e: float, t_c: float, h: float) -> tuple[float, float, bool]:
    """Direct-form contact stiffness K (1/s^2) and damping B (1/s) for restitution ``e``.

    ``omega = pi / t_c``, ``K = omega^2``, ``B = 2 zeta omega`` with ``zeta`` from
    :func:`damping_ratio`, capped at :func:`max_damping_ratio`; the flag says whether the
    cap applied. MJCF wants the numbers as ``solref="-K -B"``.
    """
    omega = np.pi / t_c
    zeta = damping_ratio(e)
    cap = max_damping_ratio(t_c, h)
    return float(omega**2), float(2.0 * min(zeta, cap) * omega), zeta > cap
