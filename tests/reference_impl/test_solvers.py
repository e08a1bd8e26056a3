"""Solvers against exact solutions: orders, stability facts, adaptive control."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from truestep.adapters.reference import build_system
from truestep.measures.stability import energy_grows
from truestep.reference_impl.integrate import integrate
from truestep.reference_impl.model import ParticleModel
from truestep.reference_impl.odes import Arenstorf, KeplerProblem
from truestep.reference_impl.particles import ParticleSystem
from truestep.reference_impl.solvers import (
    METHODS,
    RK4,
    DormandPrince54,
    Euler,
    Heun,
    ImplicitEuler,
    LectureUpdate,
    MethodFacts,
    Midpoint,
    Stability,
    SymplecticEuler,
    VelocityVerlet,
    get_solver,
    stability_polynomial,
    tableau_stability,
)
from truestep.reference_impl.solvers.base import SolverFailed
from truestep.reference_impl.solvers.explicit_rk import polynomial_step_matrix, stages_of
from truestep.reference_impl.solvers.facts import first_growth, spectral_radius
from truestep.reference_impl.solvers.implicit import implicit_euler_step
from truestep.reference_impl.solvers.splitting import (
    lecture_step,
    symplectic_euler_step,
    verlet_step,
)
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


# --------------------------------------------------------------------------------------
# The numpy solvers against closed forms (mutation testing, tools/campaigns/mutation/README.md).
#
# Every check is a closed form or an independent recomputation: one step of a Runge-Kutta
# method on ``y' = A y`` is the method's stability polynomial in ``h A`` (the Taylor
# polynomial of ``exp(h A)`` up to its order); on ``y' = p(t)`` it is the method's
# quadrature rule; backward Euler on a linear system is ``(I - h A)^-1``; the splitting
# methods' one-step maps are their update formulas; explicit Euler's stability limit on a
# damped mode is ``omega h = 2 zeta`` (underdamped) or ``2 / (zeta + sqrt(zeta^2 - 1))``.
# A non-normal matrix with distinct eigenvalues: every power of it is different.
A3 = np.array([[-0.3, 1.1, 0.2], [-0.7, -0.1, 0.5], [0.4, -0.6, -0.9]])
Y0 = np.array([0.8, -0.5, 1.3])


class Linear(System):
    """y' = A y (+ a polynomial in t), with the exact Jacobian or none."""

    def __init__(self, a, y0, t0=0.0, *, poly=None, jac=True):
        super().__init__(y0, t0)
        self.a, self.poly, self.jac, self.calls = np.asarray(a, float), poly, jac, 0

    def derivative(self, x, t):
        self.calls += 1
        out = self.a @ x
        if self.poly is not None:
            out = out + np.polyval(self.poly, t)
        return out

    def jacobian(self, x, t):
        return self.a.copy() if self.jac else None


class Riccati(System):
    """y' = -y^2 (one component): backward Euler solves h y1^2 + y1 - y0 = 0."""

    def __init__(self, y0, *, jac):
        super().__init__(np.array([y0]))
        self.jac = jac

    def derivative(self, x, t):
        return -(x**2)

    def jacobian(self, x, t):
        return np.array([[-2.0 * x[0]]]) if self.jac else None


class Damped(SecondOrderSystem):
    """q'' = -w2 q - c q' + g0 + g1 t, n independent coordinates."""

    def __init__(self, q0, v0, t0=0.0, *, w2=0.0, c=0.0, g=(0.0, 0.0)):
        super().__init__(np.concatenate([q0, v0]), t0)
        self.w2, self.c, self.g = w2, c, g

    def acceleration(self, q, v, t):
        return -self.w2 * q - self.c * v + self.g[0] + self.g[1] * t


def one_step(cls, system, h, **kw):
    solver = cls(system, **kw)
    taken = solver.step(h)
    return solver, taken, system.get_state(), system.get_time()


GAMMA = {
    Euler: [1, 1],
    Midpoint: [1, 1, 1 / 2],
    Heun: [1, 1, 1 / 2],
    RK4: [1, 1, 1 / 2, 1 / 6, 1 / 24],
}


