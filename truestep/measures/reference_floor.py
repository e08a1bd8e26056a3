"""The error floor of a case measured against a run: how far the reference run itself is
from the motion, below which no row's error means anything.

A case with no closed form (``[reference] exact = "reference-run"``) measures every row
against a fine run of the reference implementation; that run has an error of its own, and
a method that converges stops improving at it (every adaptive solver at the same error is
the reference run's floor, not theirs). :func:`reference_floor` estimates it by a second
run of the same method, through the same error measure as the results' ``error`` column:

- a fixed-step method of order ``p`` at twice the reference step ``h``: its error against
  the reference run is ``(2^p - 1)`` times the reference run's own, to leading order
  (Richardson), so the floor is that error over ``2^p - 1``;
- an adaptive one at :data:`LOOSER` times its tolerance: its error against the reference
  run bounds the reference run's own from above (the floor is below it).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from truestep.cases.case import Case

LOOSER = 100.0
"""The tolerance of an adaptive reference run's second run, as a multiple of its own."""


@dataclasses.dataclass(frozen=True)
class ReferenceFloor:
    """A reference run's own error, in the units of the results' ``error`` column.

    method : the reference method of the case's reference run;  step : its step (s), or
    its tolerance where ``adaptive``;  other : the second run's step (``2 step``) or
    tolerance (``LOOSER step``);  difference : the second run's error against the
    reference run;  order : the method's order ``p`` (``None`` where adaptive);  floor :
    the reference run's own error, ``difference / (2^p - 1)`` (fixed step), or ``None``
    (adaptive: below ``difference``)
    """

    method: str
    step: float
    adaptive: bool
    other: float
    difference: float
    order: int | None
    floor: float | None

    def _ratio_words(self) -> str:
        """How many times a method of this order at twice the step errs more than at the
        step: 2^p - 1 ("as much as" for order 1)."""
        ratio = 2 ** (self.order or 1) - 1
        return "as much as" if ratio == 1 else f"{ratio} times"

    def words(self) -> str:
        """The note the report gives the case."""
        if self.floor is not None and self.order is not None:
            return (
                f"Error floor: the errors here are measured against a run of the reference's "
                f"`{self.method}` at {self.step:.4g} s, whose own error is about {self.floor:.2g} "
                f"(the same method at {self.other:.4g} s differs from it by {self.difference:.2g}, "
                f"{self._ratio_words()} the error of a method of order {self.order} at half the "
                "step): an error below that says nothing of a run.\n"
            )
        return (
            f"Error floor: the errors here are measured against a run of the reference's "
            f"`{self.method}` at tolerance {self.step:.3g}, whose own error is below "
            f"{self.difference:.2g} (the same solver at {self.other:.3g} differs from it by that "
            "much): an error below that says nothing of a run.\n"
        )


def reference_floor(case: Case) -> ReferenceFloor | None:
    """The reference run's own error of a ``reference-run`` case (``None`` for any other
    case, and where either run fails)."""
    if case.exact != "reference-run":
        return None
    from truestep.adapters.base import facts_of
    from truestep.adapters.reference import ReferenceAdapter
    from truestep.measures import metrics

    adapter = ReferenceAdapter()
    method = str(case.exact_params.get("method", "dopri5"))
    adaptive = method in adapter.adaptive_methods
    step = float(case.exact_params.get("rtol", 1e-12) if adaptive else case.exact_params["dt"])
    other = step * LOOSER if adaptive else 2 * step
    try:
        run = adapter.simulate(case, method, other)
        if run.status != "ok":
            return None
        exact = metrics.exact_for(case, run.t)
        if exact is None:
            return None
        difference = metrics.position_error(case, run, exact)
    except Exception:  # the reference run itself failed: the case's rows say so
        return None
    if not np.isfinite(difference):
        return None
    order = None if adaptive else getattr(facts_of(adapter, method), "order", None)
    floor = None if not order else difference / (2.0**order - 1.0)
    return ReferenceFloor(method, step, adaptive, other, float(difference), order, floor)
