"""The kinetic and potential energy of many bouncing balls, summed over the balls at each
time in one compiled pass: what the energy scale of a large rain reads along its exact
path (:func:`truestep.measures.energy_scale.path_energies`), without the states.

Each ball follows the chain of parabolas of
:func:`truestep.cases.exact_particles.bounce_paths`, bounce by bounce, with the same
recurrence and the same stop; only its energies at each time are kept, summed in ball
order, so memory grows with the balls and the times (N + T), not with their product, and
no (T, N, 3) array is written. The sums round differently from the general path's
(``total_energy`` of the states: pairwise sums over the balls of ``-m g . x``), by a few
units in the last place; a test holds them to 1e-12 of the energy moved.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from truestep.cases.case import Case

STOP_LAUNCH = 1e-300
"""A ball's launch speed at or under which its schedule stops (m/s), as in ``bounce_paths``."""
STOP_COUNT = 100000
"""The most bounces of a ball's schedule, as in ``bounce_paths``."""


def rain_energies(case: Case, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times ``t`` (T,) s as given, and the kinetic and potential energy (T,) J of the
    balls of ``case`` (the ``bouncing-rain`` exact solution's scene) there: ``0.5 m |v|^2``
    and ``-m g . x`` summed over the balls (a pinned ball's mass counts as 0, as in
    ``total_energy``)."""
    from truestep.cases.exact_particles import _last_time_in_flight

    m = case.particles
    plane = m.planes[0]
    n, e = plane.normal, float(plane.restitution)
    g = float(-(m.gravity @ n))
    t = np.asarray(t, float)
    u0 = (m.x0 - plane.point) @ n - m.radius
    w0 = m.v0 @ n
    speed = np.sqrt(w0**2 + 2 * g * u0)
    first = (w0 + speed) / g
    order = np.argsort(t, kind="stable")
    sorted_t = t[order]
    rest = first + 2 * e * speed / (g * (1 - e)) if e < 1 else None
    last = _last_time_in_flight(sorted_t, rest, len(u0))
    vt = m.v0 - w0[:, None] * n
    mass = np.where(m.fixed, 0.0, m.mass).astype(float)
    kinetic, potential = _sums(
        sorted_t,
        u0,
        w0,
        first,
        e * speed,
        last,
        np.full(len(u0), np.inf) if rest is None else rest,
        e,
        g,
        mass,
        np.einsum("ij,ij->i", vt, vt),
        vt @ n,
        m.x0 @ m.gravity,
        vt @ m.gravity,
        float(n @ m.gravity),
    )
    ke, pe = np.empty(len(t)), np.empty(len(t))
    ke[order], pe[order] = kinetic, potential
    return t, ke, pe


@nb.njit(cache=True, nogil=True)
def _sums(t, u0, w0, first, launch, last, rest, e, g, mass, vt2, vtn, x0g, vtg, ng):  # pragma: no cover
    """Kinetic and potential energy (T,) at the sorted times ``t`` (T,), summed over the
    balls: per ball its heights above the plane ``u0``, normal speeds ``w0``, first
    bounces ``first``, first launch speeds ``launch``, last times read before rest
    ``last``, rest times ``rest`` (inf: none) (N,); restitution ``e``, gravity ``g`` along
    the plane's inward normal; masses, ``|vt|^2``, ``vt . n``, ``x0 . gravity`` and
    ``vt . gravity`` of each ball's tangential velocity ``vt`` (N,), and ``n . gravity``."""
    kinetic = np.zeros(len(t))
    potential = np.zeros(len(t))
    for i in range(len(u0)):
        bounced, at, leave = False, 0.0, 0.0
        nxt, nxt_launch, count, more = first[i], launch[i], 1, True
        for j in range(len(t)):
            tj = t[j]
            while more and nxt <= tj:
                bounced, at, leave = True, nxt, nxt_launch
                if at <= last[i] and leave > STOP_LAUNCH and count < STOP_COUNT:
                    nxt, nxt_launch, count = at + 2 * leave / g, leave * e, count + 1
                else:
                    more = False
            since = tj - (at if bounced else 0.0)
            start_u = 0.0 if bounced else u0[i]
            start_w = leave if bounced else w0[i]
            u = start_u + start_w * since - 0.5 * g * since**2
            w = start_w - g * since
            if tj >= rest[i]:
                u, w = 0.0, 0.0
            kinetic[j] += 0.5 * mass[i] * (vt2[i] + 2 * w * vtn[i] + w * w)
            potential[j] -= mass[i] * (x0g[i] + tj * vtg[i] + (u - u0[i]) * ng)
    return kinetic, potential
