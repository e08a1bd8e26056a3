"""The property audit's counting wrappers, around every test module of this folder."""

from __future__ import annotations

import pytest
from audit_runs import _RUNS, _counted_twin, _counting


@pytest.fixture(scope="module", autouse=True)
def counted_evaluations():
    """Wrap what does the work, to count it: the reference's derivative (every solver and
    scipy's RHS reach a particle system through ``acceleration``, ODE systems through
    their own right-hand side; Drake and scipy call its compiled twin where it has one,
    counted too), pymunk's ``Space.step``, pybullet's ``stepSimulation``,
    the MuJoCo adapter's applied-force callback (called at every force evaluation); and
    the accepted steps of the adaptive solvers (the reference's Dormand-Prince ``step``
    takes one accepted step a call, scipy's ``OdeSolver.step`` likewise)."""
    from scipy.integrate._ivp.base import OdeSolver

    from truestep.reference_impl import odes
    from truestep.reference_impl.particles import ParticleSystem
    from truestep.reference_impl.solvers.explicit_rk import DormandPrince54

    patch = pytest.MonkeyPatch()
    patch.setattr(ParticleSystem, "acceleration", _counting(ParticleSystem.acceleration))
    patch.setattr(odes.KeplerProblem, "acceleration", _counting(odes.KeplerProblem.acceleration))
    patch.setattr(odes.Arenstorf, "acceleration", _counting(odes.Arenstorf.acceleration))
    patch.setattr(odes.CircleField, "derivative", _counting(odes.CircleField.derivative))
    for system in (ParticleSystem, odes.KeplerProblem, odes.Arenstorf, odes.CircleField):
        patch.setattr(system, "compiled_derivative", _counted_twin(system.compiled_derivative))
    patch.setattr(DormandPrince54, "step", _counting(DormandPrince54.step, "steps"))
    patch.setattr(OdeSolver, "step", _counting(OdeSolver.step, "steps"))
    try:
        import pymunk

        patch.setattr(pymunk.Space, "step", _counting(pymunk.Space.step))
    except ImportError:
        pass
    try:
        from truestep.adapters import pybullet_adapter

        patch.setattr(pybullet_adapter.p, "stepSimulation", _counting(pybullet_adapter.p.stepSimulation))
    except ImportError:
        pass
    try:
        from truestep.adapters import mujoco_adapter

        applied = mujoco_adapter.AppliedForces
        patch.setattr(applied, "__call__", _counting(applied.__call__))
    except ImportError:
        pass
    try:
        from truestep.adapters import drake_adapter

        # Drake's Simulator calls its monitor after every step it takes, and once when it
        # initialises (not a step: counted off below, test_nfev_and_steps)
        patch.setattr(drake_adapter._Watch, "__call__", _counting(drake_adapter._Watch.__call__, "steps"))
    except ImportError:
        pass
    yield
    patch.undo()
    _RUNS.clear()