@pytest.mark.parametrize("cls", list(GAMMA))
def test_an_rk_step_on_a_linear_system_is_its_taylor_polynomial(cls):
    h, t0 = 0.37, 1.25
    expected = sum(g * np.linalg.matrix_power(h * A3, k) @ Y0 for k, g in enumerate(GAMMA[cls]))
    system = Linear(A3, Y0, t0)
    solver, taken, y, t = one_step(cls, system, h)
    assert taken == h and t == t0 + h
    np.testing.assert_allclose(y, expected, rtol=1e-14, atol=1e-15)
    assert solver.nfev == system.calls == len(GAMMA[cls]) - 1
    np.testing.assert_allclose(stability_polynomial(cls.A, cls.B), GAMMA[cls], rtol=1e-15)


@pytest.mark.parametrize(
    ("cls", "rule"),
    [
        (Euler, lambda p, t, h: h * p(t)),
        (Midpoint, lambda p, t, h: h * p(t + h / 2)),
        (Heun, lambda p, t, h: h * (p(t) + p(t + h)) / 2),
        (RK4, lambda p, t, h: h * (p(t) + 4 * p(t + h / 2) + p(t + h)) / 6),  # Simpson
    ],
)
def test_an_rk_step_on_y_prime_of_t_is_its_quadrature_rule(cls, rule):
    poly = [0.7, -1.3, 2.1, 0.9]  # a cubic in t: Simpson's rule is exact for it
    t0, h, y0 = 1.7, 0.3, np.array([0.25])
    system = Linear(np.zeros((1, 1)), y0, t0, poly=poly)
    _, _, y, t = one_step(cls, system, h)
    expected = y0[0] + rule(lambda s: np.polyval(poly, s), t0, h)
    assert t == pytest.approx(t0 + h, rel=1e-15)
    assert y[0] == pytest.approx(expected, rel=1e-13)
    if cls is RK4:  # and the exact integral
        integral = np.polyval(np.polyint(poly), t0 + h) - np.polyval(np.polyint(poly), t0)
        assert y[0] == pytest.approx(y0[0] + integral, rel=1e-13)


def test_the_nodes_are_the_row_sums_and_the_stages_list_the_nonzero_weights():
    np.testing.assert_array_equal(RK4.nodes(), [0.0, 0.5, 0.5, 1.0])
    st = stages_of(RK4.A)
    assert st.columns is None
    assert st.rows == ((0.0, ()), (0.5, ((0, 0.5),)), (0.5, ((1, 0.5),)), (1.0, ((2, 1.0),)))
    dp = stages_of(DormandPrince54.A[:6])
    assert dp.columns is not None
    np.testing.assert_allclose([c for c, _ in dp.rows], [0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1], rtol=1e-15)
    # column 0 feeds stages 1..5 as one run; the run's weights are that column of A
    (c0, feeds0) = dp.columns[0]
    assert c0 == 0.0 and len(feeds0) == 1 and feeds0[0][0] == slice(1, 6)
    np.testing.assert_array_equal(feeds0[0][1].ravel(), DormandPrince54.A[1:6, 0])
    # a column with a gap (stage 6 does not weigh column 1 of the 7-stage tableau)
    full = stages_of(DormandPrince54.A)
    (_, feeds1) = full.columns[1]
    assert [f[0] for f in feeds1] == [slice(2, 6)]
    a = np.zeros((4, 4))
    a[1, 0], a[3, 0], a[2, 1], a[3, 1] = 0.5, 0.25, 0.75, 0.125
    st = stages_of(a)
    assert st.columns[0][1] == ((1, 0.5), (3, 0.25))
    assert st.columns[1][1][0][0] == slice(2, 4)


def textbook_dopri_step(f, x, t, h):
    a, b, e = DormandPrince54.A, DormandPrince54.B, DormandPrince54.E
    c = a.sum(axis=1)
    k = np.zeros((7, len(x)))
    for i in range(7):
        k[i] = f(x + h * (a[i, :i] @ k[:i]), t + c[i] * h)
    return x + h * (b @ k), h * (e @ k)


