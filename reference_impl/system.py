"""The lecture's modular solver interface.

"Generic operations: get dim(x); get/set x and t; deriv eval at current (x, t).
Write solvers in terms of these." Every solver in :mod:`truestep.reference_impl.solvers`
talks to a system through this interface and nothing else.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable

import numpy as np


class System(ABC):
    """A first-order ODE system ``dx/dt = f(x, t)`` as the lecture's solvers see it.

    A subclass must:

    1. set ``dim``, the length of the flat state vector ``x``;
    2. keep its state and time, returned by :meth:`get_state` as a copy and replaced by
       :meth:`set_state` (the system may keep richer structured state behind it, but the
       flat vector is what solvers see);
    3. implement :meth:`derivative` as a pure function of its arguments: it returns a new
       array of shape ``(dim,)`` and never changes the stored state;
    4. optionally implement :meth:`jacobian` (``(dim, dim)``), used by implicit solvers;
       returning ``None`` makes them fall back to finite differences; and
       :meth:`compiled_derivative`, the same derivative compiled;
    5. optionally implement :meth:`energy` (total energy in joules, or ``None``) and
       :meth:`between_steps`, the place for collisions, emitters and lifetimes, which the
       lecture applies between solver steps, never inside one; and :meth:`observe`, extra
       arrays recorded with every stored state.
    """

    dim: int

    def __init__(self, x0: np.ndarray, t0: float = 0.0) -> None:
        self._x = np.array(x0, dtype=float).reshape(-1)
        self._t = float(t0)
        self.dim = self._x.size

    def get_state(self) -> np.ndarray:
        """Return a copy of the flat state vector, shape ``(dim,)``."""
        return self._x.copy()

    def get_time(self) -> float:
        """Return the current time in seconds."""
        return self._t

    def set_state(self, x: np.ndarray, t: float) -> None:
        """Replace the state with ``x`` (shape ``(dim,)``) at time ``t`` seconds."""
        x = np.asarray(x, dtype=float)
        if x.shape != (self.dim,):
            raise ValueError(f"set_state: x has shape {x.shape}, expected ({self.dim},)")
        self._x = x.copy()
        self._t = float(t)

    @abstractmethod
    def derivative(self, x: np.ndarray, t: float) -> np.ndarray:
        """Return ``dx/dt`` at ``(x, t)``, shape ``(dim,)``; must not modify ``x``."""

    def jacobian(self, x: np.ndarray, t: float) -> np.ndarray | None:
        """Return ``df/dx`` at ``(x, t)``, shape ``(dim, dim)``, or ``None`` if unknown."""
        return None

    def compiled_derivative(self) -> Callable[[np.ndarray, float], np.ndarray] | None:
        """A compiled function of ``(x, t)`` that returns :meth:`derivative`'s value bit for
        bit, faster, for integrators that call it at every evaluation (Drake's, scipy's);
        ``None`` (default) where there is none. Its parameters are those the system has now."""
        return None

    def rhs_kernel(self) -> tuple[int, tuple[float, ...]] | None:
        """Which compiled right-hand side of :mod:`~truestep.reference_impl.odes_kernels`
        is this system's :meth:`derivative` bit for bit, and its constants (for the
        compiled loop of :mod:`~truestep.reference_impl.odes_loop`); ``None`` (default)
        where none is: truestep's own systems name theirs, a user's system runs on the
        numpy path."""
        return None

    def energy(self, x: np.ndarray, t: float) -> float | None:
        """Return the total energy (J) at ``(x, t)``, or ``None`` if it has no meaning."""
        return None

    def between_steps(self, dt: float) -> None:
        """Apply discrete events after a solver step of ``dt`` seconds (default: none)."""
        return None

    def next_pass_time(self) -> float:
        """When :meth:`between_steps` is next scheduled to act, s (an emitter's next frame):
        an adaptive step ends there, so that the pass acts at its instant and not at the
        end of a longer step. ``inf`` (default) where nothing is scheduled."""
        return math.inf

    def observe(self) -> dict[str, np.ndarray]:
        """Per-record observables beyond the state (e.g. which particles are alive)."""
        return {}

    def event_watch(self) -> Callable[[np.ndarray], np.ndarray] | None:
        """The events an adaptive step must stop at, for the step about to be taken: a
        function of a state (dim,) whose components change sign from ``>= 0`` to ``< 0``
        where an event happens (a particle reaching a plane), or ``None`` (default: no
        events). An adaptive solver with a continuous extension stops its step at the
        first such change and :meth:`between_steps` acts there (``located = True``)."""
        return None


class SecondOrderSystem(System):
    """A system ``q'' = a(q, v, t)`` with state layout ``x = [q, v]``, each of ``dim // 2``.

    Besides the :class:`System` contract, a subclass must implement
    :meth:`acceleration`. Splitting methods (symplectic Euler, velocity Verlet and the
    lecture's update) step ``q`` and ``v`` separately through it; all other solvers
    see the derivative ``[v, a(q, v, t)]``.
    """

    @property
    def half(self) -> int:
        """Number of position coordinates, ``dim // 2``."""
        return self.dim // 2

    @abstractmethod
    def acceleration(self, q: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
        """Return ``q''`` at positions ``q`` and velocities ``v``, both shape ``(dim//2,)``."""

    def derivative(self, x: np.ndarray, t: float) -> np.ndarray:
        half = self.dim // 2
        out = np.empty(self.dim)
        out[:half] = x[half:]
        out[half:] = self.acceleration(x[:half], x[half:], t)
        return out
