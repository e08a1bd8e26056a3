"""The registry of exact solutions: what one returns (:class:`Exact`) and how one is
registered (:func:`exact_solution`). The solutions themselves live in
:mod:`truestep.cases.exact` (ODE and general ones) and :mod:`truestep.cases.exact_particles`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from truestep.cases.case import Case


@dataclass
class Exact:
    """Exact positions (and velocities, energy where known) at times ``t`` (s).

    t : (T,) s;  x : (T, n, 3) m;  v : (T, n, 3) m/s or ``None``;  energy : (T,) J or
    ``None``;  y : (T, dim), an ODE's exact states (``None`` for particle scenes; then
    ``x`` is ``y[:, None, :]``, the layout before ``y``). Build an ODE's with
    :meth:`of_ode`.
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray | None = None
    energy: np.ndarray | None = None
    y: np.ndarray | None = None

    @classmethod
    def of_ode(cls, t: np.ndarray, y: np.ndarray, energy: np.ndarray | None = None) -> Exact:
        """An ODE's exact states ``y`` (T, dim) at times ``t`` (T,) s, energy (T,) J or ``None``."""
        y = np.asarray(y)
        return cls(t, y[:, None, :], None, energy, y)


ExactFn = Callable[[Case, np.ndarray], Exact]
EXACT: dict[str, ExactFn] = {}


def exact_solution(
    name: str,
    *,
    check: Callable[[Case], None] | None = None,
    params: dict[str, str] | None = None,
    kind: str | None = None,
    energy: bool | None = None,
) -> Callable[[ExactFn], ExactFn]:
    """Register an exact solution under ``name``.

    When a case names it, the loader checks that it fits the scene: by ``check(case)``
    (which raises ``ValueError`` saying what does not fit) when given, else by
    evaluating the solution at ``t = 0``, which must raise the same way or return the
    case's start. ``params`` declares the ``[reference]`` parameters it reads (name ->
    ``"positive"``, ``"nonnegative"``, ``"count"`` or ``"string"``): the loader checks
    each and refuses any other; without it, any plain number, string or boolean passes.
    ``kind`` (``"ode"`` or ``"particles"``) is the kind of case it solves, if only one.
    ``energy`` says whether it gives the energy along the motion (``Exact.energy``), the
    curve a dissipative case's energy drift is measured against: ``None`` (default) when
    the loader should find out from its value at ``t = 0``.
    """

    def register(fn: ExactFn) -> ExactFn:
        if check is not None:
            fn.check = check  # type: ignore[attr-defined]
        fn.params = params  # type: ignore[attr-defined]
        fn.kind = kind  # type: ignore[attr-defined]
        fn.energy = energy  # type: ignore[attr-defined]
        EXACT[name] = fn
        return fn

    return register