def test_dopri5_steps_like_the_textbook_and_controls_its_step():
    t0 = 0.4
    system = Linear(A3, Y0, t0, poly=[0.3, -0.2, 0.1])
    solver = DormandPrince54(system, rtol=1e-5, atol=1e-7)
    f = system.derivative
    x, t = Y0.copy(), t0
    for _ in range(6):
        h_try = solver._h
        h = solver.step(0.5)
        if h_try is not None:
            assert h <= min(h_try, 0.5)
        x_new, err_vec = textbook_dopri_step(f, x, t, h)
        np.testing.assert_allclose(system.get_state(), x_new, rtol=1e-13, atol=1e-15)
        assert system.get_time() == pytest.approx(t + h, rel=1e-15)
        scale = 1e-7 + np.maximum(np.abs(x), np.abs(x_new)) * 1e-5
        err = math.sqrt(np.mean((err_vec / scale) ** 2))
        assert err <= 1.0
        expected_next = h * min(10.0, 0.9 * err**-0.2)
        if solver.n_rejected == 0:
            assert solver._h == pytest.approx(expected_next, rel=1e-9)
        x, t = x_new, t + h
    # the fifth-order solution is exact for polynomials of degree 4 in t
    sys2 = Linear(np.zeros((1, 1)), [0.0], 0.0, poly=[5.0, -1.0, 2.0, 0.5, 1.0])
    DormandPrince54(sys2, rtol=1e-3, atol=1e-3).step(0.6)
    tt = sys2.get_time()
    exact = np.polyval(np.polyint([5.0, -1.0, 2.0, 0.5, 1.0]), tt)
    assert sys2.get_state()[0] == pytest.approx(exact, rel=1e-12)


def test_dopri5_initial_step_is_hairers_formula():
    rtol, atol = 1e-6, 1e-8
    system = Linear(A3, Y0, 0.2)
    solver = DormandPrince54(system, rtol=rtol, atol=atol)
    x, t = Y0, 0.2
    f0 = A3 @ x
    scale = atol + np.abs(x) * rtol
    d0, d1 = np.sqrt(np.mean((x / scale) ** 2)), np.sqrt(np.mean((f0 / scale) ** 2))
    h0 = 0.01 * d0 / d1
    f1 = A3 @ (x + h0 * f0)
    d2 = np.sqrt(np.mean(((f1 - f0) / scale) ** 2)) / h0
    h1 = (0.01 / max(d1, d2)) ** (1 / 5)
    expected = min(100 * h0, h1, 1.0)
    assert solver._initial_step(x, t, f0, 1.0) == pytest.approx(expected, rel=1e-12)
    assert solver._initial_step(x, t, f0, 1e-9) == 1e-9  # bounded by the largest step
    # a state and derivative at rest: the tiny defaults
    rest = DormandPrince54(Linear(np.zeros((3, 3)), np.zeros(3)), rtol=rtol, atol=atol)
    assert rest._initial_step(np.zeros(3), 0.0, np.zeros(3), 1.0) == pytest.approx(1e-6)


def test_dopri5_rejects_a_too_long_step_and_does_not_grow_after_it():
    system = Linear(np.array([[-50.0]]), [1.0], 0.0)
    solver = DormandPrince54(system, rtol=1e-9, atol=1e-12)
    solver._h = 0.5  # far too long
    h = solver.step(0.5)
    assert solver.n_rejected >= 1 and h < 0.5
    assert solver._h <= h  # no growth right after a rejection
    y = system.get_state()[0]
    assert y == pytest.approx(math.exp(-50.0 * h), rel=1e-7)
    with pytest.raises(ValueError, match="must both be positive"):
        DormandPrince54(system, rtol=0.0, atol=1e-6)
    with pytest.raises(ValueError, match="must both be positive"):
        DormandPrince54(system, rtol=1e-6, atol=-1.0)


def test_dopri5_reuses_its_last_stage_unless_the_state_changed():
    system = Linear(A3, Y0)
    solver = DormandPrince54(system, rtol=1e-6, atol=1e-6)
    solver.step(0.1)
    n = solver.nfev
    solver.step(0.1)
    assert solver.nfev - n == 6  # FSAL: six evaluations per accepted step
    system.set_state(system.get_state() * 0.5, system.get_time())  # an event between steps
    n = solver.nfev
    solver.step(0.1)
    assert solver.nfev - n == 7


