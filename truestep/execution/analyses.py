"""The analyses beyond the main sweep: stability limits, restitution per bounce, and how
cost grows with the number of particles."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import time
from collections.abc import Callable, Iterable, Sequence

import numpy as np
import pandas as pd

from truestep.adapters import PluginFailed, get_adapter, plugin_answer
from truestep.adapters.base import duplicate_of, facts_of
from truestep.adapters.devices import engine_device
from truestep.cases.case import Case
from truestep.cases.exact import stability_limit
from truestep.cases.loader import CASE_DIR, load_case
from truestep.execution.progress import Progress
from truestep.execution.runner import preload, prepare_here
from truestep.measures.energy_scale import energy_scale
from truestep.measures.restitution import PHASE_BAND, PHASES, bounces, heights
from truestep.measures.stability import Hint, SearchResult, SearchTimeout, search_case
from truestep.numerics import own_run
from truestep.runtime import faults
from truestep.runtime.isolation import Call, Lanes, Outcome, run_untimed, untimed_workers
from truestep.tables.spec import RESTITUTION, SCALING, STABILITY

STABILITY_COLUMNS = STABILITY.names
"""The columns of ``stability.csv`` (:data:`truestep.tables.spec.STABILITY`)."""
RESTITUTION_COLUMNS = RESTITUTION.names
"""The columns of ``restitution.csv`` (:data:`truestep.tables.spec.RESTITUTION`)."""

RESTITUTION_SET = (0.0, 0.5, 0.8, 0.9, 1.0)
RESTITUTION_DTS = (1 / 240, 1 / 1000)
QUICK_RESTITUTION_SET = (0.5,)
QUICK_RESTITUTION_DTS = (1 / 240,)
BOUNCES = 3
SCALING_BUDGET_S = 12.0
"""Seconds of timed runs for the scaling table of a full run (``truestep bench`` takes
longer by default, :data:`truestep.execution.bench_defaults.BUDGET_S`, and goes to n = 1e6)."""
SCALING_SIZES = (1e2, 1e3, 1e4, 1e5)
"""Particle counts of a full run's scaling table."""


@dataclasses.dataclass(frozen=True)
class PeerSearch:
    """A search to make first, in the searching process, for its bracket (a :class:`Hint`):
    the ``engine`` this one re-implements (``correctness_peer_of``), and that engine's
    exact limit of the method on the case (s), where one is known."""

    engine: str
    exact: float | None


def _search(
    engine: str,
    case: Case,
    method: str,
    quick: bool,
    exact: float | None = None,
    hint: Hint | PeerSearch | None = None,
):
    """``(SearchResult or the safety valve's message, seconds)`` of one search; ``exact``
    is the method's exact limit on the case (s) where one is known; ``hint``: another
    engine's bracket to try first, or that engine's search to make here for it."""
    adapter = get_adapter(engine)
    start = time.perf_counter()
    if isinstance(hint, PeerSearch):
        hint = _peer_hint(hint, case, method, quick)
    try:
        result = search_case(
            case, lambda c, dt: adapter.simulate(c, method, dt), quick=quick, exact=exact, hint=hint
        )
    except SearchTimeout as err:
        return str(err), time.perf_counter() - start
    return result, time.perf_counter() - start


def _peer_hint(peer: PeerSearch, case: Case, method: str, quick: bool) -> Hint | None:
    """The bracket of ``peer``'s own search of ``method`` on ``case`` (the search its row
    publishes, made again here: the same runs give the same bracket), or ``None`` where
    that search ends without one."""
    try:
        found, _ = _search(peer.engine, case, method, quick, peer.exact)
    except Exception:  # the peer's failure is its own row's; this search goes on without
        return None
    return _hint_of(peer.engine, found)


def _hint_of(engine: str, found: object) -> Hint | None:
    """``engine``'s bracket from its search's result (a :class:`SearchResult` with status
    ``ok``), else ``None``."""
    if not isinstance(found, SearchResult) or found.status != "ok":
        return None
    return Hint(found.dt_limit, found.dt_unstable, engine)


