"""Effective restitution per bounce, from rebound velocities and from apex heights, every
quantity read from the motion itself.

A ball falls onto a plane under the normal component of gravity ``g_n`` (m/s^2, toward
the plane). A contact is the run of steps during which the plane pushes the ball (or the
ball is within :data:`CONTACT_BAND` of it). Per bounce:

* **from velocities**: the normal speed at the first sample after the contact over the
  speed at the last sample before it. This is the quantity an engine's restitution law
  acts on (``V' = V_T - k_r V_N`` on the velocity at the start of the contact step), so
  a hard-contact engine that honours ``k_r`` reads exactly ``k_r`` at any step; the
  samples miss the true impact and release by less than a step, which shows up as an
  error of at most about ``g_n dt / v``.
* **apex**: the highest height the ball reaches in the flight after the contact, the
  largest of the flight's samples (a run recorded at every step: the height it reached
  at a step), with ``H_0`` the highest point before the first contact; and the
  restitution from apexes, ``sqrt(H_n / H_(n-1))``. Nothing is extrapolated: an
  integrator whose flight is not ballistic (symplectic Euler's, a soft contact that
  launches late) is measured by the heights it actually reaches. A flight sampled every
  ``dt`` reads its apex low by at most ``g_n dt^2 / 8``.
* **when**: the time of the contact's lowest sample (its deepest point: the impact of a
  hard contact to within a step, the middle of a soft one).

Every quantity is read the same way for every engine, and none from a sample inside the
contact but the lowest: a soft contact (an engine's spring-damper, lasting several steps
and penetrating) is one contact, however its velocity turns while it lasts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

CONTACT_BAND = 1e-3
"""m. Closer than this to the plane counts as contact. A falling ball moves 18 mm per
step at 4.4 m/s and 1/240 s; engines' contact slop is below 1 mm once set for metre
scenes. Bounces whose flight never leaves the band are not detected."""

PHASES = 16
"""Balls of the impact-phase drops (:func:`truestep.execution.analyses.phase_case`): their
first contacts begin at ``PHASES`` evenly spaced points within a step, so that a contact
law that depends on where in a step the ball arrives shows its whole range (Newton's
penalty contact, asked 0.5, gave 0.33 to 0.53 over 3001 heights in an independent
audit)."""
PHASE_BAND = 0.05
"""How far (absolute) from the asked restitution the impact-phase drops may read, over
every phase, for a row to say its engine delivers the asked e: reading e from the
samples either side of a hard contact errs by at most about ``g dt / v`` (0.9 % at
1/240 s and the drop's 4.4 m/s)."""


@dataclass
class Bounce:
    """One impact: number (from 1), time of the last sample before it (s), speeds in and
    out (m/s), restitution from velocities, apex height after it (m above contact, the
    highest sample of the flight; 0 once the ball rests), restitution from apex heights,
    the deepest penetration during the contact (m, >= 0) and the time of the contact's
    lowest sample (s)."""

    bounce: int
    t: float
    v_in: float
    v_out: float
    e_velocity: float
    apex: float
    e_apex: float
    penetration: float
    t_low: float = float("nan")


def contact_intervals(
    t: np.ndarray, h: np.ndarray, vn: np.ndarray, g_n: float, *, band: float = CONTACT_BAND
) -> np.ndarray:
    """Which intervals between consecutive samples (shape (T-1,)) involve the plane.

    An interval is in contact if the plane pushed the ball during it (its normal velocity
    rose above free flight's ``vn - g_n dt`` by more than the run's round-off:
    :func:`flight_noise`, at least 1e-6 of the largest speed) or if either end is within
    ``band`` of the plane. A bounce that completes inside one step is caught by the first
    test, a soft contact spread over many steps by both.
    """
    rise = np.diff(vn) + g_n * np.diff(t)
    scale = float(np.max(np.abs(vn))) or 1.0
    near = h <= band
    pushed = rise > max(1e-6 * scale, flight_noise(rise, near))
    return pushed | near[:-1] | near[1:]


NOISE_FACTOR = 20.0
"""How many times the median flight deviation a rise must exceed to count as a push."""


def flight_noise(rise: np.ndarray, near: np.ndarray) -> float:
    """The velocity change (m/s) round-off alone makes between samples in free flight:
    :data:`NOISE_FACTOR` times the median ``|rise|`` over the intervals with both ends
    beyond the band (0 if there are none).

    ``rise`` (T-1,) is each interval's normal-velocity change above free flight's, ``near``
    (T,) which samples lie within the band. In float64 this is some 1e-15 m/s and the
    floor of 1e-6 of the largest speed decides; an engine whose float32 velocities are
    position differences over a step (XPBD) varies by ``ulp(x) / dt``, some 1e-4 m/s at a
    metre and 1 ms, which would otherwise read as a push at every step.
    """
    flight = ~near[:-1] & ~near[1:]
    if not np.any(flight):
        return 0.0
    return NOISE_FACTOR * float(np.median(np.abs(rise[flight])))


def bounces(
    t: np.ndarray, h: np.ndarray, vn: np.ndarray, g_n: float, *, band: float = CONTACT_BAND
) -> list[Bounce]:
    """Bounces of a trajectory given height above contact ``h`` (m) and normal velocity
    ``vn`` (m/s, positive away from the plane), both shape (T,), with gravity ``g_n``
    (m/s^2, >= 0) pulling toward the plane; on a wall along gravity (``g_n = 0``) the
    flights are straight and have no apex (NaN).

    A contact is a run of contact intervals (:func:`contact_intervals`); it is measured
    from the sample before the run (``v_in``, the speed toward the plane) and the sample
    after it (``v_out``); the flight after it runs to the next contact (or the end), and
    its apex is its highest sample (NaN for a flight the end of the run cuts while it
    still rises). A contact that lasts to the end of the run (the ball came to rest) has
    ``v_out = 0`` and apex 0.
    """
    if g_n < 0:
        raise ValueError(f"g_n must not be negative (gravity toward the plane or along it), got {g_n}")
    touching = contact_intervals(t, h, vn, g_n, band=band)
    edges = np.diff(np.concatenate([[0], touching.astype(np.int8), [0]]))
    starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]
    out: list[Bounce] = []
    first = int(starts[0]) if len(starts) else len(t) - 1
    apex_prev = float(np.max(h[: first + 1])) if g_n > 0 else np.nan
    for k, (a, b) in enumerate(zip(starts, ends, strict=True)):
        # intervals a..b-1 touch: samples a (before) .. b (after)
        if a == 0:
            continue
        v_in = float(-vn[a])
        low = a + int(np.argmin(h[a : b + 1]))
        penetration = max(0.0, float(-h[low]))
        resting = b >= len(t) - 1 or vn[b] <= 0
        v_out = 0.0 if resting else float(vn[b])
        if resting:
            apex = 0.0
        elif g_n > 0:
            until = int(starts[k + 1]) if k + 1 < len(starts) else len(t) - 1
            top = b + int(np.argmax(h[b : until + 1]))
            # a flight the end of the run cuts while it still rises has no apex yet
            cut = k + 1 >= len(starts) and top == len(t) - 1 and vn[top] > 0
            apex = np.nan if cut else max(float(h[top]), 0.0)
        else:  # a wall along gravity: straight flight off it, no apex
            apex = np.nan
        out.append(
            Bounce(
                len(out) + 1,
                float(t[a]),
                v_in,
                v_out,
                v_out / v_in if v_in > 0 else np.nan,
                apex,
                float(np.sqrt(apex / apex_prev)) if apex_prev > 0 else np.nan,
                penetration,
                float(t[low]),
            )
        )
        if resting:
            break
        apex_prev = apex
    return out


