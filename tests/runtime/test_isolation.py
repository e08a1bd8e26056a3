"""Isolated calls: a crash, a hang or a dying process becomes an outcome, in order."""

from __future__ import annotations

import os
import time

from truestep.runtime.isolation import run_isolated, run_isolated_all


def _square(x: int) -> int:
    return x * x


def _fail() -> None:
    raise ValueError("bad scene")


def _hang() -> None:
    time.sleep(60)


def _die() -> None:
    os._exit(3)


def test_one_call_returns_its_value_or_why_not():
    assert run_isolated(_square, (7,), 10.0).value == 49
    crashed = run_isolated(_fail, (), 10.0)
    assert crashed.status == "crashed" and "ValueError: bad scene" in crashed.message
    died = run_isolated(_die, (), 10.0)
    assert died.status == "crashed" and "exit code 3" in died.message


def test_many_calls_keep_their_order_and_a_hang_times_out_alone():
    calls = [(_square, (k,), 10.0) for k in range(5)]
    calls.insert(2, (_hang, (), 0.5))
    calls.insert(4, (_fail, (), 10.0))
    seen = []
    start = time.monotonic()
    out = run_isolated_all(calls, workers=2, done=lambda k, o: seen.append(k))
    assert time.monotonic() - start < 20
    assert [o.status for o in out] == ["ok", "ok", "timeout", "ok", "crashed", "ok", "ok"]
    assert [o.value for o in out if o.status == "ok"] == [0, 1, 4, 9, 16]
    assert sorted(seen) == list(range(len(calls)))


def test_a_sweep_that_loses_its_process_is_rerun_step_by_step(monkeypatch):
    """One step of a sweep kills its process: the sweep is run again a step per process,
    and only that step's row says crashed; a step that raises is a crashed row without
    losing the others."""
    from truestep.cases import load_cases
    from truestep.execution import runner

    case = load_cases("harmonic-oscillator")[0]
    real = runner.simulate_timed

    def flaky(engine, case, method, dt, timing, **kw):
        if dt == 1e-3:
            os._exit(7)
        if dt == 5e-4:
            raise ValueError("no such step")
        return real(engine, case, method, dt, timing, **kw)

    monkeypatch.setattr(runner, "simulate_timed", flaky)
    rows = runner.run_sweep(
        case,
        "reference",
        "symplectic-euler",
        [2e-3, 1e-3, 5e-4],
        adaptive=False,
        timing=runner.Timing(long_run_s=0.0),
    )
    assert [r["status"] for r in rows] == ["ok", "crashed", "crashed"]
    assert "exit code 7" in rows[1]["message"]
    assert "ValueError: no such step" in rows[2]["message"]
    assert rows[0]["error"] < 2e-3  # the worst over the run: 1.03e-3


def test_compiled_loops_loaded_before_forking_still_run_in_the_children():
    """preload() compiles the reference's stepping loop in the parent; a forked run of the
    compiled path (bouncing-ball, lecture) must then still run, not be killed."""
    from truestep.cases import load_cases
    from truestep.execution import runner

    runner.preload()
    case = load_cases("bouncing-ball")[0]
    rows = runner.run_sweep(
        case, "reference", "lecture", [0.004], adaptive=False, timing=runner.Timing(long_run_s=0.0)
    )
    assert rows[0]["status"] == "ok", rows[0].get("message")
    assert rows[0]["path"] == "compiled"


def _span(seconds: float) -> tuple[float, float]:
    """Sleep ``seconds``; the (start, end) of the call, ``time.monotonic()``."""
    start = time.monotonic()
    time.sleep(seconds)
    return start, time.monotonic()


def _lanes(cores: int, timed_s: float = 0.2, untimed_s: float = 0.2) -> tuple[dict, dict, list]:
    """Three timed calls of ``timed_s`` and four untimed ones of ``untimed_s`` through
    ``run_lanes`` on ``cores``; their spans, which lane each is in, and (call, when) for
    every ``done``."""
    from truestep.runtime.isolation import run_lanes

    timed, untimed = [0, 1, 2], [3, 4, 5, 6]
    spans: dict[int, tuple[float, float]] = {}
    log: list[tuple[int, float]] = []

    def done(j, outcome):
        assert outcome.status == "ok", outcome.message
        spans[j] = outcome.value
        log.append((j, time.monotonic()))

    run_lanes(
        timed, untimed, lambda j: (_span, (timed_s if j in timed else untimed_s,), 30.0), done, cores=cores
    )
    return spans, {j: j in timed for j in spans}, log


def _overlap(a: tuple[float, float], b: tuple[float, float]) -> bool:
    return a[0] < b[1] and b[0] < a[1]


