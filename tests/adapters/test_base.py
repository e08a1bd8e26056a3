"""FixedStepAdapter, the loop every fixed-step engine shares, on engines whose answer is known."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np
import pytest

import truestep
from truestep.reference_impl.integrate import BLOWUP, record_indices


class ExplicitEuler(truestep.FixedStepAdapter):
    """A user's engine in a dozen lines: explicit Euler under uniform gravity."""

    name = "user-euler"
    methods = ("euler",)
    capabilities = frozenset({"point-masses", "2d", "uniform-gravity"})
    evaluations_per_step: ClassVar = {"euler": 2}  # pretend: to see nfev count them

    def build(self, case, method, h):
        return {"x": case.model.x0.copy(), "v": case.model.v0.copy(), "g": case.model.gravity}

    def advance(self, s, k, steps, h):
        for _ in range(steps):
            s["x"] = s["x"] + h * s["v"]
            s["v"] = s["v"] + h * s["g"]

    def read(self, s):
        return s["x"], s["v"]


class Exploding(ExplicitEuler):
    """Multiplies the state by ten every step: beyond 1e12 after a known number of steps."""

    name = "exploding"

    def advance(self, s, k, steps, h):
        for _ in range(steps):
            s["x"] = s["x"] * 10.0
            s["v"] = s["v"] * 10.0


def _case(case_named, duration: float, max_records: int):
    return dataclasses.replace(case_named("free-fall"), duration=duration, max_records=max_records)


def test_records_energy_and_evaluations_of_a_user_engine(case_named):
    """Explicit Euler from (x0, v0): x_n = x0 + v0 n h + g h^2 n (n - 1) / 2 exactly, read
    at the steps record_indices picks. Tolerance 1e-12 m: round-off over 100 additions."""
    case = _case(case_named, 1.0, 30)
    adapter = ExplicitEuler()
    assert isinstance(adapter, truestep.Adapter)
    traj = adapter.simulate(case, "euler", 0.01)
    n, h = 100, 0.01
    k = record_indices(n, 30)
    assert traj.status == "ok" and traj.steps == n and traj.nfev == 2 * n
    np.testing.assert_allclose(traj.t, k * h, rtol=0, atol=1e-15)
    m = case.model
    G = m.gravity
    x = m.x0 + m.v0 * (k * h)[:, None, None] + G * (h**2 * k * (k - 1) / 2)[:, None, None]
    np.testing.assert_allclose(traj.x, x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(traj.v, m.v0 + G * (k * h)[:, None, None], rtol=0, atol=1e-12)
    kinetic = 0.5 * np.einsum("n,tni,tni->t", m.mass, traj.v, traj.v)
    np.testing.assert_allclose(traj.energy, kinetic - np.einsum("n,tni,i->t", m.mass, traj.x, G), rtol=1e-12)
    assert traj.wall_s > 0


def test_a_blow_up_between_records_stops_at_the_next_check_and_is_recorded(case_named):
    """|x| grows tenfold per step from at most 2 m: beyond 1e12 from step 12 on. With a
    record every 50 steps the check at step 64 finds it; the run stops there, records
    that state, and says unstable at 64 h."""
    case = _case(case_named, 10.0, 20)  # 1000 steps of 0.01 s, records every 50 steps
    traj = Exploding().simulate(case, "euler", 0.01)
    assert traj.status == "unstable"
    assert traj.steps == Exploding.check_every == 64
    assert traj.t[-1] == pytest.approx(0.64) and traj.t_fail == pytest.approx(0.5)
    assert np.abs(traj.x[-1]).max() > BLOWUP
    assert "non-finite or runaway state" in traj.message


def test_unknown_methods_and_missing_features_are_refused(case_named):
    adapter = ExplicitEuler()
    with pytest.raises(ValueError, match="unknown method 'rk4'"):
        adapter.simulate(case_named("free-fall"), "rk4", 0.01)
    spring = case_named("harmonic-oscillator")
    assert adapter.missing(spring, "euler") == {"anchored-springs"}
    with pytest.raises(ValueError, match="needs anchored-springs"):
        adapter.simulate(spring, "euler", 0.01)


def test_advance_is_required_unless_the_adapter_steps_in_its_own_loop(case_named):
    """``advance`` is the hook of the shared stepping loop: a user's adapter without it is
    refused when it is made (an abstract method); one that overrides ``step_and_record``
    (as MuJoCo's rollout does) needs none, and its ``advance``, never called by the loop,
    says so if called."""

    class NoAdvance(truestep.FixedStepAdapter):
        name = "no-advance"
        methods = ("euler",)
        capabilities = ExplicitEuler.capabilities
        build = ExplicitEuler.build
        read = ExplicitEuler.read

    class OwnLoop(NoAdvance):
        def step_and_record(self, case, scene, n_steps, h):
            return ExplicitEuler.step_and_record(ExplicitEuler(), case, scene, n_steps, h)

    with pytest.raises(TypeError, match="abstract method advance"):
        NoAdvance()
    traj = OwnLoop().simulate(_case(case_named, 1.0, 30), "euler", 0.01)
    mine = ExplicitEuler().simulate(_case(case_named, 1.0, 30), "euler", 0.01)
    assert traj.status == "ok" and np.array_equal(traj.x, mine.x)
    with pytest.raises(NotImplementedError, match="steps in its own step_and_record"):
        OwnLoop().advance({}, 0, 1, 0.01)
    from truestep.adapters.mujoco_adapter import MujocoAdapter

    assert not MujocoAdapter.__abstractmethods__
    with pytest.raises(NotImplementedError, match="MujocoAdapter steps in its own step_and_record"):
        MujocoAdapter().advance(None, 0, 1, 0.01)