def test_dopri5_reports_a_non_finite_derivative_as_unstable():
    class Blowup(System):
        def derivative(self, x, t):
            return np.array([np.nan])

    solver = DormandPrince54(Blowup(np.array([1.0])))
    solver._f0 = np.array([1.0])
    solver._x_end = np.array([1.0])
    solver._h = 1e-3
    with pytest.raises(FloatingPointError, match="non-finite"):
        solver.step(1.0)


def test_dopri5_reports_an_underflow_of_finite_errors_as_a_solver_failure():
    class Stiffer(System):  # an error estimate that no step size brings below 1
        def derivative(self, x, t):
            return np.array([1e300 * np.sign(t - 0.5 + 1e-300) if t > 0.5 else 1.0])

    solver = DormandPrince54(Stiffer(np.array([0.0])), rtol=1e-12, atol=1e-12)
    with pytest.raises(SolverFailed, match="underflow"):
        t = 0.0
        while t < 1.0:
            t += solver.step(1.0 - t)


@pytest.mark.parametrize("jac", [True, False])
def test_implicit_euler_on_a_linear_system_is_the_resolvent(jac):
    h, t0 = 0.3, 0.5
    system = Linear(A3, Y0, t0, jac=jac)
    solver, taken, y, t = one_step(ImplicitEuler, system, h)
    np.testing.assert_allclose(y, np.linalg.solve(np.eye(3) - h * A3, Y0), rtol=1e-9)
    assert taken == h and t == t0 + h and solver.n_jac == 1
    # on a linear system Newton with the right matrix lands in one update and stops at
    # the next: predictor, its derivative, two iterations (+ 3 differences for the matrix)
    fd = 0 if jac else 3
    assert solver.nfev == 4 + fd
    # a second step of the same size keeps the factorisation
    solver.step(h)
    assert solver.n_jac == 1 and solver.nfev == 8 + fd
    solver.step(h / 2)  # a new step size (a shorter one too): a new matrix at once
    assert solver.n_jac == 2 and solver.nfev == 12 + 2 * fd
    np.testing.assert_allclose(
        system.get_state(),
        np.linalg.solve(np.eye(3) - h / 2 * A3, np.linalg.solve(np.eye(3) - h * A3, y)),
        rtol=1e-9,
    )


@pytest.mark.parametrize("dim", [1, 3, 7, 40, 300])
def test_implicit_euler_solves_and_sizes_as_scipy_and_numpy_do_bit_for_bit(dim):
    """The solver's lean LU solve and update size (no per-call checks, no ``np.mean``)
    give scipy's ``lu_solve`` and the ``np.mean`` formula's numbers to the last bit."""
    import scipy.linalg as la

    rng = np.random.default_rng(dim)
    a = rng.normal(size=(dim, dim))
    y, b = rng.normal(size=dim) * 10.0 ** rng.integers(-3, 4, dim), rng.normal(size=dim)
    system = Linear(a, y, 0.0, jac=True)
    solver = ImplicitEuler(system)
    h = 0.01
    solve = solver._factorise(y, 0.0, system.derivative(y, 0.0), h)
    expected = la.lu_solve(la.lu_factor(np.eye(dim) - h * a), b)
    assert np.array_equal(solve(b), expected)
    size = solver._size(b, y)
    assert size == float(np.sqrt(np.mean((b / (1.0 + np.abs(y))) ** 2)))


@pytest.mark.parametrize("jac", [True, False])
def test_implicit_euler_on_riccati_solves_the_quadratic(jac):
    y0, h = 2.0, 0.1
    system = Riccati(y0, jac=jac)
    _, _, y, _ = one_step(ImplicitEuler, system, h)
    assert y[0] == pytest.approx((-1 + math.sqrt(1 + 4 * h * y0)) / (2 * h), rel=1e-9)


