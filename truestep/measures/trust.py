"""What an adapter returns is checked before anything is measured from it.

:func:`checked` turns a :class:`~truestep.adapters.base.Trajectory` that breaks the
adapter contract into that row's ``crashed`` message (never the run's), and a state that
went non-finite under an ``ok`` status into ``unstable`` at the first such record.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from truestep.adapters.base import Trajectory
from truestep.cases.case import ode_states

STATUSES = ("ok", "unstable", "solver-failed")
"""Statuses an adapter may return; the harness adds ``crashed``, ``timeout`` and the rest."""


def _shape(a: Any) -> str:
    return "x".join(map(str, np.shape(a))) or "a scalar"


START_TOLERANCE = 1e-9
"""How far the first record may lie from the case's start (t = 0), as a fraction of the
duration: one rounding of a float sum, not a shift of the clock."""
END_SLACK = 0.01
"""How far past the case's duration the last record may lie, as a fraction of it (an
engine's last step may overshoot by part of a step; never by a whole run)."""


def _complex_field(traj: Trajectory) -> str | None:
    """The first of a run's arrays that holds complex numbers (a cast to float would drop
    their imaginary part, and measure the rest), or ``None``."""
    for name in ("t", "x", "y", "v", "energy"):
        value = getattr(traj, name, None)
        if value is not None and np.iscomplexobj(value):
            return name
    return None


def contract_breach(traj: object, n: int | None = None, *, duration: float | None = None) -> str | None:
    """Why ``traj`` breaks the adapter contract, in one short line, or ``None``.

    ``t`` (T,) finite and strictly increasing, from the case's start (t = 0) and, with
    ``duration`` given, no further than its end; ``x`` (T, n, 3) for a particle scene of
    ``n`` particles (``n`` given), else ``y`` (T, dim) for an ODE case (or, from an
    adapter written before ``y``, ``x`` as (T, 1, dim)); ``v`` as ``x`` or ``None``;
    ``energy`` (T,) or ``None``; ``alive`` (T, n) or ``None``; a known status; at least
    two records when the status is ``ok``; a wall time that is positive and finite,
    counts (``nfev``, ``steps``) that are not negative, and a ``t_fail`` that is ``None``,
    NaN or a time within the run.
    """
    if not isinstance(traj, Trajectory):
        return f"adapter returned {type(traj).__name__}, not a Trajectory"
    if traj.status not in STATUSES:
        return f"adapter returned status {str(traj.status)[:40]!r} (known: {', '.join(STATUSES)})"
    complex_part = _complex_field(traj)
    if complex_part is not None:
        return f"adapter returned complex {complex_part} (states, times and energies are real numbers)"
    try:
        t = np.asarray(traj.t, dtype=float)
        x = np.asarray(traj.x if n is not None or traj.y is None else traj.y[:, None], dtype=float)
    except (TypeError, ValueError, IndexError) as err:
        return f"adapter returned non-numeric t or {'x' if n is not None else 'y'} ({str(err)[:60]})"
    breach = _times_breach(t, duration) or _t_fail_breach(traj.t_fail, duration)
    if breach is not None:
        return breach
    wall = _number(traj.wall_s)
    if not (np.isfinite(wall) and wall > 0):
        return f"adapter returned a wall time of {wall:.6g} s (it must be positive and finite)"
    for name in ("nfev", "steps"):
        count = _number(getattr(traj, name))
        if not (np.isfinite(count) and count >= 0):
            return f"adapter returned {name} = {count:.6g} (a count, at least 0)"
    if n is None and traj.y is not None and np.ndim(traj.y) != 2:
        return f"adapter returned y of shape {_shape(traj.y)}, expected (T, dim) = ({len(t)}, dim)"
    want = (len(t), n, 3) if n is not None else (len(t), 1, x.shape[-1] if x.ndim else 0)
    if x.shape != want:
        if n is None and traj.y is not None:
            return f"adapter returned y of shape {_shape(traj.y)}, expected ({len(t)}, dim)"
        return f"adapter returned x of shape {_shape(x)}, expected {want}"
    for name, expect in (("v", x.shape), ("energy", (len(t),)), ("alive", x.shape[:2])):
        value = getattr(traj, name)
        if value is not None and np.shape(value) != expect:
            return f"adapter returned {name} of shape {_shape(value)}, expected {expect}"
    if traj.status == "ok" and len(t) < 2:
        return "adapter returned status 'ok' with one record: nothing was simulated"
    return None