def heights(
    x: np.ndarray, v: np.ndarray, point: np.ndarray, normal: np.ndarray, radius: float
) -> tuple[np.ndarray, np.ndarray]:
    """Height of a ball's surface above a plane and its normal velocity.

    x, v : shape (T, 3), m and m/s;  point, normal : shape (3,);  radius : m.
    """
    return (x - point) @ normal - radius, v @ normal


def phase_contact(restitution: pd.DataFrame | None) -> pd.DataFrame:
    """The rows of the restitution sweep whose impact-phase drops leave the asked ``e_set``
    by more than :data:`PHASE_BAND` (first bounces; columns ``engine, method, dt, e_set,
    phases, e_phase_median, e_phase_min, e_phase_max, off``, ``off`` the farthest of the
    range from ``e_set``), the farthest first within each engine and method, the pairs in
    the order of the sweep."""
    cols = [
        "engine",
        "method",
        "dt",
        "e_set",
        "phases",
        "e_phase_median",
        "e_phase_min",
        "e_phase_max",
        "off",
    ]
    if restitution is None or not len(restitution) or "e_phase_min" not in restitution:
        return pd.DataFrame(columns=cols)
    r = restitution[(restitution["status"] == "ok") & (restitution["bounce"] == 1)].copy()
    for c in ("e_set", "e_phase_min", "e_phase_max", "e_phase_median", "dt", "phases"):
        r[c] = pd.to_numeric(r[c], errors="coerce")
    r = r.dropna(subset=["e_phase_min", "e_phase_max"])
    r["off"] = np.maximum(r["e_set"] - r["e_phase_min"], r["e_phase_max"] - r["e_set"])
    r = r[r["off"] > PHASE_BAND]
    order = {pair: k for k, pair in enumerate(dict.fromkeys(zip(r["engine"], r["method"], strict=True)))}
    r["pair"] = [order[p] for p in zip(r["engine"], r["method"], strict=True)]
    return r.sort_values(["pair", "off"], ascending=[True, False], kind="stable")[cols].reset_index(drop=True)


def contact_note(w: pd.Series) -> str:
    """A row's note that its engine and method's contact does not give the asked
    restitution at every impact phase (``w``: a row of :func:`phase_contact`)."""
    return (
        f"contact law: asked e {w['e_set']:g} gives {w['e_phase_min']:.3f} to {w['e_phase_max']:.3f} "
        f"over the impact phases at dt {float(w['dt']):.4g} s (restitution.csv): its error on a "
        "contact case is partly its contact law's"
    )


def with_contact_notes(results: pd.DataFrame, restitution: pd.DataFrame | None, contact: set[str]) -> None:
    """Add :func:`contact_note` to the ``message`` of each row that ran a case of
    ``contact`` (scenes with a plane) with an engine and method whose restitution drops
    leave the asked e by more than :data:`PHASE_BAND` at some impact phase
    (:func:`phase_contact`, its farthest row), in place. Rows of other cases, and rows that
    did not run, are left as they are."""
    from truestep.tables.io import RAN

    phase = phase_contact(restitution)
    if not len(phase) or results.empty or "message" not in results:
        return
    pairs = phase.groupby(["engine", "method"], sort=False)
    notes = {(str(e), str(m)): contact_note(g.iloc[0]) for (e, m), g in pairs}
    for k in results.index:
        row = results.loc[k]
        note = notes.get((str(row["engine"]), str(row["method"])))
        if note is None or row["case"] not in contact or row["status"] not in RAN:
            continue
        said = row["message"] if isinstance(row["message"], str) else ""
        results.at[k, "message"] = f"{said}; {note}" if said else note