def test_implicit_euler_refactorises_when_newton_is_slow_and_fails_when_it_must():
    h = 0.1
    system = Riccati(0.1, jac=True)
    solver = ImplicitEuler(system)
    solver.step(h)
    assert solver.n_jac == 1
    # from y0 = 5 the kept matrix (built near y = 0.1) makes Newton slow: rebuilt
    system.set_state(np.array([5.0]), system.get_time())
    solver.step(h)
    assert solver.n_jac >= 2
    assert system.get_state()[0] == pytest.approx((-1 + math.sqrt(1 + 20 * h)) / (2 * h), rel=1e-9)

    # one fast Newton iteration is not enough from 2: the damped iteration finds the root
    # of y = 2 - 0.1 y^2 all the same
    robust = Riccati(2.0, jac=True)
    ImplicitEuler(robust, max_iter=1).step(0.1)
    assert robust.get_state()[0] == pytest.approx((-1 + math.sqrt(1.8)) / 0.2, rel=1e-9)
    # from -3, y = -3 - 0.1 y^2 has no real root: the solver fails, and says so
    with pytest.raises(SolverFailed, match="no solution"):
        ImplicitEuler(Riccati(-3.0, jac=True)).step(0.1)


def test_step_matrices_are_the_one_step_maps():
    a, b = 0.3, 0.2  # (omega h)^2 and c h
    z = np.array([[0.0, 1.0], [-a, -b]])
    np.testing.assert_allclose(implicit_euler_step(a, b), np.linalg.inv(np.eye(2) - z), rtol=1e-15)
    rk4 = polynomial_step_matrix(GAMMA[RK4])(a, b)
    np.testing.assert_allclose(
        rk4, sum(np.linalg.matrix_power(z, k) / math.factorial(k) for k in range(5)), rtol=1e-14
    )
    np.testing.assert_allclose(symplectic_euler_step(a, b), [[1 - a, 1 - b], [-a, 1 - b]])
    np.testing.assert_allclose(lecture_step(a, b), [[1 - a / 2, 1 - b / 2], [-a, 1 - b]])


def split_map(cls, h, w2, c, steps=1):
    """The matrix of ``steps`` steps on (q, h v) of q'' = -w2 q - c q', column by column."""
    cols = []
    for e in np.eye(2):
        s = Damped(np.array([e[0]]), np.array([e[1] / h]), w2=w2, c=c)
        solver = cls(s)
        for _ in range(steps):
            solver.step(h)
        q, v = s.get_state()
        cols.append([q, h * v])
    return np.array(cols).T


@pytest.mark.parametrize(
    ("cls", "formula"),
    [(SymplecticEuler, symplectic_euler_step), (LectureUpdate, lecture_step)],
)
def test_splitting_steps_are_their_update_formulas(cls, formula):
    h, w2, c = 0.2, 3.0, 0.7
    np.testing.assert_allclose(split_map(cls, h, w2, c), formula(w2 * h * h, c * h), rtol=1e-14)
    assert cls.facts.stability.step_matrix is formula


def test_velocity_verlet_is_kick_drift_kick_and_reuses_its_closing_kick():
    h, w2, c = 0.2, 3.0, 0.7
    q0, v0 = 0.6, -0.4
    s = Damped(np.array([q0]), np.array([v0]), w2=w2, c=c)
    solver = VelocityVerlet(s)
    a0 = -w2 * q0 - c * v0
    v_half = v0 + 0.5 * h * a0
    q1 = q0 + h * v_half
    a1 = -w2 * q1 - c * v_half
    v1 = v_half + 0.5 * h * a1
    solver.step(h)
    np.testing.assert_allclose(s.get_state(), [q1, v1], rtol=1e-15)
    assert solver.nfev == 2
    # the next step reads the reused a1 (at the half-step velocity), not a(q1, v1)
    v_half2 = v1 + 0.5 * h * a1
    q2 = q1 + h * v_half2
    a2 = -w2 * q2 - c * v_half2
    solver.step(h)
    np.testing.assert_allclose(s.get_state(), [q2, v_half2 + 0.5 * h * a2], rtol=1e-15)
    assert solver.nfev == 3
    # after an event between steps the acceleration is evaluated afresh
    s.set_state(np.array([q2, 0.0]), s.get_time())
    solver.step(h)
    assert solver.nfev == 5
    # the same state at another time is another state
    s.set_state(s.get_state(), s.get_time() + 1.0)
    solver.step(h)
    assert solver.nfev == 7
    # its declared step matrix is the map in (q, h v, s)
    m = verlet_step(w2 * h * h, c * h)
    state = np.array([q0, h * v0, h * h * a0])
    q_, hv_, s_ = m @ state
    assert q_ == pytest.approx(q1, rel=1e-14) and hv_ == pytest.approx(h * v1, rel=1e-14)
    assert s_ == pytest.approx(h * h * a1, rel=1e-14)