def _t_fail_breach(t_fail: object, duration: float | None) -> str | None:
    """Why a run's ``t_fail`` breaks the contract: it is ``None``, NaN, or a simulated time
    (s) from 0 to the case's end; anything else (a word, a negative or infinite number)
    is no time a table can hold."""
    if t_fail is None:
        return None
    value = float("nan") if isinstance(t_fail, (str, bytes)) else _number(t_fail)
    if isinstance(t_fail, (str, bytes)) or np.isinf(value):
        return f"adapter returned t_fail = {str(t_fail)[:40]!r} (a time in s, or None)"
    end = duration * (1 + END_SLACK) + 1e-12 if duration is not None else np.inf
    if np.isfinite(value) and not 0 <= value <= end:
        return f"adapter returned t_fail = {value:.6g} s, outside the run (0 to {end:.6g} s)"
    return None


def _times_breach(t: np.ndarray, duration: float | None) -> str | None:
    """Why record times ``t`` (s) break the contract (see :func:`contract_breach`), or ``None``."""
    if t.ndim != 1 or len(t) == 0:
        return f"adapter returned t of shape {_shape(t)}, expected (T,) with T >= 1"
    if not np.all(np.isfinite(t)):
        return "adapter returned record times that are not finite"
    scale = max(abs(duration), 1.0) if duration is not None else 1.0
    if abs(t[0]) > START_TOLERANCE * scale:
        return f"adapter returned records from t = {t[0]:.6g} s, not from the case's start (t = 0)"
    if np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0))
        return f"adapter returned record times that do not increase (t = {t[k]:.6g} s, then {t[k + 1]:.6g} s)"
    if duration is not None and t[-1] > duration * (1 + END_SLACK) + 1e-12:
        return f"adapter returned records to t = {t[-1]:.6g} s, past the case's {duration:g} s"
    return None


def _number(value: object) -> float:
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        return float("nan")


def checked(traj: object, n: int | None = None, *, duration: float | None = None) -> Trajectory | str:
    """``traj`` as the harness trusts it, or the ``crashed`` message of its breach.

    A state (``x`` or ``v``) that is non-finite at some record of an ``ok`` run makes it
    ``unstable`` at the first such record's time, whatever the adapter said. ``n`` and
    ``duration``: as :func:`contract_breach`.
    """
    why = contract_breach(traj, n, duration=duration)
    if why is not None:
        return why
    assert isinstance(traj, Trajectory)  # contract_breach said so
    if n is None:
        _ode_states(traj)
    if traj.status == "ok":
        bad = ~np.isfinite(traj.x).all(axis=(1, 2))
        if traj.v is not None:
            bad |= ~np.isfinite(traj.v).all(axis=(1, 2))
        if bad.any():
            first = int(np.argmax(bad))
            traj.status, traj.t_fail = "unstable", float(traj.t[first])
            traj.message = "; ".join(
                m
                for m in (
                    traj.message,
                    "the state went non-finite (found by the harness; the adapter said ok)",
                )
                if m
            )
    return traj


def _ode_states(traj: Trajectory) -> None:
    """Give an ODE run both layouts: its states in ``y`` (T, dim) and, for code written
    before ``y``, the view ``x = y[:, None, :]``. An adapter that filled only ``x`` gets
    a ``DeprecationWarning`` (build the run with :meth:`Trajectory.of_ode`)."""
    traj.y = ode_states(traj)
    traj.x = traj.y[:, None, :]
