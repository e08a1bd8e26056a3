"""The solver base class: the one place where derivative evaluations are counted."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import ClassVar

import numpy as np

from truestep.reference_impl.solvers.facts import MethodFacts
from truestep.reference_impl.system import SecondOrderSystem, System


class SolverFailed(Exception):
    """A step whose equations the solver could not solve (an implicit method's Newton
    iteration found no solution): not a blow-up of the motion, and never read as one.
    The run stops with status ``solver-failed`` and this message."""


class Solver(ABC):
    """A one-step solver written only against :class:`~truestep.reference_impl.system.System`.

    A subclass must:

    1. implement :meth:`step`, which reads the state with ``system.get_state()`` and
       ``system.get_time()``, and writes the new one with ``system.set_state``;
    2. evaluate the right-hand side only through :meth:`fun` (or :meth:`accel` for
       second-order systems), so that :attr:`nfev` counts every evaluation;
    3. set ``adaptive = True`` if it chooses its own step sizes; then :meth:`step` takes
       the largest step it may try and returns the step it actually took;
    4. declare its :class:`~truestep.reference_impl.solvers.facts.MethodFacts` as the
       class attribute ``facts`` (order, evaluations per step, symplectic, stability);
       ``order`` is set from it.
    """

    name: str = ""
    facts: ClassVar[MethodFacts]
    order: ClassVar[int] = 0
    """``facts.order``, set when a subclass declares its facts."""
    adaptive: bool = False
    needs_second_order: bool = False

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        facts = cls.__dict__.get("facts")
        if facts is not None:
            cls.order = facts.order

    def __init__(self, system: System) -> None:
        if self.needs_second_order and not isinstance(system, SecondOrderSystem):
            raise TypeError(f"{self.name} needs a system with a position/velocity split")
        self.system = system
        self.nfev = 0
        self._derivative: Callable[[np.ndarray, float], np.ndarray] = system.derivative

    def fun(self, x: np.ndarray, t: float) -> np.ndarray:
        """Evaluate ``f(x, t)`` of the system, counting the evaluation."""
        self.nfev += 1
        return self._derivative(x, t)

    def use_compiled_derivative(self) -> bool:
        """Evaluate :meth:`fun` by the system's compiled twin of its derivative
        (:meth:`~truestep.reference_impl.system.System.compiled_derivative`: the same bits,
        a fraction of the cost) from here on, where it has one; whether it has. For a run
        whose stepping has no compiled loop (implicit Euler's Newton iteration): the
        numpy derivative stays the spec and the oracle, and a solver made without this
        call evaluates it. The twin takes the system's parameters as they are now."""
        fast = self.system.compiled_derivative()
        if fast is not None:
            self._derivative = fast
        return fast is not None

    def accel(self, q: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
        """Evaluate ``a(q, v, t)`` of a second-order system, counting the evaluation."""
        self.nfev += 1
        return self.system.acceleration(q, v, t)  # type: ignore[attr-defined]

    @abstractmethod
    def step(self, dt: float) -> float:
        """Advance the system by one step of ``dt`` seconds; return the step taken."""