def test_timed_calls_run_alone_and_untimed_ones_on_the_cores_left():
    """On two cores: the timed calls one at a time, never beside more than one other call,
    and no untimed call's outcome is handled (measured) while a timed call runs; on one
    core no call overlaps a timed one. Every call is done once."""
    for cores in (2, 1):
        spans, is_timed, log = _lanes(cores)
        assert sorted(spans) == list(range(7)) and len(log) == 7
        timed = [spans[j] for j in spans if is_timed[j]]
        assert not any(_overlap(a, b) for i, a in enumerate(timed) for b in timed[i + 1 :])
        for a in timed:
            beside = [s for j, s in spans.items() if not is_timed[j] and _overlap(a, s)]
            for s in beside:  # at no moment more than cores - 1 untimed calls beside it
                assert sum(_overlap(s, other) for other in beside if other is not s) == 0 or cores > 2
            assert cores > 1 or not beside
            handled = [t for j, t in log if not is_timed[j]]
            assert not any(a[0] < t < a[1] for t in handled)
    spans, is_timed, _ = _lanes(2)
    untimed = [spans[j] for j in spans if not is_timed[j]]
    assert any(_overlap(a, b) for a in untimed for b in spans.values() if a is not b)  # cores shared


def test_the_untimed_core_does_not_wait_for_a_long_timed_call():
    """Timed calls of 1 s and untimed ones of 0.1 s on two cores: the untimed calls follow
    one another beside the first timed call, not one per gap between timed calls."""
    spans, is_timed, _ = _lanes(2, timed_s=1.0, untimed_s=0.1)
    first = min((spans[j] for j in spans if is_timed[j]), key=lambda s: s[0])
    beside = [spans[j] for j in spans if not is_timed[j] and _overlap(first, spans[j])]
    assert len(beside) >= 3


class _Sleeps:
    """A backlog (:class:`truestep.runtime.isolation.Backlog`) of ``n`` calls of
    :func:`_span`, recording when each was made (just before its fork) and its span."""

    def __init__(self, n: int, seconds: float) -> None:
        self.n, self.seconds = n, seconds
        self.made: dict[int, float] = {}
        self.spans: dict[int, tuple[float, float]] = {}

    def __len__(self) -> int:
        return self.n

    def call(self, k):
        self.made[k] = time.monotonic()
        return (_span, (self.seconds,), 30.0)

    def done(self, k, outcome):
        assert outcome.status == "ok" and k not in self.spans, outcome.message
        self.spans[k] = outcome.value


def test_a_backlog_fills_the_cores_the_timed_calls_leave_across_runs():
    """On two cores, a backlog of untimed calls starts beside the first timed call, goes on
    across two ``run`` calls, leaves a core free for a timed run made outside the lanes
    (``free_core``: no backlog call starts until ``finish``), and is all done once by
    ``finish``; no timed call ever runs beside more than one other call."""
    from truestep.runtime.isolation import Lanes

    backlog = _Sleeps(6, 0.3)
    timed: dict[tuple[int, int], tuple[float, float]] = {}
    handled: list[float] = []

    def done_in(run: int):
        def done(j, outcome):
            assert outcome.status == "ok", outcome.message
            timed[run, j] = outcome.value
            handled.append(time.monotonic())

        return done

    with Lanes(2, [backlog]) as lanes:
        lanes.run([0, 1], [], lambda j: (_span, (0.3,), 30.0), done_in(1))
        lanes.run([0], [], lambda j: (_span, (0.3,), 30.0), done_in(2))
        lanes.free_core()
        freed = time.monotonic()
        started_before = set(backlog.made)
        time.sleep(0.4)  # what runs outside the lanes: nothing of the backlog starts meanwhile
        assert set(backlog.made) == started_before
        lanes.finish()
    assert sorted(backlog.spans) == list(range(6)) and len(timed) == 3
    assert min(backlog.made.values()) < handled[0]  # the first started beside the first timed call
    running_when_freed = [s for s in backlog.spans.values() if s[0] < freed < s[1]]
    assert len(running_when_freed) <= 1
    every = list(timed.values()) + list(backlog.spans.values())
    for a in timed.values():
        assert sum(_overlap(a, b) for b in every if b is not a) <= 1 or _at_most_one_at_a_time(a, every)


def _at_most_one_at_a_time(a: tuple[float, float], spans: list[tuple[float, float]]) -> bool:
    """Whether at every moment of ``a`` at most one other span of ``spans`` runs."""
    others = [b for b in spans if b is not a and _overlap(a, b)]
    edges = sorted({a[0], *(t for b in others for t in b if a[0] < t < a[1])})
    return all(sum(b[0] <= t < b[1] for b in others) <= 1 for t in edges)