def test_the_lecture_update_is_exact_under_a_constant_acceleration_and_symplectic_euler_not():
    g, h, t0 = -9.81, 0.1, 0.0
    for cls, exact in [(LectureUpdate, True), (SymplecticEuler, False), (VelocityVerlet, True)]:
        s = Damped(np.array([1.0]), np.array([2.0]), t0, g=(g, 0.0))
        solver = cls(s)
        for _ in range(5):
            solver.step(h)
        t = s.get_time()
        q, v = s.get_state()
        assert v == pytest.approx(2.0 + g * t, rel=1e-13)
        assert (abs(q - (1.0 + 2.0 * t + 0.5 * g * t * t)) < 1e-12) == exact
        assert cls.facts.exact_when_acceleration_is_constant == exact


def test_time_dependent_accelerations_are_read_at_the_right_times():
    h, t0 = 0.25, 2.0
    for cls, (q1, v1) in {
        SymplecticEuler: (1.0 + h * (h * t0), h * t0),
        LectureUpdate: (1.0 + 0.5 * h * (h * t0), h * t0),
        VelocityVerlet: (1.0 + h * 0.5 * h * t0, 0.5 * h * t0 + 0.5 * h * (t0 + h)),
    }.items():
        s = Damped(np.array([1.0]), np.array([0.0]), t0, g=(0.0, 1.0))
        cls(s).step(h)
        np.testing.assert_allclose(s.get_state(), [q1, v1], rtol=1e-15)
        assert s.get_time() == t0 + h


def test_split_solvers_need_a_second_order_system():
    with pytest.raises(TypeError, match="position/velocity split"):
        SymplecticEuler(Linear(A3, Y0))
    assert VelocityVerlet.needs_second_order and not RK4.needs_second_order


def test_explicit_eulers_limit_on_damped_modes_is_closed_form():
    st = Euler.facts.stability
    for zeta in (0.05, 0.3, 0.9):
        assert st.reach(zeta) == pytest.approx(2 * zeta, rel=1e-8)
    for zeta in (1.5, 4.0):
        assert st.reach(zeta) == pytest.approx(2 / (zeta + math.sqrt(zeta * zeta - 1)), rel=1e-8)
    assert st.reach(0.0) == st.imaginary == 0.0
    assert st.reach(-0.1) is None and st.reach(float("nan")) is None
    # the spectral radius of one step: |1 + lambda h| with lambda h = omega h (-zeta +- i sqrt(1-zeta^2))
    w, z = 0.4, 0.25
    assert st.radius(w, z) == pytest.approx(math.sqrt(1 - 2 * z * w + w * w), rel=1e-13)
    assert ImplicitEuler.facts.stability.reach(0.3) == float("inf")


def test_tableau_stability_limits_are_the_known_values():
    rk4 = RK4.facts.stability
    assert rk4.imaginary == pytest.approx(2 * math.sqrt(2), rel=1e-9)
    assert rk4.real == pytest.approx(2.785293563405282, rel=1e-9)
    for cls in (Euler, Midpoint, Heun):
        assert cls.facts.stability.imaginary == 0.0
        assert cls.facts.stability.real == pytest.approx(2.0, rel=1e-12)
    dp = DormandPrince54.facts.stability
    # independent: |R(z)| from (I - z A)^-1 on a fine grid of the axes
    a, b = DormandPrince54.A[:6, :6], DormandPrince54.B[:6]

    def r(z):
        return abs(1 + z * b @ np.linalg.solve(np.eye(6) - z * a, np.ones(6)))

    assert r(-dp.real * (1 - 1e-6)) <= 1 + 1e-9 < r(-dp.real * (1 + 1e-4))
    assert r(1j * dp.imaginary * (1 - 1e-4)) <= 1 + 1e-9 < r(1j * dp.imaginary * (1 + 1e-3))
    assert 3.3 < dp.real < 3.31 and 0.99 < dp.imaginary < 1.0
    # a tableau whose |R(i y)| starts above 1 (explicit Euler's) has imaginary 0
    assert tableau_stability(np.array([[0.0]]), np.array([1.0]), order=1).imaginary == 0.0