def _peer_of(adapter, case: Case, method: str) -> PeerSearch | None:
    """The search whose bracket ``adapter``'s search of ``method`` starts from: its
    ``correctness_peer_of`` engine's, where that engine is installed, has ``method`` and
    models ``case``; else ``None``."""
    peer = getattr(adapter, "correctness_peer_of", None)
    if not isinstance(peer, str):
        return None
    try:
        other = get_adapter(peer)
        if method not in other.methods or method in other.adaptive_methods:
            return None
        if plugin_answer(peer, "missing()", other.missing, case, method):
            return None
    except Exception:  # not installed, or an adapter that cannot answer: no hint
        return None
    return PeerSearch(peer, stability_limit(case, facts_of(other, method)))


class UntimedPart:
    """One analysis's untimed runs, planned before any of them starts: ``calls`` isolated
    calls that may run in any order and place (:func:`run_untimed`, or on the cores the
    sweep's timed runs leave, :func:`truestep.execution.runner.run_matrix`'s ``alongside``),
    each handed back to :meth:`done`, and :meth:`table` once all are. Its progress bar
    (:class:`Progress`; ``progress`` takes the lines instead) starts with its first call;
    :attr:`seconds` is the wall time from that start to the last call's end.

    ``prepares[k]`` is the (engine, case, method) whose adapter ``prepare`` the ``k``-th
    call needs (:func:`prepare_before_fork`): made just before its fork, once for each, so
    that planning holds up nothing (beside a sweep, the sweep has made most of them).
    ``warm(case)``, where given, is made here once per case before its first call's fork,
    for what every call of that case computes alike and keeps (a search's energy scale,
    read along the case's reference path: 1.7-1.9 s for the cloths and the rope, which
    each search process made again). ``fill(k, call)``, where given, completes the
    ``k``-th call then from what the calls done so far found (a search's
    :class:`~truestep.measures.stability.Hint`)."""

    def __init__(
        self,
        kind: str,
        calls: list[Call],
        on_done: Callable[[int, Outcome, Progress], None],
        make_table: Callable[[], pd.DataFrame],
        progress: Callable[[str], None] | None,
        prepares: Sequence[tuple[str, Case, str]] = (),
        fill: Callable[[int, Call], Call] | None = None,
        warm: Callable[[Case], object] | None = None,
    ) -> None:
        self.kind, self.calls = kind, calls
        self._fill, self._warm = fill, warm
        self._warmed: set[int] = set()
        self._on_done, self._make_table, self._progress = on_done, make_table, progress
        self._prepares = prepares
        self._prepared: set[tuple[str, str, str]] = set()
        self._bar: Progress | None = None
        self._first: float | None = None
        self._last: float | None = None
        self.by_engine: dict[str, float] = {}
        """Seconds of this part's processes by engine (each from its fork to its end,
        :attr:`~truestep.runtime.isolation.Outcome.seconds`; they may overlap), where
        ``prepares`` names each call's engine."""

    def __len__(self) -> int:
        return len(self.calls)

    def call(self, k: int) -> Call:
        """The ``k``-th call, just before it starts (its adapter prepared)."""
        if self._bar is None:
            self._bar = Progress(len(self.calls), self.kind, say=self._progress)
            self._first = self._bar.start
        if self._prepares:
            prepare_before_fork([self._prepares[k]], self._prepared)
            case = self._prepares[k][1]
            if self._warm is not None and id(case) not in self._warmed:
                self._warmed.add(id(case))
                with contextlib.suppress(Exception):  # the call that needs it then fails in its own row
                    self._warm(case)
        return self.calls[k] if self._fill is None else self._fill(k, self.calls[k])

    def done(self, k: int, out: Outcome) -> None:
        """The ``k``-th call's outcome."""
        if self._bar is None:  # not started: the run's budget was spent
            self.call(k)
        assert self._bar is not None
        if self._prepares:
            engine = self._prepares[k][0]
            self.by_engine[engine] = self.by_engine.get(engine, 0.0) + out.seconds
        self._on_done(k, out, self._bar)
        self._last = time.perf_counter()
        faults.point("analyses")

    def run(self, workers: int) -> UntimedPart:
        """Run every call here (``workers`` at once, or on the cluster of
        :func:`~truestep.runtime.isolation.set_untimed_runner`)."""
        run_untimed([self.call(k) for k in range(len(self))], workers, self.done)
        return self

    def table(self) -> pd.DataFrame:
        """The analysis's table, once every call is done."""
        if self._bar is not None:
            self._bar.close()
        return self._make_table()

    @property
    def seconds(self) -> float:
        if self._first is None or self._last is None:
            return 0.0
        return self._last - self._first


