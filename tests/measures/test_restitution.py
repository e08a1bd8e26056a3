"""The stability criterion and the restitution estimator on known inputs."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from truestep.adapters import get_adapter
from truestep.cases import load_cases
from truestep.cases.exact import stability_limit
from truestep.measures.restitution import bounces
from truestep.measures.stability import MIN_STEPS, SearchTimeout, bisect_limit, energy_grows, is_stable

T = np.linspace(0.0, 100.0, 20001)


@pytest.mark.parametrize(
    "energy",
    [
        1.0 + 0.3 * np.sin(7.3 * T) ** 2,  # bounded oscillation, like symplectic Euler
        1.0 + 0.99 * np.sin(0.4 * T) ** 2,  # large, slow but bounded
        np.exp(-0.01 * T),  # decaying, like implicit Euler
        np.full_like(T, 2.5),  # conserved
        -0.5 + 1e-13 * np.sin(3 * T),  # round-off around a negative energy
        # two modes beating: the band's edge drifts by 15% over the run
        1.0 + 0.01 * (1 + 0.15 * T / T[-1]) * np.sin(30 * T) + 0.002 * np.sin(0.9 * T),
        # an error below the start that touches it only at t = 0, like Verlet's
        1.0 - 7e-4 * np.sin(5 * T) ** 2 + 2e-5 * np.sin(0.05 * T) ** 2,
    ],
    ids=["oscillating", "slow-oscillating", "decaying", "constant", "roundoff", "beating", "below-start"],
)
def test_bounded_energy_is_stable(energy):
    assert not energy_grows(T, energy)


@pytest.mark.parametrize(
    "energy",
    [
        np.exp(0.001 * T),  # slow exponential growth (explicit Euler at a small step)
        1.0 + 1e-3 * T,  # secular linear drift upward
        (1.0 + 0.3 * np.sin(7.3 * T) ** 2) * np.exp(0.02 * T),  # growing oscillation
        np.where(T < 90, 1.0, np.inf),  # blow-up to infinity
    ],
    ids=["slow-exponential", "linear-drift", "growing-oscillation", "non-finite"],
)
def test_growing_energy_is_unstable(energy):
    assert energy_grows(T, energy)


@pytest.mark.parametrize("name", ["spring-chain", "mass-ratio-chain"])
def test_multi_mode_chains_are_stable_below_and_unstable_above_the_exact_limit(name):
    """Symplectic Euler on a linear chain, run as a search runs it (5000 steps): bounded
    at 2%, 10% and 99.5% of 2/omega_max, growing at 100.5%. Beats between the chain's modes moved the
    energy band's edge by 10-15% over such runs, which a criterion comparing bare peaks
    read as growth (it called these chains unstable at every step)."""
    case = load_cases(name)[0]
    limit = stability_limit(case, "symplectic-euler")
    adapter = get_adapter("reference")

    def stable(dt):
        trial = dataclasses.replace(case, duration=MIN_STEPS * dt, max_records=MIN_STEPS)
        return is_stable(adapter.simulate(trial, "symplectic-euler", dt))

    assert stable(0.995 * limit) and stable(0.1 * limit) and stable(0.02 * limit)
    assert not stable(1.005 * limit)


def test_bisection_finds_a_known_boundary_within_its_budget():
    calls = []

    def stable_at(dt):
        calls.append(dt)
        return dt <= 0.2

    r = bisect_limit(stable_at, 1e-3, 0.5, rel_tol=1e-3, max_runs=30)
    assert r.dt_limit <= 0.2 < r.dt_unstable
    assert r.dt_unstable / r.dt_limit - 1 <= 1e-3
    assert len(calls) == r.runs <= 30


def test_a_slow_machine_finds_the_same_limit_and_only_the_safety_valve_is_a_timeout():
    """The search is bounded by runs, not by seconds: slow calls give the same bracket as
    fast ones; past ``budget_s`` it raises instead of reporting where it happened to be."""

    def fast(dt):
        return dt <= 0.2

    def slow(dt):
        time.sleep(0.02)
        return dt <= 0.2

    quick, patient = (
        bisect_limit(f, 1e-3, 0.5, rel_tol=1e-3, max_runs=30, budget_s=60.0) for f in (fast, slow)
    )
    assert (quick.dt_limit, quick.dt_unstable, quick.runs) == (
        patient.dt_limit,
        patient.dt_unstable,
        patient.runs,
    )
    with pytest.raises(SearchTimeout, match="safety limit"):
        bisect_limit(slow, 1e-3, 0.5, rel_tol=1e-3, max_runs=30, budget_s=0.1)


def exact_bouncing_ball(t, h0, e, g=9.81):
    """Height above contact and velocity of an ideal ball: apexes h0 e^(2n)."""
    h, v = np.empty_like(t), np.empty_like(t)
    t1 = np.sqrt(2 * h0 / g)
    starts, speeds = [0.0, t1], [g * t1]
    for _ in range(30):
        speeds.append(speeds[-1] * e)
        starts.append(starts[-1] + 2 * speeds[-1] / g)
    for i, ti in enumerate(t):
        if ti < t1:
            h[i], v[i] = h0 - 0.5 * g * ti**2, -g * ti
            continue
        k = np.searchsorted(starts, ti) - 1
        tau, u = ti - starts[k], speeds[k]
        h[i], v[i] = u * tau - 0.5 * g * tau**2, u - g * tau
    return h, v


@pytest.mark.parametrize("e", [0.5, 0.8, 0.9, 1.0])
@pytest.mark.parametrize("dt", [1 / 240, 1 / 1000])
def test_restitution_estimator_is_exact_on_an_exact_trajectory(e, dt):
    t1 = np.sqrt(2 / 9.81)
    zeno = t1 * (1 + 2 * e / (1 - e)) if e < 1 else np.inf  # infinitely many bounces by then
    t = np.arange(0.0, min(2.5, 0.9 * zeno), dt)
    h, v = exact_bouncing_ball(t, 1.0, e)
    found = bounces(t, h, v, 9.81)
    assert len(found) >= 3
    t_hit = np.sqrt(2 / 9.81) * (1 + 2 * np.cumsum(e ** np.arange(6)) - 2)  # impacts
    for k, b in enumerate(found[:3], start=1):
        if np.isnan(b.apex):  # the run ends while this flight still rises
            assert k == len(found) and b.t_low > 2.5 - 2 * np.sqrt(2 / 9.81) * e**k
            continue
        # The apex is the highest sample of the flight: an exact arc sampled every dt
        # reads low by at most g dt^2 / 8, never high.
        low = 9.81 * dt**2 / 8
        assert e ** (2 * k) - low <= b.apex <= e ** (2 * k)
        # Speeds are sampled up to one step before impact and after release: gravity
        # changes each by at most g dt, so the ratio is within 2 g dt / v_out of e.
        assert b.e_velocity == pytest.approx(e, abs=2 * 9.81 * dt / b.v_out)
        assert b.penetration == 0.0
        # the lowest sample of the contact is the one nearest the impact, within a step
        assert abs(b.t_low - t_hit[k - 1]) <= dt


def test_a_ball_that_stops_has_zero_rebound():
    t = np.arange(0.0, 1.0, 1 / 240)
    h, v = exact_bouncing_ball(t, 1.0, 0.5)
    stop = t > 0.4515
    h[stop], v[stop] = -1e-4, 0.0  # lands and rests, slightly sunk
    found = bounces(t, h, v, 9.81)
    assert len(found) == 1
    assert found[0].e_velocity == 0.0 and found[0].penetration == pytest.approx(1e-4)
