"""The compiled path equals the numpy reference on every case and method it runs.

The numpy :class:`~truestep.reference_impl.particles.ParticleSystem`, the solver classes
and :func:`~truestep.reference_impl.integrate.integrate` are the oracle. Each case runs
its largest swept step for at most 300 steps both ways: the same status, records, steps
and evaluations, and the same states to round-off. Tolerance: 1e-12 of the state's size
(the compiled sums run in another order than numpy's BLAS products, about 1e-16 a step;
a bounded run cannot build that up beyond 1e-13 in 300 steps), absolute for runs that
blew up (their states are huge and only the status and the count must agree).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from truestep.adapters.reference import ReferenceAdapter
from truestep.cases import load_cases
from truestep.reference_impl.compiled import compiled_reason, independent

METHODS = ["euler", "midpoint", "heun", "rk4", "symplectic-euler", "verlet", "lecture"]
CASES = [c for c in load_cases("*") if compiled_reason(c.model, "rk4") is None]
ROUND_OFF = 1e-12


def test_every_particle_case_but_fields_and_emitters_is_compiled():
    names = {c.name for c in load_cases("*") if c.model is not None}
    assert names - {c.name for c in CASES} == {"hair-strands", "particle-fountain"}
    assert {c.name for c in CASES if independent(c.model)} >= {"particle-rain", "bouncing-ball"}


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_compiled_equals_numpy(case):
    dt = case.dts[0]
    short = dataclasses.replace(case, duration=min(case.duration, 300 * case.steps_for(dt)[1]))
    for method in METHODS:
        fast = ReferenceAdapter().simulate(short, method, dt)
        slow = ReferenceAdapter(compiled=False).simulate(short, method, dt)
        label = f"{case.name}/{method}"
        assert (fast.path, slow.path) == ("compiled", "numpy"), label
        assert fast.status == slow.status, label
        assert (fast.steps, fast.nfev, len(fast.t)) == (slow.steps, slow.nfev, len(slow.t)), label
        np.testing.assert_array_equal(fast.t, slow.t, err_msg=label)
        if fast.status == "ok":
            size = max(1.0, float(np.max(np.abs(slow.x))), float(np.max(np.abs(slow.v))))
            np.testing.assert_allclose(fast.x, slow.x, rtol=0, atol=ROUND_OFF * size, err_msg=label)
            np.testing.assert_allclose(fast.v, slow.v, rtol=0, atol=ROUND_OFF * size, err_msg=label)
            np.testing.assert_allclose(fast.energy, slow.energy, rtol=1e-9, atol=ROUND_OFF * size,
                                       err_msg=label)
        else:
            assert fast.t_fail == slow.t_fail, label


def test_fields_and_emitters_run_on_the_numpy_path(case_named):
    traj = ReferenceAdapter().simulate(case_named("hair-strands"), "lecture", 1 / 150)
    assert traj.path == "numpy"
    assert compiled_reason(case_named("hair-strands").model, "lecture") == "emitters"
    assert compiled_reason(None, "rk4").startswith("an ODE case")
    assert "not a fixed-step explicit method" in compiled_reason(case_named("free-fall").model,
                                                                 "implicit-euler")