SHARED_COLUMNS = ("dt_limit", "dt_unstable", "runs", "status")
"""What a method whose steps are another's, bit for bit, takes from that one's search."""


def stability_table(
    cases: list[Case],
    engines: list[str],
    *,
    quick: bool,
    workers: int = 1,
    progress: Callable[[str], None] | None = None,
) -> pd.DataFrame:
    """Bisect the largest stable step for every case that declares a search.

    ``--quick`` searches only cases whose search says ``quick = true``, to 1%. Searches
    are not timed, so up to ``workers`` run at once, each in its own process. Each
    finished search is a line with done / total and the time left (:class:`Progress`;
    ``progress`` takes the lines instead).
    """
    return stability_part(cases, engines, quick=quick, progress=progress).run(workers).table()


def stability_part(
    cases: list[Case], engines: list[str], *, quick: bool, progress: Callable[[str], None] | None = None
) -> UntimedPart:
    """The searches of :func:`stability_table`, planned (longest first, so that no long
    search starts last while the other cores idle)."""
    rows: list[dict] = []
    calls, slots = [], []
    searched: dict[tuple[str, str, str], dict] = {}
    sharing: list[tuple[dict, tuple[str, str, str], str]] = []
    for case in cases:
        if case.stability is None or (quick and not case.stability.quick):
            continue
        for engine in engines:
            adapter = get_adapter(engine)
            for method in adapter.methods:
                row: dict[str, object] = {"case": case.name, "engine": engine, "method": method}
                try:
                    missing = plugin_answer(engine, "missing()", adapter.missing, case, method)
                except PluginFailed as err:
                    rows.append({**row, "dt_limit_exact": np.nan, "status": "crashed", "note": str(err)})
                    continue
                adaptive = method in adapter.adaptive_methods
                exact = None if adaptive else stability_limit(case, facts_of(adapter, method))
                row["dt_limit_exact"] = np.nan if exact is None else exact
                if missing:
                    rows.append({**row, "status": "unsupported", "note": ",".join(sorted(missing))})
                elif adaptive:
                    rows.append({**row, "status": "skipped", "note": "adaptive: chooses its own step"})
                elif (same := duplicate_of(adapter, case, method)) is not None:
                    rows.append({**row, "status": "skipped", "note": same})
                elif (twin := _twin_searched(engine, adapter, case, method, searched)) is not None:
                    row["device"] = engine_device(engine)
                    rows.append(row)
                    sharing.append((row, (case.name, engine, twin[0]), twin[1]))
                else:
                    row["device"] = engine_device(engine)
                    rows.append(row)
                    searched[(case.name, engine, method)] = row
                    slots.append(row)
                    peer = _peer_of(adapter, case, method)
                    calls.append(
                        (
                            _search,
                            (engine, case, method, quick, exact, peer),
                            case.timeout_s * case.stability.max_runs,
                        )
                    )

    def done(k: int, out: Outcome, bar: Progress) -> None:
        row = slots[order[k]]
        if out.status != "ok":
            row.update(status=out.status, note=out.message)
            bar.done(f"{row['case']} {row['engine']}/{row['method']}: {out.status}")
            return
        r, seconds = out.value
        if isinstance(r, str):  # the safety valve fired: no limit from this machine's speed
            row.update(status="timeout", note=r)
            bar.done(f"{row['case']} {row['engine']}/{row['method']}: timeout ({r})")
            return
        row.update(dt_limit=r.dt_limit, dt_unstable=r.dt_unstable, runs=r.runs, status=r.status, note=r.note)
        bar.done(
            f"{row['case']:20s} {row['engine']:9s} {row['method']:17s} dt_limit "
            f"{r.dt_limit:.5g} ({_exact_words(row['dt_limit_exact'])}) in {r.runs} runs, "
            f"{seconds:.1f} s"
        )

    def table() -> pd.DataFrame:
        for row, key, why in sharing:
            searched_row = searched[key]
            words = f"the same steps as {key[2]}'s, bit for bit ({why}): its search"
            row.update(
                {c: searched_row.get(c, np.nan) for c in ("dt_limit", "dt_unstable", "runs", "status")}
            )
            row["note"] = "; ".join(n for n in (words, searched_row.get("note")) if isinstance(n, str) and n)
        return STABILITY.frame(rows)

    order = sorted(range(len(calls)), key=_sources_first(calls))
    planned = [calls[k] for k in order]
    prepares = [(engine, case, method) for _, (engine, case, method, *_), _t in planned]
    return UntimedPart(
        "stability", planned, done, table, progress, prepares, fill=_peer_bracket(searched), warm=energy_scale
    )