def test_stability_scans_and_validation():
    assert first_growth(lambda y: 0.5) == float("inf")
    assert first_growth(lambda y: 2.0) == 0.0
    assert first_growth(lambda y: 1.0 + y, lo=1e-3, hi=1.0) == pytest.approx(1e-12, abs=1e-3)
    assert first_growth(lambda y: 0.5 + y, lo=1e-3, hi=10.0) == pytest.approx(0.5, rel=1e-12)
    assert first_growth(lambda y: 1.0 + max(0.0, y - 2.0), lo=1e-3, hi=10.0) == pytest.approx(
        2.0 + 1e-12, rel=1e-9
    )
    assert spectral_radius(np.array([[0.0, 2.0], [-2.0, 0.0]])) == pytest.approx(2.0)
    with pytest.raises(ValueError, match="non-negative"):
        Stability(imaginary=-1.0, real=1.0)
    with pytest.raises(ValueError, match="non-negative"):
        Stability(imaginary=1.0, real=-1.0)
    with pytest.raises(ValueError, match="A-stable"):
        Stability(imaginary=1.0, real=float("inf"), a_stable=True)
    with pytest.raises(ValueError, match="A-stable"):
        Stability(imaginary=float("inf"), real=1.0, a_stable=True)
    bare = Stability(imaginary=1.0, real=1.0)
    assert bare.reach(0.5) is None and bare.reach(0.0) == 1.0
    with pytest.raises(ValueError, match="no step_matrix"):
        bare.radius(0.1, 0.1)
    for bad in (
        {"order": 0},
        {"order": True},
        {"order": 1.0},
        {"velocity_order": 0},
        {"evaluations_per_step": 0},
        {"evaluations_per_step": True},
        {"evaluations_per_step": 1.5},
    ):
        kw = {"order": 1, "evaluations_per_step": 1, "symplectic": False} | bad
        with pytest.raises(ValueError, match="positive integer"):
            MethodFacts(**kw)
    f = MethodFacts(order=2, evaluations_per_step=None, symplectic=True, velocity_order=1)
    assert f.order_for(velocity_forces=True) == 1 and f.order_for(velocity_forces=False) == 2
    g = MethodFacts(order=2, evaluations_per_step=1, symplectic=False)
    assert g.order_for(velocity_forces=True) == 2 and g.exact_when_acceleration_is_constant
    assert not MethodFacts(
        order=1, evaluations_per_step=1, symplectic=False
    ).exact_when_acceleration_is_constant


def test_the_registry_and_the_evaluation_count():
    assert get_solver("rk4") is RK4 and get_solver(Heun) is Heun
    with pytest.raises(KeyError, match="unknown method 'nope'; known: euler, midpoint"):
        get_solver("nope")
    assert {cls.name: cls.order for cls in METHODS.values()} == {
        "euler": 1,
        "midpoint": 2,
        "heun": 2,
        "rk4": 4,
        "dopri5": 5,
        "symplectic-euler": 1,
        "verlet": 2,
        "implicit-euler": 1,
        "lecture": 1,
    }
    assert [cls.adaptive for cls in METHODS.values()].count(True) == 1
    s = Damped(np.array([1.0]), np.array([0.0]), w2=1.0)
    solver = RK4(s)
    solver.step(0.1)
    solver.accel(np.array([1.0]), np.array([0.0]), 0.0)
    assert solver.nfev == 5


def test_method_facts_are_immutable_shared_data():
    import dataclasses

    for facts in (RK4.facts, RK4.facts.stability):
        with pytest.raises(dataclasses.FrozenInstanceError):
            facts.order = 3  # type: ignore[misc]
        assert hash(facts) == hash(dataclasses.replace(facts))  # hashable, by value
    assert len({cls.facts for cls in (Euler, Midpoint, Euler)}) == 2


def test_a_stability_function_that_touches_minus_one_is_stable_past_the_touch():
    # R(z) = 1 + z + z^2 / 8: R(-x) = 1 - x + x^2 / 8 reaches -1 at x = 4 without
    # crossing it (a double root of R + 1) and leaves [-1, 1] at x = 8.
    a, b = np.array([[0.0, 0.0], [0.5, 0.0]]), np.array([0.75, 0.25])
    np.testing.assert_allclose(stability_polynomial(a, b), [1.0, 1.0, 0.125])
    x = np.linspace(0.0, 8.0, 801)
    assert np.max(np.abs(1 - x + x * x / 8)) <= 1.0 + 1e-15 < abs(1 - 8.01 + 8.01**2 / 8)
    st = tableau_stability(a, b, order=1)
    assert st.real == pytest.approx(8.0, rel=1e-9)
    assert st.imaginary == 0.0  # |R(iy)|^2 = 1 + y^2 (1 - 1/4) + ...: grows at once


