"""Closed forms the exact solutions are built from: the damped oscillator and the Kepler
orbit, functions of plain numbers and times (no case, no scene)."""

from __future__ import annotations

import numpy as np


def oscillator(m: float, k: float, c: float, u0: float, w0: float, t: np.ndarray):
    """Displacement and velocity of ``m u'' + c u' + k u = 0`` from ``u(0)=u0, u'(0)=w0``.

    Handles under-, critically and over-damped cases; ``m`` kg, ``k`` N/m, ``c`` N s/m.
    """
    omega0 = np.sqrt(k / m)
    zeta = c / (2.0 * np.sqrt(k * m))
    if zeta < 1.0:
        wd = omega0 * np.sqrt(1.0 - zeta**2)
        a = zeta * omega0
        B = (w0 + a * u0) / wd
        e = np.exp(-a * t)
        u = e * (u0 * np.cos(wd * t) + B * np.sin(wd * t))
        du = e * ((-a * u0 + B * wd) * np.cos(wd * t) + (-a * B - u0 * wd) * np.sin(wd * t))
    elif zeta == 1.0:
        a = omega0
        B = w0 + a * u0
        e = np.exp(-a * t)
        u = e * (u0 + B * t)
        du = e * (B - a * (u0 + B * t))
    else:
        r = omega0 * np.sqrt(zeta**2 - 1.0)
        l1, l2 = -zeta * omega0 + r, -zeta * omega0 - r
        A = (w0 - l2 * u0) / (l1 - l2)
        B = u0 - A
        u = A * np.exp(l1 * t) + B * np.exp(l2 * t)
        du = A * l1 * np.exp(l1 * t) + B * l2 * np.exp(l2 * t)
    return u, du


def kepler_state(e: float, mu: float, a: float, t: np.ndarray) -> np.ndarray:
    """State ``(x, y, vx, vy)`` at times ``t`` of a Kepler orbit starting at pericentre.

    Solves Kepler's equation ``E - e sin E = n t`` by Newton's method to machine
    precision; semi-major axis ``a``, mean motion ``n = sqrt(mu / a^3)``.
    """
    n = np.sqrt(mu / a**3)
    M = np.mod(n * t, 2 * np.pi)
    E = M + e * np.sin(M) if e < 0.8 else np.full_like(M, np.pi)
    for _ in range(50):
        dE = (E - e * np.sin(E) - M) / (1 - e * np.cos(E))
        E = E - dE
        if np.max(np.abs(dE)) < 1e-15:
            break
    b = a * np.sqrt(1 - e**2)
    denom = 1 - e * np.cos(E)
    x = a * (np.cos(E) - e)
    y = b * np.sin(E)
    vx = -a * n * np.sin(E) / denom
    vy = b * n * np.cos(E) / denom
    return np.stack([x, y, vx, vy], axis=1)