def _sources_first(calls: list[Call]) -> Callable[[int], tuple[bool, float]]:
    """The order of the searches: those another search starts from (:class:`PeerSearch`)
    first, so that their brackets are in when those start; then the longest first."""
    sources = {(c[1][1].name, c[1][5].engine, c[1][2]) for c in calls if isinstance(c[1][5], PeerSearch)}

    def key(k: int) -> tuple[bool, float]:
        engine, case, method = calls[k][1][:3]
        return (case.name, engine, method) not in sources, -_search_cost(engine, case, method)

    return key


def _peer_bracket(searched: dict[tuple[str, str, str], dict]) -> Callable[[int, Call], Call]:
    """A search's call as it starts: where its peer's search (a :class:`PeerSearch`) is done
    here, that search's bracket (a :class:`Hint`, or ``None`` if it found none) instead of
    the search to make again: the same bracket either way, only the work differs."""

    def fill(k: int, call: Call) -> Call:
        fn, args, timeout = call
        peer = args[5]
        if not isinstance(peer, PeerSearch):
            return call
        row = searched.get((args[1].name, peer.engine, args[2]))
        if row is None or "status" not in row:
            return call
        known = None
        if row["status"] == "ok":
            known = Hint(float(row["dt_limit"]), float(row["dt_unstable"]), peer.engine)
        return fn, (*args[:5], known), timeout

    return fill


def _twin_searched(
    engine: str, adapter, case: Case, method: str, searched: dict[tuple[str, str, str], dict]
) -> tuple[str, str] | None:
    """``(other method, why)`` where the adapter says ``method`` steps ``case`` bit for bit
    as another method does (its optional ``same_steps``, Adapter protocol item 12) and that
    method's search is already in the table; else ``None``. A ``same_steps`` that raises,
    or names a method not searched, leaves ``method`` to its own search."""
    same = getattr(adapter, "same_steps", None)
    if same is None:
        return None
    try:
        twin = plugin_answer(engine, "same_steps()", same, case, method)
    except PluginFailed:
        return None
    if twin is None or (case.name, engine, twin[0]) not in searched:
        return None
    return str(twin[0]), str(twin[1])


def prepare_before_fork(
    runs: Iterable[tuple[str, Case, str]], seen: set[tuple[str, str, str]] | None = None
) -> None:
    """Each adapter's optional ``prepare(case, method)`` (compile, load kernels), called
    here once per engine, scene and method before the processes that run them are forked,
    so that each process finds them ready instead of paying for them again. A prepare that
    fails is left for the run itself to report. ``seen`` holds the (engine, case name,
    method) already prepared, and receives these."""
    seen = set() if seen is None else seen
    for engine, case, method in runs:
        if (engine, case.name, method) not in seen:
            seen.add((engine, case.name, method))
            prepare_here(engine, case, method)


def _exact_words(limit: object) -> str:
    """The exact limit as a progress line says it: ``exact 0.0199``, or that there is none."""
    value = float(limit) if isinstance(limit, int | float) else float("nan")
    return f"exact {value:.5g}" if np.isfinite(value) or value == np.inf else "no exact limit known"


IMPLICIT_COST = 8.0
"""Evaluations a step of a method whose count varies (implicit Euler's Newton iterations)
is taken to cost, for scheduling only."""


def _search_cost(engine: str, case: Case, method: str) -> float:
    """A rough relative cost of a search, for scheduling only: steps of its smallest-step
    run times the particles, times the evaluations a step of ``method`` makes (its
    declared facts; :data:`IMPLICIT_COST` where the count varies)."""
    from truestep.adapters.base import facts_of

    spec = case.stability
    if spec is None:
        raise ValueError(f"{case.name}: the case declares no stability search")
    steps = max(spec.min_steps, spec.horizon / spec.dt_lo)
    facts = facts_of(get_adapter(engine), method)
    per_step = 1.0 if facts is None else float(facts.evaluations_per_step or IMPLICIT_COST)
    return steps * case.bodies * per_step


