"""Bounce properties on synthetic trajectories whose apexes and bounce times are known:
hard contact (one step), soft contact (an engine's spring-damper over many steps,
penetrating) and chatter (the velocity turning several times inside one contact); and on
flights that are not ballistic, where the heights actually reached are the answer.

The trajectory follows the exact bouncing ball (drop height h0, restitution e, launches
at T_k with speed e^k V) everywhere but in a window of ``contact_steps`` steps around each
T_k, where the ball dips into the floor and its normal velocity does what the contact
model makes it do. Every flight sample outside the windows lies on the exact arcs, so the
highest sample of a flight is the apex to within ``g dt^2 / 8``, and the lowest sample of a
window is at T_k. Reading the first sample whose velocity points up instead (inside the
floor under soft contact) gives ~100% errors.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from truestep.adapters.base import Trajectory
from truestep.measures.properties import PROPERTIES
from truestep.measures.restitution import bounces

H0, E, G, R = 1.0, 0.8, 9.81, 0.05  # the bouncing-ball case: drop height, restitution, g, radius


def _exact_schedule(t_end: float) -> tuple[np.ndarray, np.ndarray]:
    """Bounce times T_k and launch speeds e^k V of the instantaneous model (own closed form)."""
    v = np.sqrt(2 * G * H0)
    times, speeds = [v / G], [E * v]
    while times[-1] < t_end:
        times.append(times[-1] + 2 * speeds[-1] / G)
        speeds.append(speeds[-1] * E)
    return np.array(times), np.array(speeds)


def soft_bounces(
    dt: float, contact_steps: int, *, depth: float, chatter: float, t_end: float = 2.5
) -> Trajectory:
    """The ball's trajectory sampled every ``dt`` s (see the module docstring): in each
    contact window the height dips to ``-depth`` m and the normal velocity is replaced by
    a rebound with ``chatter`` m/s of sign-changing wobble on it."""
    t = np.arange(0.0, t_end + dt / 2, dt)
    times, speeds = _exact_schedule(t_end)
    k = np.searchsorted(times, t)  # bounces before t: k (flight k starts at times[k-1])
    start = np.where(k > 0, times[np.maximum(k - 1, 0)], 0.0)
    w0 = np.where(k > 0, speeds[np.maximum(k - 1, 0)], 0.0)
    u0 = np.where(k > 0, 0.0, H0)
    u = u0 + w0 * (t - start) - 0.5 * G * (t - start) ** 2
    w = w0 - G * (t - start)
    half = 0.5 * contact_steps * dt
    for tk, vk in zip(times, speeds, strict=True):
        inside = np.abs(t - tk) < half
        phase = (t[inside] - (tk - half)) / (2 * half)  # 0 .. 1 through the contact
        u[inside] = -depth * np.sin(np.pi * phase)
        w[inside] = (vk / E) * (2 * phase - 1) + chatter * np.sin(6 * np.pi * phase)
    x = np.zeros((len(t), 1, 3))
    v = np.zeros((len(t), 1, 3))
    x[:, 0, 1], v[:, 0, 1] = u + R, w
    return Trajectory(t=t, x=x, v=v, energy=None, steps=len(t) - 1)


@pytest.mark.parametrize(
    ("contact_steps", "depth", "chatter"),
    [(1, 0.0, 0.0), (10, 0.004, 0.0), (16, 0.01, 0.3)],
    ids=["hard", "soft", "soft-chatter"],
)
def test_apex_and_launch_of_each_flight_are_exact(case_named, contact_steps, depth, chatter):
    case = case_named("bouncing-ball")
    dt = 1e-3
    traj = soft_bounces(dt, contact_steps, depth=depth, chatter=chatter)
    # Sampling: an apex read low by at most g dt^2 / 8 (relative to the lowest apex, the
    # third), a bounce time off by at most half a step (the windows are centred on T_k).
    assert PROPERTIES["apex_height_error"](case, traj) <= G * dt**2 / 8 / (H0 * E**6)
    assert PROPERTIES["bounce_time_error"](case, traj) <= dt / 2 + 1e-12
    found = bounces(traj.t, traj.x[:, 0, 1] - R, traj.v[:, 0, 1], G)
    assert len(found) >= 3
    if depth:
        assert [b.penetration for b in found[:3]] == pytest.approx([depth] * 3, rel=0.05)


def test_reading_inside_the_contact_gives_the_old_hundred_percent(case_named):
    """The shortcut the old code took (the first sample whose normal velocity points up)
    lands inside the floor under soft contact: apex near 0, error near 100%."""
    traj = soft_bounces(2e-3, 10, depth=0.004, chatter=0.0)
    u = traj.x[:, 0, 1] - R
    w = traj.v[:, 0, 1]
    up = np.flatnonzero((w[1:] > 0) & (w[:-1] <= 0)) + 1
    apex = np.maximum(u[up], 0) + w[up] ** 2 / (2 * G)
    exact = H0 * E ** (2 * np.arange(1, 4))
    assert np.max(np.abs(apex[:3] / exact - 1)) > 0.9
    assert PROPERTIES["apex_height_error"](case_named("bouncing-ball"), traj) <= (
        G * 2e-3**2 / 8 / (H0 * E**6)
    )


def test_a_flight_that_is_not_ballistic_is_measured_by_the_heights_it_reaches(case_named):
    """A ball stepped by symplectic Euler at 4 ms (velocity first, then position) and
    reflected with e = 0.8 at the floor: its flights are not ballistic arcs, so the apex
    extrapolated from a flight's first sample (``u + w^2 / 2g``) is not the height it
    reaches. The property reads the heights reached: each flight's highest sample, found
    here from the bounce steps this loop knows."""
    case = case_named("bouncing-ball")
    dt = 4e-3
    n = round(2.5 / dt)
    u, w = np.empty(n + 1), np.empty(n + 1)
    u[0], w[0] = H0, 0.0
    hits = []
    for i in range(n):
        w[i + 1] = w[i] - G * dt
        u[i + 1] = u[i] + dt * w[i + 1]
        if u[i + 1] < 0 and w[i + 1] < 0:  # the lecture's response, lifted onto the floor
            u[i + 1], w[i + 1] = 0.0, -E * w[i + 1]
            hits.append(i + 1)
    t = np.arange(n + 1) * dt
    x, v = np.zeros((n + 1, 1, 3)), np.zeros((n + 1, 1, 3))
    x[:, 0, 1], v[:, 0, 1] = u + R, w
    traj = Trajectory(t=t, x=x, v=v, energy=None, steps=n)
    reached = np.array([u[a:b].max() for a, b in itertools.pairwise(hits[:4])])
    extrapolated = np.array([u[a] + w[a] ** 2 / (2 * G) for a in hits[:3]])
    exact = H0 * E ** (2 * np.arange(1, 4))
    want = float(np.max(np.abs(reached / exact - 1)))
    assert abs(float(np.max(np.abs(extrapolated / exact - 1))) - want) > 0.3 * want  # differ
    assert PROPERTIES["apex_height_error"](case, traj) == pytest.approx(want, rel=1e-12)
    # recorded more sparsely than every step: no guess
    thin = Trajectory(t=t[::2], x=x[::2], v=v[::2], energy=None, steps=n)
    assert np.isnan(PROPERTIES["apex_height_error"](case, thin))


def test_momentum_drift_counts_an_impulse_that_was_never_delivered(case_named):
    """triangle-impulse applies 20 N for 0.01 s: P must become and stay 0.2 N s. A run
    that keeps P = 0 conserves momentum perfectly and must still score 1 (it delivered
    nothing); one that delivers 0.1 N s scores 0.5."""
    case = case_named("triangle-impulse")
    t = np.linspace(0.0, 1.0, 101)
    n = case.model.n
    for delivered, drift in ((0.0, 1.0), (0.1, 0.5), (0.2, 0.0)):
        v = np.zeros((len(t), n, 3))
        v[:, :, 0] = delivered / case.model.mass.sum()  # spread evenly: P = delivered
        traj = Trajectory(t=t, x=np.zeros((len(t), n, 3)), v=v, energy=None)
        assert PROPERTIES["momentum_drift"](case, traj) == pytest.approx(drift, abs=1e-12)
