"""What is known about an integration method, as data: order, cost, symplecticity, stability.

Every reference solver carries a :class:`MethodFacts` as its class attribute ``facts``,
and every engine adapter declares one for each of its methods (or names the reference
method whose facts it shares). The harness reads them; nothing keys a table by method
names.

Stability is stated on the **linear test system**

    q'' = -omega^2 q - c q'        (a spring of angular frequency omega, s^-1, and a
                                    damper of rate c, s^-1, the scene's own damper)

for which one step of ``h`` seconds is a linear map of the state ``(q, h v)`` (and of
whatever the method carries from one step to the next) that depends only on
``a = (omega h)^2`` and ``b = c h``. A mode with damping ratio ``zeta`` has
``b = 2 zeta omega h``; an undamped one (``b = 0``) has eigenvalues ``+-i omega``, on the
imaginary axis of the complex plane of ``lambda h``; pure damping (``a = 0``) decays at
the real rate ``-c``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

StepMatrix = Callable[[float, float], np.ndarray]
"""``(a, b) -> M``: one step on the test system, ``a = (omega h)^2``, ``b = c h``
(dimensionless). ``M`` is square, ``(k, k)`` with ``k >= 2``, acting on ``(q, h v)``
followed by what the method keeps between steps (velocity Verlet: ``h^2`` times the
acceleration it reuses)."""

SCAN_MAX = 1e6
"""The largest ``omega h`` a stability scan looks at; a method stable up to it counts as
stable at every step (no step that large is ever searched: ``dt_hi`` is at most 1 s)."""
SCAN_MIN = 1e-6
"""The smallest ``omega h`` a scan looks at: a damped mode's spectral radius is
``1 - zeta omega h`` there, below 1 by far more than round-off for damping ratios from
about 1e-6 (a convergent method cannot grow there for any)."""
SCAN_PER_DECADE = 200
"""Grid points per decade of ``omega h`` before a bracket is refined: 1.2% apart, finer
than any feature of the stability regions here."""
RADIUS_TOL = 1e-12
"""A spectral radius above ``1 + RADIUS_TOL`` is growth. Round-off in the eigenvalues of a
small matrix is about 1e-15; growth slower than 1e-12 per step doubles in 1e12 steps."""


def spectral_radius(m: np.ndarray) -> float:
    """The largest eigenvalue magnitude of a square matrix (dimensionless)."""
    return float(np.max(np.abs(np.linalg.eigvals(np.asarray(m, float)))))


def first_growth(radius: Callable[[float], float], *, lo: float = SCAN_MIN, hi: float = SCAN_MAX) -> float:
    """The smallest ``x`` in ``[lo, hi]`` where ``radius(x)`` exceeds ``1 + RADIUS_TOL``.

    Scans a geometric grid (:data:`SCAN_PER_DECADE`) and refines the first bracket by
    Brent's method to 1e-14 relative, to where the radius crosses 1 itself when the
    bracket's stable end lies below 1 (a damped mode's does), else to where it crosses
    ``1 + RADIUS_TOL``. Returns ``0.0`` if ``radius(lo)`` already grows and ``inf`` if
    nothing in the range does.
    """
    from scipy.optimize import brentq  # here, not at import: scipy.optimize is a third of a second

    grid = [float(x) for x in np.geomspace(lo, hi, int(SCAN_PER_DECADE * np.log10(hi / lo)) + 1)]
    grows = next((k for k, x in enumerate(grid) if radius(x) > 1.0 + RADIUS_TOL), None)
    if grows is None:
        return float("inf")
    if grows == 0:
        return 0.0
    stable, unstable = grid[grows - 1], grid[grows]
    level = 1.0 if radius(stable) < 1.0 else 1.0 + RADIUS_TOL
    return float(brentq(lambda y: radius(y) - level, stable, unstable, xtol=1e-300, rtol=1e-14))


@dataclass(frozen=True)
class Stability:
    """Where a method is stable on the linear test system (module docstring).

    imaginary : float
        The method is stable on the undamped oscillator for every ``omega h`` in
        ``[0, imaginary)``: the half-length of the segment of the imaginary axis in its
        stability region. ``0``: unstable at every step; ``inf``: stable at every step.
    real : float
        Stable under pure damping for every ``c h`` in ``[0, real]`` (for a first-order
        method, on ``y' = -c y``): the length of the segment ``[-real, 0]`` of the
        negative real axis in its stability region; ``inf``: stable at every step.
    a_stable : bool
        Stable for every step on every undamped or damped mode (the whole left
        half-plane); then ``imaginary`` and ``real`` are ``inf``.
    step_matrix : StepMatrix or None
        The one-step map on the test system (:data:`StepMatrix`): the whole stability
        region, from which the limit on a damped mode follows. ``None``: not declared
        (limits on damped modes are then unknown).
    """

    imaginary: float
    real: float
    a_stable: bool = False
    step_matrix: StepMatrix | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if not (self.imaginary >= 0 and self.real >= 0):
            raise ValueError(
                f"Stability: imaginary={self.imaginary} and real={self.real} "
                "must be non-negative (inf for every step)"
            )
        if self.a_stable and not (np.isinf(self.imaginary) and np.isinf(self.real)):
            raise ValueError("Stability: an A-stable method has imaginary = real = inf")

    def radius(self, omega_h: float, zeta: float) -> float:
        """Spectral radius of one step on a mode of ``omega h`` and damping ratio ``zeta``."""
        if self.step_matrix is None:
            raise ValueError("Stability.radius: no step_matrix declared")
        return spectral_radius(self.step_matrix(omega_h**2, 2.0 * zeta * omega_h))

    def reach(self, zeta: float) -> float | None:
        """The largest ``omega h`` below which every step is stable on a mode with damping
        ratio ``zeta`` (dimensionless; ``0.0`` none, ``inf`` every step), or ``None`` if
        the declared data do not say.

        Undamped: :attr:`imaginary`. Damped (``zeta > 0``, under- or overdamped): the first
        ``omega h`` where the spectral radius of :attr:`step_matrix` exceeds 1
        (:func:`first_growth`), to 1e-14 relative; near ``zeta = 1`` (a double eigenvalue,
        which round-off splits by its square root) to about 1e-8.
        """
        if not np.isfinite(zeta) or zeta < 0:
            return None
        if self.a_stable:
            return float("inf")
        if zeta == 0:
            return float(self.imaginary)
        if self.step_matrix is None:
            return None
        return first_growth(lambda y: self.radius(y, zeta))


@dataclass(frozen=True)
class MethodFacts:
    """The facts of one integration method that the harness gates and reports on.

    order : int
        Order of convergence in the step ``h`` on smooth problems whose forces depend on
        positions (and time) only: the global error falls as ``h^order``.
    evaluations_per_step : int or None
        Derivative (force) evaluations one step makes (for an adaptive method, one
        accepted step); ``None`` when it varies (Newton iterations). Engines that hide
        their evaluations report ``nfev`` as steps times this.
    symplectic : bool
        Whether a step is a symplectic map for forces that depend on positions only.
    stability : Stability or None
        Where it is stable on the linear test system; ``None``: unknown.
    velocity_order : int or None
        The order when forces also depend on velocity (dampers, drag, Coriolis terms);
        ``None``: the same as :attr:`order`. Splitting methods that read the velocity
        explicitly inside a kick (velocity Verlet, leapfrog) drop to 1.
    exact_constant_acceleration : bool or None
        Whether it reproduces motion under a constant acceleration (positions quadratic
        in time) exactly, to round-off; ``None``: as ``order >= 2`` says (every
        Runge-Kutta method of order 2 or more is exact there). The lecture's update is
        exact there though of order 1; symplectic Euler is not.
    """

    order: int
    evaluations_per_step: int | None
    symplectic: bool
    stability: Stability | None = None
    velocity_order: int | None = None
    exact_constant_acceleration: bool | None = None

    def __post_init__(self) -> None:
        for name in ("order", "velocity_order"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
                raise ValueError(f"MethodFacts.{name}: a positive integer, got {value!r}")
        e = self.evaluations_per_step
        if e is not None and (isinstance(e, bool) or not isinstance(e, int) or e < 1):
            raise ValueError(f"MethodFacts.evaluations_per_step: a positive integer or None, got {e!r}")

    @classmethod
    def like(cls, method: str, **changes: object) -> MethodFacts:
        """The facts of the reference method ``method`` with ``changes`` (field -> value):
        ``MethodFacts.like("verlet", velocity_order=2)`` for a velocity Verlet that keeps
        its order with dampers."""
        if method not in NAMED:
            raise KeyError(f"unknown method {method!r}; known: {', '.join(NAMED)}")
        return dataclasses.replace(NAMED[method], **changes)  # type: ignore[arg-type]

    def order_for(self, *, velocity_forces: bool) -> int:
        """The declared order on a problem whose forces do (or do not) depend on velocity."""
        if velocity_forces and self.velocity_order is not None:
            return self.velocity_order
        return self.order

    @property
    def exact_when_acceleration_is_constant(self) -> bool:
        """:attr:`exact_constant_acceleration`, with its default resolved."""
        if self.exact_constant_acceleration is None:
            return self.order >= 2
        return self.exact_constant_acceleration


NAMED: dict[str, MethodFacts] = {}
"""The facts of the reference's methods by name (:meth:`MethodFacts.like` reads them),
filled by :mod:`truestep.reference_impl.solvers`, this module's package, as it loads."""