DROP_CASE = CASE_DIR / "analyses" / "restitution-drop.toml"
"""The restitution sweep's scene: a ball of radius 0.05 m dropped from 1 m onto y = 0."""


@functools.cache
def _drop() -> Case:
    return load_case(DROP_CASE)


def drop_geometry() -> tuple[float, float, float]:
    """The drop's ball radius (m), the height of its lowest point above the plane (m) and
    gravity along the plane's normal (m/s^2), as :data:`DROP_CASE` sets them."""
    model = _drop().particles
    plane = model.planes[0]
    radius = float(model.radius[0])
    height = float((model.x0[0] - plane.point) @ plane.normal) - radius
    return radius, height, float(-model.gravity @ plane.normal)


def bounce_case(e: float, dt: float) -> Case:
    """The drop of :data:`DROP_CASE` with restitution ``e`` at step ``dt`` (s), run in whole
    steps past the third bounce."""
    drop = _drop()
    model = drop.particles
    _, height, g = drop_geometry()
    t_first = np.sqrt(2 * height / g)
    steps = int(np.ceil((t_first * (1 + 2 * (e + e**2 + e**3)) + 0.25) / dt))
    duration = steps * dt  # whole steps: the run steps exactly the dt its rows are labelled with
    return dataclasses.replace(
        drop,
        name=f"bounce-e{e:g}",
        scene=dataclasses.replace(model, planes=[dataclasses.replace(model.planes[0], restitution=e)]),
        duration=duration,
        dts=[dt],
        quick_dts=[dt],
        max_records=int(np.ceil(duration / dt)) + 1,
    )


PHASE_SPACING = 0.25
"""m between the phase drops' balls along the plane (radius 0.05 m: they never touch)."""


def phase_case(e: float, dt: float, phases: int = PHASES) -> Case:
    """The drop of :data:`DROP_CASE` as ``phases`` balls side by side, ball ``k`` raised so
    that its first contact begins ``k / phases`` of a step after the single drop's
    (``h_k = g t_k^2 / 2``, ``t_k = t_1 + k dt / phases``), with restitution ``e`` at
    step ``dt`` (s), run in whole steps to past the apex of the last ball's first bounce."""
    drop = _drop()
    model = drop.particles
    plane = model.planes[0]
    radius, height, g = drop_geometry()
    along = np.array([1.0, 0.0, 0.0])
    assert abs(float(along @ plane.normal)) < 1e-12, "the drop's plane is not y = const"
    t_k = np.sqrt(2 * height / g) + dt * np.arange(phases) / phases
    rise = 0.5 * g * t_k**2 - height
    x0 = model.x0[0] + rise[:, None] * plane.normal + PHASE_SPACING * np.arange(phases)[:, None] * along
    steps = int(np.ceil((t_k[-1] * (1 + e) + 0.1) / dt)) + 20  # to the apex, with room
    scene = dataclasses.replace(
        model,
        mass=np.full(phases, model.mass[0]),
        x0=x0,
        v0=np.zeros((phases, 3)),
        radius=np.full(phases, radius),
        fixed=np.zeros(phases, bool),
        planes=[dataclasses.replace(plane, restitution=e)],
    )
    return dataclasses.replace(
        drop,
        name=f"bounce-phases-e{e:g}",
        scene=scene,
        duration=steps * dt,
        dts=[dt],
        quick_dts=[dt],
        max_records=steps + 1,
    )


def _phase_values(engine: str, method: str, e: float, dt: float) -> tuple[dict, str]:
    """The impact-phase drops' columns of a bounce-1 row (``phases``, ``e_phase_median``,
    ``_min``, ``_max``) and a note: why they are missing, or that the asked ``e`` is not
    delivered within :data:`PHASE_BAND` over every phase."""
    case = phase_case(e, dt)
    traj = get_adapter(engine).simulate(case, method, dt)
    if traj.status != "ok" or traj.v is None:
        return {"phases": 0}, f"the impact-phase drops: {traj.status} {traj.message}".strip()
    plane = case.particles.planes[0]
    radius, _, g = drop_geometry()
    measured = []
    for k in range(case.particles.n):
        h, vn = heights(traj.x[:, k], traj.v[:, k], plane.point, plane.normal, radius)
        found = bounces(traj.t, h, vn, g)
        if found and np.isfinite(found[0].e_velocity):
            measured.append(found[0].e_velocity)
    if not measured:
        return {"phases": 0}, "the impact-phase drops: no first bounce measured"
    values = np.array(measured)
    lo, hi = float(values.min()), float(values.max())
    out = {
        "phases": len(values),
        "e_phase_median": float(np.median(values)),
        "e_phase_min": lo,
        "e_phase_max": hi,
    }
    if lo < e - PHASE_BAND or hi > e + PHASE_BAND:
        return out, (
            f"asked e = {e:g} is not delivered across impact phases: {lo:.3g} to {hi:.3g} "
            f"(median {out['e_phase_median']:.3g}) over {len(values)} drops whose contact begins "
            f"at evenly spaced points of a step, beyond the band of {PHASE_BAND:g}"
        )
    return out, ""


