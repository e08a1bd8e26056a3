"""dopri5 after its speed-up: the same steps, evaluations and numbers as before it.

Three routes to the claim:

1. the step as it was written before (:class:`TextbookDopri5`: each stage's argument
   summed row by row, the RMS norm by ``np.mean``), run beside
   :class:`~truestep.reference_impl.solvers.DormandPrince54` on the same scenes: the same
   trajectory to the last bit, the same accepted steps and evaluations;
2. numbers recorded from the code before the speed-up (:data:`BEFORE`): accepted steps
   and ``nfev`` exactly, final states to round-off;
3. scipy's RK45, the same tableau, norm and controller: the same steps and ``nfev``
   where the two agreed before, final states to round-off.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from truestep.adapters import get_adapter
from truestep.adapters.reference import build_system
from truestep.reference_impl.integrate import BLOWUP, Run, _finite, _well_inside, integrate
from truestep.reference_impl.solvers import RK4, DormandPrince54
from truestep.reference_impl.solvers.explicit_rk import Stages, rk_stages, stages_of
from truestep.reference_impl.system import System

BEFORE: dict[tuple[str, float], tuple[int, int, list[float]]] = {
    # (case, tolerance): (accepted steps, nfev, final state), from the reference adapter's
    # dopri5 before the speed-up (commit 2c7ccd8, x86-64). The final state is the whole
    # state for an ODE case; for a particle scene the position and velocity of its first
    # particle, then of its last.
    ("arenstorf-orbit", 1e-06): (
        132,
        1004,
        [0.9940240003771242, 0.00010122550230045159, 0.016266010125374153, -1.9976650669076321],
    ),
    ("arenstorf-orbit", 1e-08): (
        320,
        2114,
        [0.9939995551165938, -8.905028691476085e-07, -0.000147530534280918, -2.0016543505471343],
    ),
    ("arenstorf-orbit", 1e-10): (
        794,
        4772,
        [0.9939999922483008, -1.995806338218279e-08, -3.2712560716664785e-06, -2.0015863131915537],
    ),
    ("kepler-orbit", 1e-06): (
        94,
        746,
        [0.4000092260929083, -4.941399139173769e-05, 8.677148786603861e-05, 1.9999614588916232],
    ),
    ("kepler-orbit", 1e-08): (
        222,
        1370,
        [0.4000000326167521, -4.206044917697688e-06, 1.2710292828226055e-05, 1.9999998703704254],
    ),
    ("close-encounter", 1e-06): (
        305,
        2324,
        [
            -1.1378697835451124,
            -1.2820922686593954,
            0.0,
            0.7629872506421028,
            0.6555921338021603,
            0.0,
            -1.2737523054606112,
            -1.2355603531277985,
            0.0,
            -1.7630456473570921,
            -1.8437586418206955,
            0.0,
        ],
    ),
    ("close-encounter", 1e-08): (
        737,
        4838,
        [
            -1.1384691116033578,
            -1.2826549328725505,
            0.0,
            0.7813919246427723,
            0.6482965515498526,
            0.0,
            -1.2733815033133447,
            -1.2350728689725174,
            0.0,
            -1.7815809012490946,
            -1.836519077402772,
            0.0,
        ],
    ),
    ("circle-field", 1e-05): (16, 98, [0.9999780378941382, 2.0052135973960827e-05]),
    ("circle-field", 1e-09): (94, 566, [0.9999999974209434, 3.042092185795431e-10]),
    ("spring-chain", 1e-06): (
        159,
        1004,
        [
            0.09771289487391474,
            0.0,
            0.0,
            1.3213472963485684,
            0.0,
            0.0,
            0.2800714559722241,
            0.0,
            0.0,
            2.958993234403833,
            0.0,
            0.0,
        ],
    ),
    ("spring-chain", 1e-08): (
        399,
        2408,
        [
            0.09771870051034491,
            0.0,
            0.0,
            1.3212271118223868,
            0.0,
            0.0,
            0.28007051764033875,
            0.0,
            0.0,
            2.958979922786661,
            0.0,
            0.0,
        ],
    ),
    ("hanging-cloth", 1e-04): (
        326,
        2252,
        [
            0.0,
            1.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.7004601531757786,
            0.28896835711728935,
            0.0056273161127085,
            4.3915830852412764e-05,
            -1.455662906089871e-05,
            -0.003831417118886127,
        ],
    ),
    ("spring-damper-pair", 1e-06): (
        23,
        152,
        [
            0.6518735193678133,
            1.0,
            0.0,
            1.1470988031948064,
            1.0,
            0.0,
            1.6493754935440625,
            1.0,
            0.0,
            0.28430039893506487,
            1.0,
            0.0,
        ],
    ),
    ("spring-damper-pair", 1e-08): (
        56,
        344,
        [
            0.6518733385557235,
            0.9999999999999997,
            0.0,
            1.1471102676763232,
            1.0,
            0.0,
            1.649375553814759,
            0.9999999999999997,
            0.0,
            0.284296577441226,
            1.0,
            0.0,
        ],
    ),
    # Collisions between the steps, and an emitter (an observed ``alive`` per record).
    ("bouncing-ball", 1e-04): (7, 110, [0.0, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 0.0]),
    ("particle-fountain", 1e-04): (
        30,
        236,
        [
            0.01590686260198923,
            0.6872307931956028,
            0.10911231377729383,
            -0.19258380019061336,
            -1.3369081296404475,
            0.3327362847885536,
            0.16535705617749294,
            0.09186648900030531,
            -0.7140433247098886,
            0.4983328057958335,
            -3.156962156913829,
            -1.8784259410968824,
        ],
    ),
}
FOUNTAIN_ALIVE = ((31, 1200), 18781)
"""particle-fountain at 1e-4 before the speed-up: the shape of ``extra["alive"]`` (one
row per record, one column per pool slot) and how many particle-records were alive."""

ROUND_OFF = {"arenstorf-orbit": 2e-9}
"""Largest difference (in the state's units) between two roundings of the same run. The
Arenstorf orbit's two close passes by the Earth amplify round-off: our dopri5 and scipy's
RK45, the same algorithm with its sums in another order, end 2e-10 apart at rtol 1e-8
(measured); the other scenes 5e-13 at most, hence :data:`ROUND_OFF_DEFAULT`."""
ROUND_OFF_DEFAULT = 1e-11

ROUNDED_STEPS = {"hanging-cloth"}
"""Scenes whose step sequence is set by round-off: dopri5 rides the cloth's stability
limit, where the error estimate amplifies the last bits of the state until a step just
accepted or rejected turns the other way (the same algorithm rounded as scipy does it
takes 325 steps and 2264 evaluations, not 326 and 2252). Their recorded counts hold where
the code before the speed-up rounds as it did on the recording machine."""


class TextbookDopri5(DormandPrince54):
    """The dopri5 step as written before its speed-up, kept as the oracle: each stage's
    argument ``x + sum_j (h a_ij) k_j`` summed row by row, the RMS norm by ``np.mean``. It
    keeps no continuous extension, so it steps through impacts as dopri5 did then."""

    dense = None

    def _initial_step(self, x: np.ndarray, t: float, f0: np.ndarray, h_max: float) -> float:
        scale = self.atol + np.abs(x) * self.rtol
        d0 = _textbook_rms(x / scale)
        d1 = _textbook_rms(f0 / scale)
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, h_max)
        f1 = self.fun(x + h0 * f0, t + h0)
        d2 = _textbook_rms((f1 - f0) / scale) / h0
        if d1 <= 1e-15 and d2 <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1 / (self.error_order + 1))
        return min(100 * h0, h1, h_max)

    def step(self, dt: float) -> float:
        x, t = self.system.get_state(), self.system.get_time()
        if self._f0 is None or not np.array_equal(x, self._x_end):  # an event moved it
            self._f0 = self.fun(x, t)
        if self._h is None:
            self._h = self._initial_step(x, t, self._f0, dt)
        h = min(self._h, dt)
        rejected = False
        while True:
            k = self._k
            k[0] = self._f0
            for i in range(1, 6):
                xi = x
                for j in np.flatnonzero(self.A[i, :i]):
                    xi = xi + (h * float(self.A[i, j])) * k[j]
                k[i] = self.fun(xi, t + float(self.A[i].sum()) * h)
            x_new = x + h * (self.B[:6] @ k[:6])
            self._k[6] = self.fun(x_new, t + h)
            scale = self.atol + np.maximum(np.abs(x), np.abs(x_new)) * self.rtol
            err = _textbook_rms(h * (self.E @ self._k) / scale)
            if err <= 1.0:
                factor = self.max_factor if err == 0 else self.safety * err**-0.2
                factor = min(self.max_factor, factor)
                if rejected:
                    factor = min(1.0, factor)
                self._h = h * factor
                break
            if not np.isfinite(err):
                factor = self.min_factor
            else:
                factor = max(self.min_factor, self.safety * err**-0.2)
            h *= factor
            rejected = True
            self.n_rejected += 1
            if h < 1e-14 * max(1.0, abs(t)):
                raise FloatingPointError(f"dopri5: step size underflow at t={t:.6g}")
        self._f0 = self._k[6].copy()
        self._x_end = x_new
        self.system.set_state(x_new, t + h)
        return h


def _textbook_rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def run_case(case, cls: type[DormandPrince54], tol: float) -> Run:
    """``cls`` on the case's numpy system at rtol = atol = ``tol``, as the adapter runs it."""
    system = build_system(case)
    return integrate(
        cls(system, rtol=tol, atol=tol), case.duration, case.duration, max_records=case.max_records
    )


def final_state(case, run: Run) -> np.ndarray:
    """What :data:`BEFORE` records of a run's last state."""
    x = run.x[-1]
    if case.kind == "ode":
        return x
    n = case.model.n
    q, v = x[: 3 * n].reshape(n, 3), x[3 * n :].reshape(n, 3)
    return np.concatenate([q[0], v[0], q[-1], v[-1]])


RECORDED_DURATIONS = {"kepler-orbit": 18.84955592153876, "circle-field": 6.283185307179586}
"""Scenes whose run was longer when :data:`BEFORE` was recorded (three periods and one
turn, before every step had to divide the duration): they are run as they were."""


def recorded_case(case):
    """The case as it was when :data:`BEFORE` was recorded."""
    duration = RECORDED_DURATIONS.get(case.name)
    return case if duration is None else dataclasses.replace(case, duration=duration)


@pytest.fixture(scope="module")
def runs(case_named):
    """Each recorded (case, tolerance) run by the solver and by the oracle, once each;
    ``get(name, tol, oracle=False)`` runs the solver only (the oracle's Python step is the
    slow one)."""
    cache: dict[tuple[str, float, type], Run] = {}

    def one(name: str, tol: float, solver: type) -> Run:
        if (name, tol, solver) not in cache:
            cache[name, tol, solver] = run_case(recorded_case(case_named(name)), solver, tol)
        return cache[name, tol, solver]

    def get(name: str, tol: float, *, oracle: bool = True) -> tuple[Run, Run | None]:
        return one(name, tol, DormandPrince54), one(name, tol, TextbookDopri5) if oracle else None

    return get


SMOOTH = [key for key in BEFORE if key[0] not in ("bouncing-ball", "particle-fountain")]
"""The recorded scenes without planes: on the others dopri5 now stops its steps at impacts,
which the textbook step (and the code before) did not."""


@pytest.mark.parametrize(("name", "tol"), SMOOTH, ids=[f"{n}-{t:g}" for n, t in SMOOTH])
def test_the_same_run_as_the_textbook_step_to_the_last_bit(runs, name, tol):
    new, old = runs(name, tol)
    assert (new.status, new.steps, new.nfev) == (old.status, old.steps, old.nfev)
    np.testing.assert_array_equal(new.t, old.t)
    np.testing.assert_array_equal(new.x, old.x)
    assert new.extra.keys() == old.extra.keys()
    for key in new.extra:
        np.testing.assert_array_equal(new.extra[key], old.extra[key])


EVENTS = {"bouncing-ball", "particle-fountain"}
"""Scenes where something between the steps (a collision, an emitter) changes the state.
Since the first stage is evaluated afresh after such a change (before, the derivative at
the state the step had ended at was reused), their runs differ from :data:`BEFORE`."""
UNCHANGED = [key for key in BEFORE if key[0] not in EVENTS]


@pytest.mark.parametrize(("name", "tol"), UNCHANGED, ids=[f"{n}-{t:g}" for n, t in UNCHANGED])
def test_the_steps_evaluations_and_states_recorded_before(case_named, runs, name, tol):
    steps, nfev, state = BEFORE[name, tol]
    new, old = runs(name, tol)
    if name in ROUNDED_STEPS and (old.steps, old.nfev) != (steps, nfev):
        pytest.skip(
            f"{name}: the code before the speed-up rounds otherwise on this machine "
            f"({old.steps} steps, {old.nfev} evaluations)"
        )
    assert new.status == "ok"
    assert (new.steps, new.nfev) == (steps, nfev)
    np.testing.assert_allclose(
        final_state(recorded_case(case_named(name)), new),
        state,
        rtol=0,
        atol=ROUND_OFF.get(name, ROUND_OFF_DEFAULT),
    )


def test_the_observed_extras_are_kept_per_record(case_named):
    """The fountain's first half second (its emitter fills part of the pool) keeps one
    row of ``alive`` per record, one column per pool slot."""
    case = dataclasses.replace(recorded_case(case_named("particle-fountain")), duration=0.5)
    new = run_case(case, DormandPrince54, 1e-4)
    pool = FOUNTAIN_ALIVE[0][1]
    assert new.extra["alive"].shape == (len(new.t), pool)
    assert 0 < int(new.extra["alive"].sum()) <= len(new.t) * pool


class Flipped(System):
    """``x' = -x`` whose state is negated by the first event after t = 0.3 (a stand-in for
    a collision: a change between the steps that the derivative does not know of)."""

    def __init__(self) -> None:
        super().__init__(np.array([1.0, 2.0]))
        self.flipped_at: tuple[np.ndarray, float] | None = None
        self.evaluated: list[tuple[np.ndarray, float]] = []

    def derivative(self, x: np.ndarray, t: float) -> np.ndarray:
        self.evaluated.append((x.copy(), t))
        return -x

    def between_steps(self, dt: float) -> None:
        if self.flipped_at is None and self.get_time() > 0.3:
            x = -self.get_state()
            self.set_state(x, self.get_time())
            self.flipped_at = (x, self.get_time())


def test_after_an_event_the_first_stage_is_the_derivative_at_the_changed_state():
    system = Flipped()
    run = integrate(DormandPrince54(system, rtol=1e-8, atol=1e-8), 1.0, 1.0)
    x, t = system.flipped_at
    after = [k for k, (xk, tk) in enumerate(system.evaluated) if tk == t]
    assert any(np.array_equal(system.evaluated[k][0], x) for k in after)
    # and the solution after the event is the exact one from the flipped state
    later = run.t > t
    exact = x[None, :] * np.exp(-(run.t[later] - t))[:, None]
    np.testing.assert_allclose(run.x[later], exact, rtol=1e-6, atol=0)


AGREED_WITH_SCIPY = [
    key for key in BEFORE if key[0] not in ROUNDED_STEPS | {"bouncing-ball", "particle-fountain"}
]
"""Where scipy's RK45 took the same steps and evaluations before (it models no collisions
or emitters; on the cloth the two round apart, :data:`ROUNDED_STEPS`)."""


@pytest.mark.parametrize(("name", "tol"), AGREED_WITH_SCIPY, ids=[f"{n}-{t:g}" for n, t in AGREED_WITH_SCIPY])
def test_the_steps_evaluations_and_states_of_scipys_rk45(case_named, runs, name, tol):
    case = recorded_case(case_named(name))
    theirs = get_adapter("scipy").simulate(case, "RK45", tol)
    new, _ = runs(name, tol, oracle=False)
    assert (new.steps, new.nfev) == (theirs.steps, theirs.nfev)
    ours = new.x[-1]
    if case.kind == "ode":
        np.testing.assert_allclose(ours, theirs.x[-1, 0], rtol=0, atol=ROUND_OFF.get(name, ROUND_OFF_DEFAULT))
    else:
        n = case.model.n
        np.testing.assert_allclose(ours[: 3 * n].reshape(n, 3), theirs.x[-1], rtol=0, atol=ROUND_OFF_DEFAULT)
        np.testing.assert_allclose(ours[3 * n :].reshape(n, 3), theirs.v[-1], rtol=0, atol=ROUND_OFF_DEFAULT)


class Riccati(System):
    """``x' = x^2``: the first component ``1 / (1 - t)`` leaves every bound at t = 1."""

    def derivative(self, x: np.ndarray, t: float) -> np.ndarray:
        with np.errstate(over="ignore", invalid="ignore"):
            return x * x


@pytest.mark.parametrize(
    ("tol", "steps", "nfev", "t_fail"),
    [
        # Recorded before the speed-up: the first state beyond BLOWUP ends the run, recorded.
        (1e-6, 172, 2054, 1.0000006495122762),
        (1e-9, 672, 4034, 0.9999999999458525),
    ],
)
def test_a_blow_up_ends_an_adaptive_run_at_the_same_step(tol, steps, nfev, t_fail):
    run = integrate(DormandPrince54(Riccati(np.array([1.0, 0.5])), rtol=tol, atol=tol), 3.0, 3.0)
    assert (run.status, run.steps, run.nfev, len(run.t)) == ("unstable", steps, nfev, steps + 1)
    assert run.t_fail == run.t[-1] == pytest.approx(t_fail, rel=1e-12)
    assert not _finite(run.x[-1]) and all(_finite(x) for x in run.x[:-1])


def test_the_quick_blow_up_check_never_passes_what_the_full_one_fails():
    below = np.nextafter(BLOWUP, 0.0)
    states = [
        np.array(v)
        for v in (
            [],
            [0.0],
            [below],
            [-below],
            [BLOWUP],
            [-BLOWUP],
            [np.nan],
            [np.inf],
            [-np.inf],
            [1.0, np.nan],
            [1e200, 1.0],
            [below] * 3,
            [0.7 * BLOWUP] * 3,
            [1e-300, -1e-300],
        )
    ]
    for x in states:
        with np.errstate(over="ignore"):  # 1e200 squared: the sum overflows, as it may
            assert not _well_inside(x) or _finite(x), x
    assert _well_inside(np.array([below * 0.5, 1.0])) and _well_inside(np.zeros(5))


def _gappy_tableau() -> np.ndarray:
    """A made-up tableau whose stages feed runs of one and of several later stages, with a
    gap (``a[4, 0] = 0``), to exercise every kind of feed."""
    a = np.zeros((6, 6))
    a[1, 0] = 0.3
    a[2, :2] = [0.1, 0.4]
    a[3, :3] = [0.2, -0.3, 0.9]
    a[4, 1:4] = [0.5, 0.1, 0.2]
    a[5, :5] = [0.15, 0.05, 0.3, -0.25, 0.6]
    return a


@pytest.mark.parametrize(
    "a", [DormandPrince54.A[:6], RK4.A, _gappy_tableau()], ids=["dopri5", "rk4", "gappy"]
)
@pytest.mark.parametrize("dim", [1, 4, 384])
def test_stages_summed_by_column_are_the_rows_to_the_last_bit(a, dim):
    stages = stages_of(a)
    by_rows = Stages(stages.rows, None)
    rng = np.random.default_rng(dim)
    x, k0 = rng.standard_normal(dim), rng.standard_normal(dim)

    def fun(y: np.ndarray, t: float) -> np.ndarray:
        return np.sin(3.0 * y) * (1.0 + t) - 0.7 * y

    for first in (None, k0):
        k1 = rk_stages(fun, x, 0.3, 0.0123, stages, np.empty((len(a), dim)), first)
        k2 = rk_stages(fun, x, 0.3, 0.0123, by_rows, np.empty((len(a), dim)), first)
        np.testing.assert_array_equal(k1, k2)
    assert (stages.columns is None) == (a is RK4.A)
