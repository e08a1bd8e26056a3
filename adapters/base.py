"""The Adapter protocol and the Trajectory every adapter returns."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from truestep.cases.case import Case

STATUSES = ("ok", "unstable", "crashed", "timeout", "unsupported", "skipped")


@dataclass
class Trajectory:
    """A run, in the same shape and units whichever engine produced it.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Recorded times, s, starting with the initial state.
    x : ndarray, shape (T, n, 3)
        Positions read back from the engine, m. ODE scenes store their whole state as
        ``(T, 1, dim)``.
    v : ndarray, shape (T, n, 3), or None
        Velocities, m/s (``None`` for ODE scenes, whose state is in ``x``).
    energy : ndarray, shape (T,), or None
        Total energy, J, computed from the read-back state by the same function for every
        engine (:func:`truestep.reference_impl.particles.total_energy`).
    alive : ndarray of bool, shape (T, n), or None
        Which particles exist at each record (scenes with emitters).
    status : str
        ``ok``; ``unstable`` (non-finite or runaway state, at ``t_fail``); ``crashed``;
        ``timeout``.
    t_fail : float or None
        Time at which a run became unstable, s.
    nfev : int
        Derivative evaluations, or engine steps where the engine hides them.
    steps : int
        Steps taken.
    wall_s : float
        Seconds spent stepping (scene building excluded).
    message : str
        What went wrong, or notes the engine wants in the table.
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray | None
    energy: np.ndarray | None
    status: str = "ok"
    t_fail: float | None = None
    nfev: int = 0
    steps: int = 0
    wall_s: float = float("nan")
    message: str = ""
    alive: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)


@runtime_checkable
class Adapter(Protocol):
    """One engine behind the harness.

    An adapter must:

    1. have a ``name`` (the engine's name in the tables: ``reference``, ``scipy``,
       ``pymunk``, ``pybullet``, ``mujoco``) and ``methods``, the names of the
       integrators it offers, with ``adaptive_methods`` the subset whose ``dt`` is a
       tolerance;
    2. declare ``capabilities``, the features of :meth:`ParticleModel.features` (and
       ``ode``, ``second-order``) it can model; :meth:`missing` names what a case needs
       beyond them, and may refine that per method;
    3. in :meth:`simulate`, build the scene outside the timed region, step it for
       ``case.duration`` seconds with step ``dt`` (or tolerance ``dt`` for an adaptive
       method), read the engine's own state back at every recorded step, and return a
       :class:`Trajectory` whose ``wall_s`` covers the stepping only;
    4. report a blow-up as status ``unstable`` with ``t_fail``, never raise for it;
    5. import its engine only inside its own module;
    6. optionally, ``duplicate(case, method)``: the reason a method would compute bit for
       bit what another of its methods computes on ``case`` (the harness then skips it
       with that reason), or ``None``.
    """

    name: str
    methods: tuple[str, ...]
    adaptive_methods: tuple[str, ...]
    capabilities: frozenset[str]

    def missing(self, case: Case, method: str) -> set[str]:
        """Features ``case`` needs that this adapter cannot model with ``method``."""
        ...

    def simulate(self, case: Case, method: str, dt: float) -> Trajectory:
        """Run ``case`` with ``method`` at step (or tolerance) ``dt``."""
        ...


def finite_until(x: np.ndarray, t: np.ndarray, limit: float = 1e12) -> tuple[str, float | None]:
    """Status of recorded positions ``x`` (T, ...): ``ok`` or ``unstable`` at the first bad time."""
    flat = np.abs(x.reshape(len(x), -1))
    bad = ~np.all(np.isfinite(flat), axis=1) | (np.nanmax(np.where(np.isfinite(flat), flat, np.inf),
                                                          axis=1, initial=0.0) > limit)
    if not np.any(bad):
        return "ok", None
    return "unstable", float(t[int(np.argmax(bad))])