def _bounce_rows(engine: str, method: str, e: float, dt: float) -> list[dict]:
    """The rows of one drop (:func:`bounce_case`), bounce by bounce; the first with the
    impact-phase drops' values (:func:`_phase_values`)."""
    case = bounce_case(e, dt)
    traj = get_adapter(engine).simulate(case, method, dt)
    base = {"engine": engine, "method": method, "dt": dt, "e_set": e}
    if traj.status != "ok":
        return [{**base, "bounce": 1, "status": traj.status, "note": traj.message}]
    assert traj.v is not None, "a particle run records its velocities"
    plane = case.particles.planes[0]
    radius, _, g = drop_geometry()
    h, vn = heights(traj.x[:, 0], traj.v[:, 0], plane.point, plane.normal, radius)
    found = bounces(traj.t, h, vn, g)
    rows = []
    for k in range(1, BOUNCES + 1):
        if k <= len(found):
            b = found[k - 1]
            rows.append(
                {
                    **base,
                    "bounce": k,
                    "e_measured": b.e_velocity,
                    "e_apex": b.e_apex,
                    "v_in": b.v_in,
                    "v_out": b.v_out,
                    "apex": b.apex,
                    "penetration": b.penetration,
                    "status": "ok",
                    "note": "",
                }
            )
        else:
            why = "ball at rest after the previous contact" if found else "no contact found"
            rows.append({**base, "bounce": k, "status": "ok", "note": why})
    values, note = _phase_values(engine, method, e, dt)
    rows[0].update(values)
    rows[0]["note"] = "; ".join(n for n in (str(rows[0]["note"]), note) if n)
    return rows


def restitution_table(
    engines: list[str], *, quick: bool, workers: int = 1, progress: Callable[[str], None] | None = None
) -> pd.DataFrame:
    """Drop a ball at every requested restitution and step, in every engine and method.

    The drops are not timed, so up to ``workers`` run at once, each in its own process;
    each finished drop is a line with done / total and the time left (as
    :func:`stability_table`).
    """
    return restitution_part(engines, quick=quick, progress=progress).run(workers).table()


def restitution_part(
    engines: list[str], *, quick: bool, progress: Callable[[str], None] | None = None
) -> UntimedPart:
    """The drops of :func:`restitution_table`, planned."""
    e_set = QUICK_RESTITUTION_SET if quick else RESTITUTION_SET
    dts = QUICK_RESTITUTION_DTS if quick else RESTITUTION_DTS
    groups: list[list[dict]] = []  # the rows of one drop (or one unsupported method)
    calls, slots = [], []
    for engine in engines:
        adapter = get_adapter(engine)
        probe = bounce_case(0.5, dts[0])
        for method in getattr(adapter, "bounce_methods", None) or adapter.methods:
            try:
                missing = plugin_answer(engine, "missing()", adapter.missing, probe, method)
            except PluginFailed as err:
                groups.append([{"engine": engine, "method": method, "status": "crashed", "note": str(err)}])
                continue
            if missing or method in adapter.adaptive_methods:
                why = ",".join(sorted(missing)) or (
                    "adaptive: the sweep compares fixed steps (its bounces are measured in the cases)"
                )
                groups.append([{"engine": engine, "method": method, "status": "unsupported", "note": why}])
                continue
            for dt in dts:
                for e in e_set:
                    groups.append([])
                    slots.append((len(groups) - 1, engine, method, e, dt))
                    calls.append((_bounce_rows, (engine, method, e, dt), 60.0))

    def done(k: int, out: Outcome, bar: Progress) -> None:
        g, engine, method, e, dt = slots[k]
        bar.done(f"{engine:9s} {method:17s} dt {dt:.4g} e {e:g}: {out.status}")
        device = engine_device(engine)
        if out.status == "ok":
            groups[g].extend({**r, "device": device} for r in out.value)
        else:
            groups[g].append(
                {
                    "engine": engine,
                    "method": method,
                    "dt": dt,
                    "e_set": e,
                    "bounce": 1,
                    "status": out.status,
                    "note": out.message,
                    "device": device,
                }
            )

    first = {(engine, method): bounce_case(e, dt) for _, engine, method, e, dt in reversed(slots)}
    prepares = [(engine, first[engine, method], method) for _, engine, method, _e, _dt in slots]
    return UntimedPart(
        "restitution",
        calls,
        done,
        lambda: RESTITUTION.frame([r for g in groups for r in g]),
        progress,
        prepares,
    )


