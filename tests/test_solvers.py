"""Solvers against exact solutions: orders, stability facts, adaptive control."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from truestep.adapters.reference import build_system
from truestep.measures.stability import energy_grows
from truestep.reference_impl.integrate import integrate
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.odes import Arenstorf, KeplerProblem
from truestep.reference_impl.particles import ParticleSystem
from truestep.reference_impl.solvers import METHODS, get_solver
from truestep.reference_impl.system import SecondOrderSystem, System


class Oscillator(SecondOrderSystem):
    """x'' = -omega^2 x in one dimension; energy (v^2 + omega^2 x^2) / 2."""

    def __init__(self, omega: float):
        super().__init__(np.array([1.0, 0.0]))
        self.omega = omega

    def acceleration(self, q, v, t):
        return -(self.omega**2) * q

    def jacobian(self, x, t):
        return np.array([[0.0, 1.0], [-(self.omega**2), 0.0]])

    def energy(self, x, t):
        return 0.5 * (x[1] ** 2 + self.omega**2 * x[0] ** 2)


def oscillator_energy(method: str, omega_dt: float, steps: int = 4000) -> np.ndarray:
    system = Oscillator(omega=1.0)
    run = integrate(METHODS[method](system), steps * omega_dt, omega_dt, max_records=steps)
    return run.t, np.array([system.energy(x, 0) for x in run.x]), run.status


@pytest.mark.parametrize(
    ("method", "bounded_at", "growing_at"),
    [("symplectic-euler", 1.99, 2.01), ("verlet", 1.99, 2.01), ("rk4", 2.82, 2.84)],
)
def test_stability_limits_of_the_undamped_oscillator(method, bounded_at, growing_at):
    t, e, status = oscillator_energy(method, bounded_at)
    assert status == "ok" and not energy_grows(t, e)
    t, e, status = oscillator_energy(method, growing_at)
    assert status == "unstable" or energy_grows(t, e)


@pytest.mark.parametrize("method", ["euler", "midpoint", "heun", "lecture"])
@pytest.mark.parametrize("omega_dt", [1e-3, 1e-2, 0.1, 1.0])
def test_methods_growing_at_every_step(method, omega_dt):
    # |R(i y)| > 1 for all y > 0 on the imaginary axis: energy rises every step.
    _t, e, _ = oscillator_energy(method, omega_dt, steps=2000)
    assert np.all(np.diff(e) > 0)


@pytest.mark.parametrize("omega_dt", [1e-3, 1e-2, 0.1, 1.0, 10.0, 100.0])
def test_implicit_euler_decays_at_every_step(omega_dt):
    # Backward Euler multiplies the oscillator's energy by exactly 1 / (1 + y^2) < 1 per
    # step (|1 / (1 - i y)|^2), however large the step; 20 steps stay far from underflow.
    _t, e, _ = oscillator_energy("implicit-euler", omega_dt, steps=20)
    assert np.allclose(e[1:] / e[:-1], 1 / (1 + omega_dt**2), rtol=1e-9)


def test_lecture_update_is_exact_under_constant_gravity():
    model = ParticleModel(
        mass=np.array([2.0]),
        x0=np.array([[0.0, 10.0, 0.0]]),
        v0=np.array([[1.0, 3.0, 0.0]]),
        radius=np.zeros(1),
        fixed=np.zeros(1, bool),
        gravity=np.array([0.0, -9.81, 0.0]),
    )
    system = ParticleSystem(model)
    dt = 0.37
    run = integrate(METHODS["lecture"](system), 37 * dt, dt)
    t = run.t[:, None]
    exact = model.x0[0] + model.v0[0] * t + 0.5 * model.gravity * t**2
    # Exact to round-off: p' = p + v dt + a dt^2 / 2 for constant a.
    assert np.max(np.abs(run.x[:, :3] - exact)) < 1e-12 * np.max(np.abs(exact))


def final_error(method: str, n: int) -> float:
    system = Oscillator(omega=10.0)
    t_end = 2.0
    run = integrate(METHODS[method](system), t_end, t_end / n, max_records=10)
    exact = np.array([np.cos(10 * t_end), -10 * np.sin(10 * t_end)])
    return float(np.max(np.abs(run.x[-1] - exact)))


@pytest.mark.parametrize(
    ("method", "order"),
    [
        ("euler", 1),
        ("midpoint", 2),
        ("heun", 2),
        ("rk4", 4),
        ("symplectic-euler", 1),
        ("verlet", 2),
        ("implicit-euler", 1),
        ("lecture", 1),
    ],
)
def test_convergence_order(method, order):
    ns = np.array([4000, 8000, 16000]) if order == 1 else np.array([500, 1000, 2000])
    errors = [final_error(method, n) for n in ns]
    slope = -np.polyfit(np.log(ns), np.log(errors), 1)[0]
    # 0.15: the tolerance; the sweep is in the asymptotic range for each order.
    assert slope == pytest.approx(order, abs=0.15)


@pytest.mark.parametrize(
    ("system", "t_end", "exact"),
    [
        (
            lambda: Arenstorf(np.array([0.994, 0, 0, -2.00158510637908252240537862224])),
            17.0652165601579625588917206249,
            np.array([0.994, 0, 0, -2.00158510637908252240537862224]),
        ),
        (lambda: KeplerProblem(np.array([0.4, 0.0, 0.0, 2.0])), 2 * np.pi, np.array([0.4, 0.0, 0.0, 2.0])),
    ],
    ids=["arenstorf", "kepler"],
)
def test_dopri5_matches_scipy_rk45(system, t_end, exact):
    tol = 1e-8
    s = system()
    solver = METHODS["dopri5"](s, rtol=tol, atol=tol)
    run = integrate(solver, t_end, t_end)
    ours = np.max(np.abs(run.x[-1] - exact))
    s2 = system()
    ref = solve_ivp(
        lambda t, y: s2.derivative(y, t), (0, t_end), s2.get_state(), method="RK45", rtol=tol, atol=tol
    )
    theirs = np.max(np.abs(ref.y[:, -1] - exact))
    # Same tableau, norm and controller as scipy's RK45: within 10% in error and cost.
    assert ours == pytest.approx(theirs, rel=0.10)
    assert solver.nfev == pytest.approx(ref.nfev, rel=0.10)


def test_derivative_does_not_change_the_state(case_named):
    s = build_system(case_named("damped-oscillator"))
    x = s.get_state()
    before = x.copy()
    s.derivative(x, 0.0)
    assert np.array_equal(x, before) and np.array_equal(s.get_state(), before)


class _Riccati(System):
    """x' = x^2 from x(0) = 1: the solution 1 / (1 - t) leaves every bound at t = 1."""

    def derivative(self, x, t):
        with np.errstate(over="ignore", invalid="ignore"):
            return x * x


@pytest.mark.parametrize("max_records", [10, 100000])
def test_a_blow_up_stops_the_run_and_records_where_it_happened(max_records):
    """Explicit Euler on x' = x^2 passes 1e12 shortly after t = 1: the run stops within
    64 steps of it, the last record is the first one beyond the bound, every earlier
    record is finite, and t_fail is that record's time."""
    solver = get_solver("euler")(_Riccati(np.array([1.0])))
    run = integrate(solver, 3.0, 1e-4, max_records=max_records)
    assert run.status == "unstable" and run.t_fail == run.t[-1]
    assert not np.all(np.abs(run.x[-1]) < 1e12)
    assert np.all(np.abs(run.x[:-1]) < 1e12)
    assert 1.0 < run.t_fail < 1.0 + 65 * 1e-4 + 0.01
