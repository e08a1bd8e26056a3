"""The right-hand sides of :mod:`~truestep.reference_impl.odes`, compiled.

Each kernel writes ``dy/dt`` of a flat state ``y`` (dim,) into ``out`` (dim,) with the
arithmetic of its system's :meth:`~truestep.reference_impl.system.System.derivative`, in
the same order, so that both give the same bits (tested on random states far from and
near the orbits). Python's ``x ** 2`` calls the C library's ``pow``, which does not always
round as ``x * x`` does: the kernels take the exponent as an argument (``two``), which the
compiler cannot fold into a product, so that they call ``pow`` too. The systems hand them
out through :meth:`~truestep.reference_impl.system.System.compiled_derivative`, for the
integrators outside truestep that call a derivative back at every evaluation (Drake's,
scipy's).
"""

from __future__ import annotations

import math
from typing import Any

from numba import njit

ODE: dict[str, Any] = {"cache": True, "error_model": "numpy"}
"""How a right-hand side is compiled: on its own, cached, called from Python."""
KEPLER, ARENSTORF, CIRCLE = 0, 1, 2
"""Which right-hand side the compiled loop calls (:func:`rhs`)."""


@njit(**ODE)
def kepler(y, t, out, mu):
    """``q' = v, v' = -mu q / |q|^3`` in the plane: :meth:`odes.KeplerProblem.derivative`."""
    q0, q1 = y[0], y[1]
    r2 = q0 * q0 + q1 * q1
    s = -mu / (r2 * math.sqrt(r2))
    out[0], out[1] = y[2], y[3]
    out[2], out[3] = q0 * s, q1 * s
    return out


@njit(**ODE)
def arenstorf(y, t, out, mu, two):
    """The restricted three-body problem in the rotating frame:
    :meth:`odes.Arenstorf.derivative` (``two`` = 2.0, see the module docstring)."""
    nu = 1.0 - mu
    x, z = y[0], y[1]
    r1 = (x + mu) ** two + z * z
    r2 = (x - nu) ** two + z * z
    d1 = r1 * math.sqrt(r1)
    d2 = r2 * math.sqrt(r2)
    out[0], out[1] = y[2], y[3]
    out[2] = x + 2 * y[3] - nu * (x + mu) / d1 - mu * (x - nu) / d2
    out[3] = z - 2 * y[2] - nu * z / d1 - mu * z / d2
    return out


@njit(**ODE)
def circle(y, t, out):
    """The lecture's field ``x' = (-y, x)``: :meth:`odes.CircleField.derivative`."""
    out[0], out[1] = -y[1], y[0]
    return out


@njit(**ODE)
def rhs(system, y, t, out, params):
    """``dy/dt`` of the ``system`` named by :data:`KEPLER`, :data:`ARENSTORF` or
    :data:`CIRCLE`, into ``out``; ``params`` (float64) its constants as its system's
    ``rhs_kernel`` gives them."""
    if system == KEPLER:
        return kepler(y, t, out, params[0])
    if system == ARENSTORF:
        return arenstorf(y, t, out, params[0], params[1])
    return circle(y, t, out)