def untimed_parts(
    cases: list[Case], engines: list[str], *, quick: bool, progress: Callable[[str], None] | None = None
) -> list[UntimedPart]:
    """The untimed analyses of :func:`run_analyses` for these cases and engines, planned:
    the stability searches and, when a case tagged ``restitution`` is among ``cases``, the
    bounce drops."""
    parts = [stability_part(cases, engines, quick=quick, progress=progress)]
    if any("restitution" in c.tags for c in cases):
        parts.append(restitution_part(engines, quick=quick, progress=progress))
    return parts


@own_run()
def run_analyses(
    cases: list[Case],
    engines: list[str],
    results: pd.DataFrame,
    *,
    quick: bool,
    progress: Callable[[str], None] | None = None,
    seconds: dict[str, float] | None = None,
    ran: list[UntimedPart] | None = None,
    lanes: Lanes | None = None,
) -> dict[str, pd.DataFrame]:
    """Every table besides ``results``: ``stability`` (for the cases with a search),
    ``restitution`` (when a case tagged ``restitution`` is among ``cases``; else empty)
    and ``scaling`` (particle-steps per second against n, :func:`truestep.execution.bench.scaling_table`
    in :data:`SCALING_BUDGET_S`, when the rain case is among ``cases`` and the run is not
    ``quick``; else empty).

    The first two are not timed: their runs share the machine's cores
    (:func:`untimed_workers`), here, or, where ``ran`` holds those parts
    (:func:`untimed_parts`), as the backlog of ``lanes`` beside the sweep's timed runs. The
    scaling table is timed, so it runs one run at a time on a core of its own: after the
    others, or with their backlog's children that still run on the other cores (none
    started meanwhile), then the backlog's rest. Each phase shows done / total and the
    time left (``progress`` takes the lines instead); ``seconds`` receives each one's wall
    time (``analyses stability``, ``analyses restitution``, ``analyses scaling``, s; for a
    part run as a backlog, from its first call's start to its last call's end), and the
    seconds of each engine's processes in the first two (``analyses stability mujoco``...:
    :attr:`UntimedPart.by_engine`).
    """
    from truestep.execution.bench import RAIN_CASE, scaling_table

    preload()
    if ran is None:
        ran = [
            part.run(untimed_workers())
            for part in untimed_parts(cases, engines, quick=quick, progress=progress)
        ]
    rain = next((c for c in cases if c.name == RAIN_CASE), None)
    if lanes is not None:
        lanes.free_core()
    start = time.perf_counter()
    tables = {
        "scaling": (
            scaling_table(
                engines, sizes=SCALING_SIZES, budget_s=SCALING_BUDGET_S, case=rain, progress=progress
            )
            if rain is not None and not quick
            else SCALING.frame([])
        )
    }
    if seconds is not None:
        seconds["analyses scaling"] = round(time.perf_counter() - start, 3)
    if lanes is not None:
        lanes.finish()
    tables.update({part.kind: part.table() for part in ran})
    tables.setdefault("restitution", RESTITUTION.frame([]))
    if seconds is not None:
        for part in ran:
            seconds[f"analyses {part.kind}"] = round(part.seconds, 3)
            seconds.update({f"analyses {part.kind} {e}": round(s, 3) for e, s in part.by_engine.items()})
        seconds.setdefault("analyses restitution", 0.0)
    return {kind: tables[kind] for kind in ("stability", "restitution", "scaling")}