def test_velocity_verlet_is_first_order_with_a_damper_and_second_without():
    def error(c, h, t_end=2.0):
        s = Damped(np.array([1.0]), np.array([0.0]), w2=1.0, c=c)
        solver = VelocityVerlet(s)
        for _ in range(round(t_end / h)):
            solver.step(h)
        wd = math.sqrt(1 - c * c / 4)
        exact = math.exp(-c * t_end / 2) * (math.cos(wd * t_end) + c / (2 * wd) * math.sin(wd * t_end))
        return abs(s.get_state()[0] - exact)

    damped = math.log2(error(0.5, 0.02) / error(0.5, 0.01))
    undamped = math.log2(error(0.0, 0.02) / error(0.0, 0.01))
    assert abs(damped - 1.0) < 0.15 and abs(undamped - 2.0) < 0.15
    facts = VelocityVerlet.facts
    assert facts.order_for(velocity_forces=True) == 1 and facts.order_for(velocity_forces=False) == 2
    for cls in (SymplecticEuler, LectureUpdate, RK4, Heun, ImplicitEuler):
        assert cls.facts.order_for(velocity_forces=True) == cls.facts.order


def test_a_narrow_bump_above_one_ends_the_real_stability_interval():
    # R(-x) = 1 + x p(x), p(x) = -(1 - x)(1 - x / 1.5)(1 - x / 3): |R(-x)| <= 1 on [0, 1],
    # above 1 on (1, 1.5), back below 1 on (1.5, 3): the stable interval is [0, 1].
    s1, s2, s3 = 1 + 1 / 1.5 + 1 / 3, 1 / 1.5 + 1 / 3 + 1 / 4.5, 1 / 4.5
    a = np.diag([1.0, 1.0, 1.0], k=-1)
    b = np.array([1 - s1, s1 - s2, s2 - s3, s3])
    np.testing.assert_allclose(stability_polynomial(a, b), [1, 1, s1, s2, s3], rtol=1e-14)

    def r_minus(x):
        return 1 - x + s1 * x**2 - s2 * x**3 + s3 * x**4

    x = np.linspace(0.0, 1.0, 1001)
    assert np.all(np.abs(r_minus(x)) <= 1 + 1e-15) and r_minus(1.2) > 1 and abs(r_minus(2.0)) < 1
    assert tableau_stability(a, b, order=1).real == pytest.approx(1.0, rel=1e-9)


def test_finite_difference_jacobians_step_by_at_least_sqrt_eps():
    a = A3.copy()
    a[0] = 0.0  # the first coordinate stays exactly 0
    y0 = np.array([0.0, -0.5, 1.3])
    h = 0.3
    s = Linear(a, y0, jac=False)
    ImplicitEuler(s).step(h)
    np.testing.assert_allclose(s.get_state(), np.linalg.solve(np.eye(3) - h * a, y0), rtol=1e-9)


def test_the_step_matrix_is_left_out_of_the_stability_repr():
    text = repr(RK4.facts.stability)
    assert text.startswith("Stability(imaginary=") and "step_matrix" not in text


def test_implicit_euler_rebuilds_at_an_iterate_when_the_predictor_s_matrix_is_slow():
    """Found by the mutation run: from y0 = 2 at h = 0.4 the matrix built at the predictor
    makes Newton converge slowly (updates shrink ~0.55 per iteration); it is rebuilt at the
    current iterate, as the docstring says, and the step solves the quadratic."""
    y0, h = 2.0, 0.4
    solver = ImplicitEuler(Riccati(y0, jac=True))
    solver.step(h)
    assert solver.n_jac == 2
    assert solver.system.get_state()[0] == pytest.approx((-1 + math.sqrt(1 + 4 * h * y0)) / (2 * h), rel=1e-9)
