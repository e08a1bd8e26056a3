"""Static particles: the whole life of each particle kept as one strand (hair, fur, grass).

"If the entire life cycle of each particle is rendered simultaneously, the result is
static particles: strands of material that show the particles' overall trajectory."
An emitter scene is simulated as usual; every particle's positions over its life become
a polyline, drawn with a thickness that may taper from root to tip.

The strands are stored packed, like a sparse matrix in CSR form: the points of all
strands one after another, and ``start`` offsets where each strand begins, so that
lengths, thicknesses and checks are vectorised over all strands at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Strands:
    """Polylines of particle lives, packed.

    points : ndarray, shape (P, 3), m      every strand's points, strand after strand
    times : ndarray, shape (P,), s         when the particle was at each point
    velocities : ndarray, shape (P, 3)     its velocity there, m/s
    start : ndarray of int, shape (S + 1,) strand ``s`` is ``points[start[s]:start[s+1]]``
    slot : ndarray of int, shape (S,)      the particle slot each strand came from
    thickness : ndarray, shape (P,), m     rendered thickness at each point
    """

    points: np.ndarray
    times: np.ndarray
    velocities: np.ndarray
    start: np.ndarray
    slot: np.ndarray
    thickness: np.ndarray

    def __len__(self) -> int:
        return len(self.slot)

    def strand(self, s: int) -> np.ndarray:
        """The polyline of strand ``s``, shape (k, 3)."""
        return self.points[self.start[s] : self.start[s + 1]]

    def strand_index(self) -> np.ndarray:
        """Which strand each point belongs to, shape (P,)."""
        return np.repeat(np.arange(len(self)), np.diff(self.start))

    def segment_lengths(self) -> np.ndarray:
        """Length of the segment ending at each point (0 at roots), shape (P,), m."""
        seg = np.zeros(len(self.points))
        if len(self.points) > 1:
            seg[1:] = np.linalg.norm(np.diff(self.points, axis=0), axis=1)
        seg[self.start[:-1]] = 0.0
        return seg

    def arc_length(self) -> np.ndarray:
        """Arc length from the strand's root to each point, shape (P,), m."""
        cum = np.cumsum(self.segment_lengths())
        return cum - np.repeat(cum[self.start[:-1]], np.diff(self.start))

    def lengths(self) -> np.ndarray:
        """Polyline length of every strand, shape (S,), m."""
        if not len(self):
            return np.zeros(0)
        return np.add.reduceat(self.segment_lengths(), self.start[:-1])


def collect_strands(
    t: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    alive: np.ndarray,
    *,
    root_thickness: float | np.ndarray = 1e-3,
    taper: float = 1.0,
) -> Strands:
    """Cut recorded particle positions into strands, one per particle life.

    Parameters
    ----------
    t : ndarray, shape (T,), s;  x, v : ndarray, shape (T, n, 3), m and m/s
    alive : ndarray of bool, shape (T, n)
        A slot's consecutive alive records form one strand; a slot reused by a later
        particle starts a new one (records must be dense enough to see it dead between
        two lives: an emitter reuses a freed slot as late as it can).
    root_thickness : float or ndarray, shape (n,), m
        Thickness at the root, per slot or for all.
    taper : float
        Fraction by which the thickness falls from root to tip, linearly in arc length
        (0: uniform, 1: to a point).
    """
    alive = np.asarray(alive, dtype=bool)
    n = alive.shape[1]
    by_slot = alive.T  # (n, T)
    slot_of, rec_of = np.nonzero(by_slot)  # slot-major: each slot's records in time order
    new = np.ones(len(slot_of), dtype=bool)
    if len(slot_of) > 1:
        new[1:] = (slot_of[1:] != slot_of[:-1]) | (rec_of[1:] != rec_of[:-1] + 1)
    start = np.append(np.flatnonzero(new), len(slot_of))
    strands = Strands(
        points=x[rec_of, slot_of],
        times=t[rec_of],
        velocities=v[rec_of, slot_of],
        start=start,
        slot=slot_of[start[:-1]],
        thickness=np.zeros(len(slot_of)),
    )
    roots = np.broadcast_to(np.asarray(root_thickness, dtype=float), (n,))
    total = np.repeat(strands.lengths(), np.diff(start))
    frac = np.divide(strands.arc_length(), total, out=np.zeros_like(total), where=total > 0)
    strands.thickness = roots[slot_of] * (1.0 - taper * frac)
    return strands


def ballistic_deviation(strands: Strands, gravity: np.ndarray, drag: float, mass: float) -> np.ndarray:
    """Distance of every strand point from the exact path of its root, shape (P,), m.

    Each strand's first point and velocity fix the motion under uniform gravity and
    viscous drag ``k``: ``x(s) = x_0 + v_inf s + (v_0 - v_inf) (m / k) (1 - e^(-k s / m))``
    with ``v_inf = m g / k`` (``x_0 + v_0 s + g s^2 / 2`` when ``k = 0``), ``s`` the time
    since the root. A strand of a free particle lies on that curve exactly.
    """
    roots = np.repeat(strands.start[:-1], np.diff(strands.start))
    s = (strands.times - strands.times[roots])[:, None]
    x0, v0 = strands.points[roots], strands.velocities[roots]
    if drag > 0:
        tau = mass / drag
        v_inf = tau * gravity
        exact = x0 + v_inf * s + (v0 - v_inf) * tau * (-np.expm1(-s / tau))
    else:
        exact = x0 + v0 * s + 0.5 * gravity * s**2
    return np.linalg.norm(strands.points - exact, axis=1)
