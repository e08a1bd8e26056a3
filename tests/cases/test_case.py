"""A case carries one scene, typed by its kind (``cases/case.py``): a particle scene or an
ODE, each with its own state shape and features; an ODE run's states have their own
field, ``y`` (T, dim), in every engine that runs one and in every exact solution."""

from __future__ import annotations

import numpy as np
import pytest

from truestep.adapters import get_adapter
from truestep.cases.case import OdeSpec
from truestep.cases.exact import EXACT
from truestep.cases.loader import load_cases
from truestep.reference_impl.model import ParticleModel

CASES = load_cases("*")
ODE_CASES = [c for c in CASES if isinstance(c.scene, OdeSpec)]
QUICK_ODE_CASES = [c for c in ODE_CASES if c.in_quick]  # long-orbit's 1000 periods: 8 s for no more


def test_every_case_carries_one_scene_and_its_kind_follows_from_it():
    assert ODE_CASES and len(ODE_CASES) < len(CASES)
    for case in CASES:
        match case.scene:
            case OdeSpec() as ode:
                assert (case.kind, case.model, case.ode, case.bodies) == ("ode", None, ode, 1)
                assert case.features == ode.features() and "ode" in case.features
                with pytest.raises(TypeError, match="no particle scene"):
                    getattr(case, "particles")  # noqa: B009
            case ParticleModel() as model:
                assert (case.kind, case.ode, case.model, case.bodies) == ("particles", None, model, model.n)
                assert case.features == model.features() and "ode" not in case.features
                with pytest.raises(TypeError, match="no ODE"):
                    getattr(case, "ode_spec")  # noqa: B009
            case other:
                pytest.fail(f"{case.name}: a scene of type {type(other).__name__}")


RUNS = [("reference", "rk4"), ("reference", "dopri5"), ("scipy", "DOP853")]


@pytest.mark.parametrize(("engine", "method"), RUNS)
@pytest.mark.parametrize("case", QUICK_ODE_CASES, ids=lambda c: c.name)
def test_an_ode_run_carries_its_states_in_y(case, engine, method):
    """``y`` is (T, dim), starts at the case's ``y0``, and the old layout ``x`` is a view
    of it."""
    adapter = get_adapter(engine)
    adaptive = method in adapter.adaptive_methods
    if adapter.missing(case, method):
        pytest.skip(f"{engine}/{method} cannot run {case.name}")
    dt = case.sweep(adaptive=adaptive, quick=True)[-1]
    traj = adapter.simulate(case, method, dt)
    assert traj.y is not None and traj.y.shape == (len(traj.t), case.ode_spec.dim)
    assert traj.v is None and traj.x.shape == (len(traj.t), 1, case.ode_spec.dim)
    assert np.shares_memory(traj.x, traj.y)
    np.testing.assert_array_equal(traj.y[0], case.ode_spec.y0)


@pytest.mark.parametrize("case", ODE_CASES, ids=lambda c: c.name)
def test_every_ode_exact_solution_gives_states_in_y(case):
    if case.exact not in EXACT:
        pytest.skip(f"{case.name}: no closed-form exact solution")
    exact = EXACT[case.exact](case, np.array([0.0]))
    if len(exact.t):
        assert exact.y is not None and exact.y.shape == (1, case.ode_spec.dim)
        np.testing.assert_allclose(exact.y[0], case.ode_spec.y0, rtol=1e-12, atol=1e-12)
