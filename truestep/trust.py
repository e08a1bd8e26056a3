"""What an adapter returns is checked before anything is measured from it.

:func:`checked` turns a :class:`~truestep.adapters.base.Trajectory` that breaks the
adapter contract into that row's ``crashed`` message (never the run's), and a state that
went non-finite under an ``ok`` status into ``unstable`` at the first such record.
"""

from __future__ import annotations

import numpy as np

from truestep.adapters.base import Trajectory

STATUSES = ("ok", "unstable", "solver-failed")
"""Statuses an adapter may return; the harness adds ``crashed``, ``timeout`` and the rest."""


def _shape(a: object) -> str:
    return "x".join(map(str, np.shape(a))) or "a scalar"


def contract_breach(traj: object, n: int | None = None) -> str | None:
    """Why ``traj`` breaks the adapter contract, in one short line, or ``None``.

    ``t`` (T,) finite and non-decreasing; ``x`` (T, n, 3) for a particle scene of ``n``
    particles (``n`` given), else (T, 1, dim) for an ODE case; ``v`` as ``x`` or ``None``;
    ``energy`` (T,) or ``None``; ``alive`` (T, n) or ``None``; a known status; at least
    two records when the status is ``ok``.
    """
    if not isinstance(traj, Trajectory):
        return f"adapter returned {type(traj).__name__}, not a Trajectory"
    if traj.status not in STATUSES:
        return f"adapter returned status {str(traj.status)[:40]!r} (known: {', '.join(STATUSES)})"
    try:
        t = np.asarray(traj.t, dtype=float)
        x = np.asarray(traj.x, dtype=float)
    except (TypeError, ValueError) as err:
        return f"adapter returned non-numeric t or x ({str(err)[:60]})"
    if t.ndim != 1 or len(t) == 0:
        return f"adapter returned t of shape {_shape(t)}, expected (T,) with T >= 1"
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
        return "adapter returned record times that are not finite and non-decreasing"
    want = (len(t), n, 3) if n is not None else (len(t), 1, x.shape[-1] if x.ndim else 0)
    if x.shape != want:
        return f"adapter returned x of shape {_shape(x)}, expected {want}"
    for name, want in (("v", x.shape), ("energy", (len(t),)), ("alive", x.shape[:2])):
        value = getattr(traj, name)
        if value is not None and np.shape(value) != want:
            return f"adapter returned {name} of shape {_shape(value)}, expected {want}"
    if traj.status == "ok" and len(t) < 2:
        return "adapter returned status 'ok' with one record: nothing was simulated"
    return None


def checked(traj: object, n: int | None = None) -> Trajectory | str:
    """``traj`` as the harness trusts it, or the ``crashed`` message of its breach.

    A state (``x`` or ``v``) that is non-finite at some record of an ``ok`` run makes it
    ``unstable`` at the first such record's time, whatever the adapter said. ``n``: as
    :func:`contract_breach`.
    """
    why = contract_breach(traj, n)
    if why is not None:
        return why
    if traj.status == "ok":
        bad = ~np.isfinite(traj.x).all(axis=(1, 2))
        if traj.v is not None:
            bad |= ~np.isfinite(traj.v).all(axis=(1, 2))
        if bad.any():
            first = int(np.argmax(bad))
            traj.status, traj.t_fail = "unstable", float(traj.t[first])
            traj.message = "; ".join(m for m in (traj.message, "the state went non-finite "
                                     "(found by the harness; the adapter said ok)") if m)
    return traj
