"""Round three, continued (issue 37): the failures of the issue that had a unit test and
no attack yet, each repeated with the input of the unit test named in its docstring,
against the target's ``truestep`` command as a user starts it (:attr:`Target.cli`):
results that run code when read, plugins that end their process, take its signals, its
directory or its standard output, processes left behind by a killed run, a scheduler that
never answers, ``--resume`` after an adapter changed, tables ``run`` writes and ``gate``
must read, and inputs that gave a traceback."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import threading
import time
from pathlib import Path

from hostile_attacks.adapters import alive
from hostile_attacks.common import (
    CALL_TIMEOUT,
    HERE,
    RUN_TIMEOUT,
    Campaign,
    Result,
    gate,
    mkfifo,
    refused,
    shipped_tables,
    tables_without_timing,
)
from hostile_attacks.round_three import _lines, _plugin_env, _rows

QUICK_BASELINE = HERE.parents[1] / "tests" / "baselines" / "quick"
"""The project's quick baseline (its tables and ``run.json``): the run the baseline
attacks garble."""


def _plugin(where: Path, module: str, text: str) -> None:
    (where / f"{module}.py").write_text(text)


def _registered(where: Path, package: str, group: str, entries: dict[str, str]) -> None:
    """A dist-info in ``where`` for ``package``, registering ``entries`` (name -> value)
    in the entry-point ``group``."""
    info = where / f"{package}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {package}\nVersion: 1.0\n")
    lines = "".join(f"{name} = {value}\n" for name, value in entries.items())
    (info / "entry_points.txt").write_text(f"[{group}]\n{lines}")


def _statuses(folder: Path, engine: str) -> set[str]:
    return {r["status"] for r in _rows(folder) if r["engine"] == engine}


def _wait_for_pid(path: Path, proc, timeout: float = RUN_TIMEOUT) -> int | None:
    """The pid a plugin writes to ``path``, once it is there (None: the command ended
    first, or ``timeout`` passed)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        if path.exists() and path.read_text().strip():
            time.sleep(0.2)
            return int(path.read_text())
        time.sleep(0.05)
    return None


def _still_alive(pids: list[int], within: float = 10.0) -> list[int]:
    """Those of ``pids`` still running after ``within`` s (killed then: the campaign
    cleans up after the target)."""
    deadline = time.monotonic() + within
    left = alive(pids)
    while left and time.monotonic() < deadline:
        time.sleep(0.1)
        left = alive(left)
    for pid in left:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return left


# -- item 4: a result crosses as data ------------------------------------------------------

ENDS_WHEN_READ = """
import os
from truestep.adapters.reference import ReferenceAdapter


class ExitsWhenRead:
    def __reduce__(self):
        return (os._exit, (0,))


class Hostile(ReferenceAdapter):
    name = "ends-when-read"
    methods = ("rk4",)
    adaptive_methods = ()

    def simulate(self, case, method, dt, *, monitor=False):
        traj = super().simulate(case, method, dt, monitor=monitor)
        if dt == min(case.quick_dts):
            traj.extra["gift"] = ExitsWhenRead()
        return traj
"""


def attack_result_that_ends_the_process_when_read(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter whose result at the finest quick step carries an object that calls
    ``os._exit(0)`` when unpickled: the run goes on and publishes (exit 0), that row is
    ``crashed`` naming ``posix._exit``, its others and the reference's ``ok``
    (tests/runtime/test_result_as_data.py; it used to make ``truestep run`` exit 0 with no
    report and no line)."""
    _plugin(where, "ends_when_read", ENDS_WHEN_READ)
    result = c.quick_run(
        where, "rep", cases="free-fall", engines="ends_when_read:Hostile,reference", env=_plugin_env(c, where)
    )
    rows = _rows(where / "rep")
    mine = [r for r in rows if r["engine"] == "ends-when-read"]
    crashed = [r for r in mine if r["status"] == "crashed"]
    named = len(crashed) == 1 and "posix._exit" in crashed[0]["message"]
    others_ok = len(mine) > 1 and all(r["status"] == "ok" for r in mine if r not in crashed)
    ref = _statuses(where / "rep", "reference")
    ok = result.code == 0 and named and others_ok and ref == {"ok"} and "Traceback" not in result.err
    said = crashed[0]["message"][:100] if crashed else f"rows {sorted({r['status'] for r in mine})}"
    return ok, f"{said}; reference {sorted(ref)}; {result.why()}"


# -- item 5: plugin code cannot end the command ---------------------------------------------


def attack_case_library_callable_raises_system_exit(c: Campaign, where: Path) -> tuple[bool, str]:
    """A package whose ``truestep.cases`` entry point is a callable that raises
    ``SystemExit(0)``: ``list`` and ``run`` are exit 2 with one line naming the entry
    point, no report (tests/adapters/test_plugin_calls.py, the case library that never answers;
    it used to end ``truestep run`` with exit 0 and no report)."""
    _plugin(where, "exits_cases", "def where():\n    raise SystemExit(0)\n")
    _registered(where, "exits-cases", "truestep.cases", {"exits": "exits_cases:where"})
    env = _plugin_env(c, where)
    notes = []
    for args in (
        ["list", "--cases", "free-fall"],
        ["run", "--quick", "--cases", "free-fall", "--out", "rep"],
    ):
        result = c.truestep([*args, "--engines", "reference"], where, env=env, timeout=RUN_TIMEOUT)
        lines = _lines(result)
        named = len(lines) == 1 and "exits_cases:where" in lines[0]
        if result.code != 2 or not named or "Traceback" in result.err or (where / "rep").exists():
            return False, f"{args[0]}: {result.why()}"
        notes.append(f"{args[0]}: {lines[0][:100]}")
    return True, "; ".join(notes)


def attack_adapter_import_calls_sys_exit(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter module whose import calls ``sys.exit(0)``: a run naming it is exit 2
    with one line saying so, no report (tests/runtime/test_supervisor.py; it used to end
    ``truestep run`` with exit 0 and no report)."""
    _plugin(where, "exits_at_import", "import sys\nsys.exit(0)\n")
    result = c.quick_run(
        where, "rep", cases="free-fall", engines="exits_at_import:X,reference", env=_plugin_env(c, where)
    )
    lines = _lines(result)
    said = len(lines) == 1 and "importing exits_at_import called sys.exit(0)" in lines[0]
    ok = result.code == 2 and said and "Traceback" not in result.err and not (where / "rep").exists()
    return ok, result.why()


ENDS_ON_A_LATER_CALL = """
import os
from pathlib import Path
from truestep.adapters.reference import ReferenceAdapter

def _again(mark):
    if Path(mark).exists():
        os._exit(0)
    Path(mark).write_text("")

class X(ReferenceAdapter):
    name = "ends-on-a-later-call"
    methods = ("rk4",)
    adaptive_methods = ()

    def __init__(self):
        _again(f"made-in-{os.getppid()}")  # once per parent: a second making ends its process
        super().__init__()

    @property
    def speed_claim(self):
        _again(f"read-in-{os.getpid()}")  # a second read in one process ends it
        return True
"""


def attack_adapter_ends_its_process_on_a_later_making_or_read(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter whose ``__init__`` ends its process when made a second time below the
    same parent, and whose ``speed_claim`` property ends its process when read a second
    time in it: the run is exit 0 with a report, and the plugin's rows are there
    (tests/runtime/test_supervisor.py, the adapter made and read only in forked
    processes; it used to end ``truestep run`` with exit 3, as the adapter was made again
    and read again in truestep's own process)."""
    _plugin(where, "ends_on_a_later_call", ENDS_ON_A_LATER_CALL)
    result = c.quick_run(
        where,
        "rep",
        cases="free-fall",
        engines="ends_on_a_later_call:X,reference",
        env=_plugin_env(c, where),
    )
    if result.code != 0 or "Traceback" in result.err or not (where / "rep" / "results.csv").exists():
        return False, result.why()
    statuses = _statuses(where / "rep", "ends-on-a-later-call")
    return bool(statuses), f"exit 0, its rows: {', '.join(sorted(statuses))}"


# -- item 6: nothing outlives a run ---------------------------------------------------------

HELPER_THEN_SLEEP = """
import subprocess, sys, time
from pathlib import Path
from truestep.adapters.reference import ReferenceAdapter


class X(ReferenceAdapter):
    name = "helper-then-sleep"
    methods = ("rk4",)
    adaptive_methods = ()

    def simulate(self, case, method, dt, **kw):
        helper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
        Path("helper.pid").write_text(str(helper.pid))
        time.sleep(120)
"""


def _signal_while_the_helper_runs(c: Campaign, where: Path, sig: signal.Signals) -> tuple[Result, list[int]]:
    """A run of an adapter that starts a helper and sleeps, sent ``sig`` once the helper
    runs: its result and the helpers still alive 10 s later."""
    _plugin(where, "helper_then_sleep", HELPER_THEN_SLEEP)
    started = time.perf_counter()
    proc = c.start(
        ["run", "--quick", "--engines", "helper_then_sleep:X", "--cases", "free-fall", "--out", "rep"],
        where,
        env=_plugin_env(c, where),
    )
    helper = _wait_for_pid(where / "helper.pid", proc)
    if helper is None:
        result = c.finish(proc, 1, started)
        raise RuntimeError(f"the adapter's helper never started: {result.why()}")
    proc.send_signal(sig)
    result = c.finish(proc, CALL_TIMEOUT, started)
    return result, _still_alive([helper])


def attack_sigkill_of_run_leaves_no_helper(c: Campaign, where: Path) -> tuple[bool, str]:
    """SIGKILL of ``truestep run`` while an adapter's helper process runs: no helper is
    alive 10 s later (tests/runtime/test_supervisor.py; 4 of 4 used to stay alive, re-parented
    to init)."""
    result, left = _signal_while_the_helper_runs(c, where, signal.SIGKILL)
    return not left, f"{len(left)} helper(s) outlived the run; {result.why()}"


def attack_sighup_of_run_leaves_no_helper(c: Campaign, where: Path) -> tuple[bool, str]:
    """SIGHUP of ``truestep run`` (its terminal closed) while an adapter's helper runs:
    exit 129, its last line "interrupted by SIGHUP", no helper alive 10 s later
    (tests/runtime/test_supervisor.py; there used to be no line at all, and the helpers lived)."""
    result, left = _signal_while_the_helper_runs(c, where, signal.SIGHUP)
    lines = _lines(result)
    said = bool(lines) and "interrupted by SIGHUP" in lines[-1]
    ok = not left and result.code == 128 + signal.SIGHUP and said and "Traceback" not in result.err
    return ok, f"{len(left)} helper(s) outlived the run; {result.why()}"


def _session(sid: int) -> list[int]:
    """The live processes of session ``sid`` (zombies left out)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[3]) == sid and fields[0] not in ("Z", "X"):
            out.append(int(stat.parent.name))
    return out


def attack_kill_of_compile_leaves_no_worker_compiling(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep compile`` into empty caches (``NUMBA_CACHE_DIR``, ``WARP_CACHE_PATH``),
    sent SIGKILL (then, afresh, SIGTERM) once it has forked its helpers: none of its
    processes is alive 10 s later (tests/reference_impl/test_compiled.py,
    tests/execution/test_compile_command.py; its forked worker used to keep compiling and
    writing the cache)."""
    notes = []
    for sig in (signal.SIGKILL, signal.SIGTERM):
        caches = where / sig.name
        env = c.env(NUMBA_CACHE_DIR=str(caches / "numba"), WARP_CACHE_PATH=str(caches / "warp"))
        started = time.perf_counter()
        proc = c.start(["compile"], where, env=env)
        deadline = time.monotonic() + CALL_TIMEOUT
        members = _session(proc.pid)
        while len(members) < 3 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
            members = _session(proc.pid)
        if len(members) < 3:
            result = c.finish(proc, 1, started)
            return False, f"{sig.name}: compile forked no helper (processes {members}); {result.why()}"
        time.sleep(1.0)
        members = sorted(set(members) | set(_session(proc.pid)))
        proc.send_signal(sig)
        result = c.finish(proc, CALL_TIMEOUT, started)
        left = _still_alive(sorted(set(members) | set(_session(proc.pid))))
        if left:
            return (
                False,
                f"{sig.name}: {len(left)} of its {len(members)} processes alive 10 s later; {result.why()}",
            )
        notes.append(f"{sig.name}: {len(members)} processes, none left, exit {result.code}")
    return True, "; ".join(notes)


def attack_sigterm_while_the_loops_compile_ahead(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep run --quick`` into an empty numba cache, sent SIGTERM once it has forked
    its compile helpers: it ends within 10 s with exit 143 and one line (``interrupted by
    SIGTERM``), no traceback, and none of its processes alive 10 s later
    (tests/execution/test_compile_command.py; it took 12 s to answer, and each helper printed the
    traceback of the handler it inherited)."""
    env = c.env(NUMBA_CACHE_DIR=str(where / "numba"))
    started = time.perf_counter()
    command = ["run", "--quick", "--cases", "harmonic-oscillator,hanging-cloth", "--engines", "reference"]
    proc = c.start([*command, "--out", "rep"], where, env=env)
    deadline = time.monotonic() + CALL_TIMEOUT
    members = _session(proc.pid)
    while len(members) < 3 and time.monotonic() < deadline and proc.poll() is None:  # the command, a helper
        time.sleep(0.2)
        members = _session(proc.pid)
    if len(members) < 3:
        result = c.finish(proc, 1, started)
        return False, f"the run forked no compile helper (processes {members}); {result.why()}"
    time.sleep(1.0)
    members = sorted(set(members) | set(_session(proc.pid)))
    signalled = time.perf_counter()
    proc.send_signal(signal.SIGTERM)
    result = c.finish(proc, CALL_TIMEOUT, started)
    answered = time.perf_counter() - signalled
    left = _still_alive(sorted(set(members) | set(_session(proc.pid))))
    lines = [x for x in result.err.splitlines() if x.startswith("truestep:")]
    ok = (
        result.code == 128 + signal.SIGTERM
        and answered < 10.0
        and not left
        and "Traceback" not in result.err
        and len(lines) == 1
        and "interrupted by SIGTERM" in lines[0]
        and "from the 0 finished sweeps" in lines[0]  # while it compiled, before any sweep
    )
    return ok, f"answered in {answered:.1f} s, {len(left)} of {len(members)} processes left; {result.why()}"


DAEMON = """
import os, time
from pathlib import Path
from truestep.adapters.reference import ReferenceAdapter


def daemon(mark):
    if Path(mark).exists():
        return
    if os.fork() == 0:
        os.setsid()
        if os.fork() == 0:
            Path(mark).write_text(str(os.getpid()))
            time.sleep(120)
        os._exit(0)
    while not Path(mark).exists():
        time.sleep(0.01)


class InPrepare(ReferenceAdapter):
    name = "daemon-in-prepare"
    methods = ("rk4",)
    adaptive_methods = ()

    def prepare(self, case, method):
        daemon("daemon.pid")


class WhenMade(ReferenceAdapter):
    name = "daemon-when-made"
    methods = ("rk4",)
    adaptive_methods = ()

    def __init__(self):
        daemon("daemon.pid")
"""


def attack_daemon_started_by_an_adapter_outlives_the_run(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter that double-forks a daemon (``setsid``) from its ``prepare()``, then
    one that does so from its ``__init__``: each run is exit 0 and its daemon is not
    alive 10 s after it (tests/runtime/test_supervisor.py; a daemon from ``prepare()``, called
    in truestep's own process, used to outlive the run)."""
    _plugin(where, "daemons", DAEMON)
    notes = []
    for cls in ("InPrepare", "WhenMade"):
        (where / "daemon.pid").unlink(missing_ok=True)
        shutil.rmtree(where / "rep", ignore_errors=True)
        result = c.quick_run(
            where, "rep", cases="free-fall", engines=f"daemons:{cls}", env=_plugin_env(c, where)
        )
        mark = where / "daemon.pid"
        if not mark.exists():
            return False, f"{cls}: no daemon started; {result.why()}"
        left = _still_alive([int(mark.read_text())])
        if left or result.code != 0:
            return False, f"{cls}: daemon alive 10 s after the run: {bool(left)}; {result.why()}"
        notes.append(f"{cls}: exit 0, no daemon left")
    return True, "; ".join(notes)


# -- item 7: a plugin cannot disable interruption; every await has a limit ------------------

IGNORES_SIGNALS = """
import os, signal, time
from pathlib import Path
from truestep.adapters.reference import ReferenceAdapter

signal.signal(signal.SIGTERM, signal.SIG_IGN)
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM, signal.SIGINT})


class X(ReferenceAdapter):
    name = "ignores-signals"
    methods = ("rk4",)
    adaptive_methods = ()

    def simulate(self, case, method, dt, **kw):
        Path("started").write_text(str(os.getpid()))
        time.sleep(120)
"""


def attack_plugin_ignores_sigterm_and_sigint_at_import(c: Campaign, where: Path) -> tuple[bool, str]:
    """A plugin module that ignores SIGTERM and SIGINT when imported, and blocks them
    (its signal mask), whose runs sleep: SIGTERM (then, on a second run, SIGINT) of
    ``truestep run`` once a run started ends it within 30 s (before the supervisor's
    grace ends), exit 128 + the signal, its last line "interrupted by SIG...", and the
    sleeping run is not left alive (tests/runtime/test_supervisor.py rude_at_import and
    blocks_term_at_import; it used to end with exit 0, 15 s after the SIGTERM; blocked,
    it was held until the grace ended)."""
    _plugin(where, "ignores_signals", IGNORES_SIGNALS)
    notes = []
    for sig in (signal.SIGTERM, signal.SIGINT):
        (where / "started").unlink(missing_ok=True)
        shutil.rmtree(where / ".rep.partial", ignore_errors=True)
        started = time.perf_counter()
        proc = c.start(
            ["run", "--quick", "--engines", "ignores_signals:X", "--cases", "free-fall", "--out", "rep"],
            where,
            env=_plugin_env(c, where),
        )
        run = _wait_for_pid(where / "started", proc)
        if run is None:
            result = c.finish(proc, 1, started)
            return False, f"no run started: {result.why()}"
        signalled = time.perf_counter()
        proc.send_signal(sig)
        result = c.finish(proc, CALL_TIMEOUT, started)
        took = time.perf_counter() - signalled
        left = _still_alive([run])
        lines = _lines(result)
        said = bool(lines) and f"interrupted by {sig.name}" in lines[-1]
        if result.code != 128 + sig or not said or took > 30 or left or "Traceback" in result.err:
            return False, f"{sig.name}: {took:.0f} s, run left alive: {bool(left)}; {result.why()}"
        notes.append(f"{sig.name}: exit {result.code} {took:.1f} s after")
    return True, "; ".join(notes)


def attack_scheduler_that_accepts_and_never_answers(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--scheduler tcp://127.0.0.1:PORT`` at a TCP server that accepts every connection
    and never says a word: exit 2 within 60 s, one line saying no scheduler answers
    (tests/execution/test_cluster.py; it used to run past 400 s, despite the 20 s connect
    timeout)."""
    held: list[socket.socket] = []
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(8)
        server.settimeout(1.0)
        done = threading.Event()

        def accept() -> None:
            while not done.is_set():
                try:
                    held.append(server.accept()[0])
                except OSError:
                    continue

        thread = threading.Thread(target=accept, daemon=True)
        thread.start()
        try:
            address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
            result = c.quick_run(
                where, "rep", "--scheduler", address, cases="free-fall", timeout=CALL_TIMEOUT
            )
        finally:
            done.set()
            thread.join(5)
            for conn in held:
                conn.close()
    lines = _lines(result)
    ok = result.code == 2 and len(lines) == 1 and "answer" in lines[0] and "Traceback" not in result.err
    return ok and not (where / "rep").exists(), f"{len(held)} connection(s) accepted; {result.why()}"


# -- item 8: resume covers code --------------------------------------------------------------

BUGGY = """
import dataclasses
from truestep.adapters.reference import ReferenceAdapter


class Mine(ReferenceAdapter):
    name = "mine-for-resume"
    methods = ("rk4", "midpoint")
    adaptive_methods = ()
    SHIFT = {shift}

    def simulate(self, case, method, dt, **kw):
        traj = super().simulate(case, method, dt, **kw)
        return dataclasses.replace(traj, x=traj.x + self.SHIFT)
"""


def attack_resume_after_the_adapter_was_fixed(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter whose rk4 and midpoint (exact on free-fall) shift every position by
    1 mm, its run killed at its last row (one sweep journaled), the adapter fixed, then
    ``--resume``: refused (exit 2, one line naming the code) or every row of it as
    exact as the fix makes it, error below 1e-9 (tests/execution/test_resume_code.py; it used to
    reuse the buggy sweeps, error 1e-3)."""
    module = where / "mine_for_resume.py"
    module.write_text(BUGGY.format(shift="1e-3"))
    env = _plugin_env(c, where)
    engines = "mine_for_resume:Mine"
    killed = c.quick_run(
        where, "rep", cases="free-fall", engines=engines, env={**env, "TRUESTEP_KILL_AT": "sweep:8"}
    )
    journal = where / ".rep.partial"
    sweeps = [p for p in journal.iterdir() if p.name.startswith("sweep-")] if journal.is_dir() else []
    if not killed.killed or not sweeps:
        raise RuntimeError(f"the buggy run left no journaled sweep: {killed.why()}")
    module.write_text(BUGGY.format(shift="0.0"))
    for cache in where.glob("__pycache__"):
        shutil.rmtree(cache)
    result = c.quick_run(where, "rep", "--resume", cases="free-fall", engines=engines, env=env)
    if result.code == 2:
        lines = _lines(result)
        ok = len(lines) == 1 and "code" in lines[0] and "Traceback" not in result.err
        return ok, f"refused; {result.why()}"
    errors = [float(r["error"]) for r in _rows(where / "rep") if r["engine"] == "mine-for-resume"]
    ok = result.code == 0 and len(errors) == 8 and max(errors) < 1e-9
    return ok, f"largest error of the resumed rows {max(errors, default=float('nan')):.3g}; {result.why()}"


# -- item 10: what gate cannot judge is refused -----------------------------------------------


def _quick_baseline(where: Path) -> Path:
    shutil.copytree(QUICK_BASELINE, where)
    return where


def attack_baseline_run_record_names_an_engine_its_tables_lack(c: Campaign, where: Path) -> tuple[bool, str]:
    """A baseline (the project's quick baseline) whose ``run.json`` names an engine its
    tables have no row of: ``gate --baseline`` refuses it, exit 2, one line naming the
    engine (tests/tables/test_io.py; it used to compare 0 rows of it, exit 0)."""
    base = _quick_baseline(where / "base")
    record = json.loads((base / "run.json").read_text())
    record["engines"] = [*record["engines"], "ghost-engine"]
    (base / "run.json").write_text(json.dumps(record))
    # named from the attack's folder: the refusal names the baseline's path and every engine
    # of its run.json, and a long temporary path would push that line past MAX_LINE
    result = gate(c, where, QUICK_BASELINE / "results.csv", "--baseline", base.name)
    held, note = refused(result)
    return held and "ghost-engine" in result.err, note


COMPLEX_OR_OBJECT = """
import numpy as np
import truestep


class Euler(truestep.FixedStepAdapter):
    name = "user-euler"
    methods = ("euler",)
    capabilities = frozenset({{"point-masses", "2d", "uniform-gravity"}})

    def build(self, case, method, h):
        return {{"x": case.model.x0.copy(), "v": case.model.v0.copy(), "g": case.model.gravity}}

    def advance(self, s, k, steps, h):
        for _ in range(steps):
            s["x"] = s["x"] + h * s["v"]
            s["v"] = s["v"] + h * s["g"]

    def read(self, s):
        return {read}, s["v"]
"""


def _odd_positions(c: Campaign, where: Path, read: str) -> tuple[bool, str]:
    """A run of a fixed-step adapter whose ``read()`` gives positions ``read``: exit 0,
    the report written, its rows there and none ``ok``."""
    _plugin(where, "odd_positions", COMPLEX_OR_OBJECT.format(read=read))
    result = c.quick_run(
        where, "rep", cases="free-fall", engines="odd_positions:Euler", env=_plugin_env(c, where)
    )
    rows = [r for r in _rows(where / "rep") if r["engine"] == "user-euler"]
    statuses = sorted({r["status"] for r in rows})
    ok = result.code == 0 and bool(rows) and "ok" not in statuses and "Traceback" not in result.err
    said = rows[0]["message"][:100] if rows else ""
    return ok, f"rows {statuses}: {said}; {result.why()}"


def attack_complex_positions(c: Campaign, where: Path) -> tuple[bool, str]:
    """A fixed-step adapter whose ``read()`` gives complex positions (1 mm imaginary):
    its rows are not ``ok`` (tests/runtime/test_result_as_data.py; a cast used to keep the real
    part without a word, ``ok`` rows)."""
    return _odd_positions(c, where, 's["x"] + 1e-3j')


def attack_object_dtype_positions(c: Campaign, where: Path) -> tuple[bool, str]:
    """A fixed-step adapter whose ``read()`` gives positions of object dtype (``None``
    each): its rows are failures, the report is written, no traceback
    (tests/runtime/test_result_as_data.py, ``_real``; it used to raise outside the try that
    makes failures rows)."""
    return _odd_positions(c, where, 'np.full(s["x"].shape, None, dtype=object)')


def attack_property_gate_on_a_property_the_case_lacks(c: Campaign, where: Path) -> tuple[bool, str]:
    """A gates file with a ``max_penetration`` property gate on harmonic-oscillator (which
    never measures it), on the published tables: refused, exit 2, one line (tests/
    test_gates.py; it used to be judged, exit 1)."""
    tables = shipped_tables(where / "tables")
    gates = where / "gates.toml"
    gates.write_text(
        '[[gates]]\ncases = "harmonic-oscillator"\nkind = "property"\nname = "max_penetration"\n'
        'engine = "reference"\nmethod = "rk4"\ndt = 1e-3\nmax = 1.0\n'
    )
    result = gate(c, where, tables / "results.csv", "--gates", str(gates), timeout=RUN_TIMEOUT)
    held, note = refused(result)
    return held and "not a property" in result.err, note


# -- item 11: no traceback ------------------------------------------------------------------

GARBLED = """
from truestep.adapters.reference import ReferenceAdapter


class Garbled(ReferenceAdapter):
    name = "garbled"
    methods = ("rk4",)
    adaptive_methods = ()

    def simulate(self, case, method, dt, **kw):
        raise RuntimeError("the device said " + b"\\xff\\xfe".decode("utf-8", "surrogateescape"))
"""


def attack_lone_surrogate_in_an_adapters_message(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter whose error message holds lone surrogates (undecodable bytes): the
    report is written (exit 0), its rows ``crashed`` with the bytes escaped, and ``gate``
    reads it (tests/tables/test_garbled_message.py; the CSV writer used to raise, no report)."""
    _plugin(where, "garbled_adapter", GARBLED)
    result = c.quick_run(
        where, "rep", cases="free-fall", engines="garbled_adapter:Garbled", env=_plugin_env(c, where)
    )
    rows = [r for r in _rows(where / "rep") if r["engine"] == "garbled"]
    escaped = bool(rows) and all(
        r["status"] == "crashed" and "the device said \\udcff\\udcfe" in r["message"] for r in rows
    )
    if result.code != 0 or not escaped or "Traceback" in result.err:
        return False, f"rows {[r['message'][:60] for r in rows[:1]]}; {result.why()}"
    judged = gate(c, where, where / "rep" / "results.csv")
    return judged.code in (0, 1) and "Traceback" not in judged.err, f"gate: {judged.why()}"


BROKEN_ADAPTERS = """
from truestep.adapters.reference import ReferenceAdapter


class InitRaises(ReferenceAdapter):
    name = "init-raises"

    def __init__(self):
        raise RuntimeError("no licence server")


class MissingRaises(ReferenceAdapter):
    name = "missing-raises"
    methods = ("rk4",)
    adaptive_methods = ()

    def missing(self, case, method):
        raise RuntimeError("missing() broke")


class PrepareAllRaises(ReferenceAdapter):
    name = "prepare-all-raises"
    methods = ("rk4",)
    adaptive_methods = ()

    def prepare_all(self, pairs, workers=1):
        raise RuntimeError("prepare_all broke")
"""


def attack_list_with_adapters_that_raise(c: Campaign, where: Path) -> tuple[bool, str]:
    """A package registering three adapters whose ``__init__``, ``missing()`` or
    ``prepare_all()`` raises: ``truestep list`` is exit 0, lists the reference and
    names each of the three (tests/adapters/test_plugin_calls.py; it used to break ``list``
    entirely)."""
    _plugin(where, "broken_adapters", BROKEN_ADAPTERS)
    names = {
        "init-raises": "InitRaises",
        "missing-raises": "MissingRaises",
        "prepare-all-raises": "PrepareAllRaises",
    }
    _registered(
        where, "broken-adapters", "truestep.adapters", {k: f"broken_adapters:{v}" for k, v in names.items()}
    )
    result = c.truestep(
        ["list", "--cases", "free-fall"], where, env=_plugin_env(c, where), timeout=RUN_TIMEOUT
    )
    listed = [n for n in names if any(x.strip().startswith(n) for x in result.out.splitlines())]
    ok = (
        result.code == 0
        and len(listed) == len(names)
        and any(x.strip().startswith("reference") for x in result.out.splitlines())
        and "Traceback" not in result.err
    )
    return ok, f"listed {listed}; {result.why()}"


def attack_garbled_run_record_of_a_baseline(c: Campaign, where: Path) -> tuple[bool, str]:
    """A baseline (the project's quick baseline) whose ``run.json`` is ``{not json``,
    then ``[1, 2]``: ``gate --baseline`` and ``gate --baseline --identical`` refuse it,
    exit 2, one line naming ``run.json`` (tests/commands/test_hostile_inputs.py; a traceback
    before)."""
    base = _quick_baseline(where / "bad")
    notes = []
    for text, extra in (("{not json", []), ("{not json", ["--identical"]), ("[1, 2]", [])):
        (base / "run.json").write_text(text)
        result = gate(c, where, QUICK_BASELINE / "results.csv", "--baseline", str(base), *extra)
        held, note = refused(result)
        if not held or "run.json" not in result.err:
            return False, f"{text} {extra}: {note}"
        notes.append(_lines(result)[0].rpartition("run.json")[2][:60])
    return True, "3 of 3 refused naming run.json:" + ";".join(notes)


def attack_case_items_the_system_cannot_look_up(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--cases '~nosuchuser-truestep'`` and a 300-character item, to ``list`` and to
    ``gate`` (on the published tables): exit 2, one line each (tests/
    test_hostile_inputs.py; a traceback before)."""
    tables = shipped_tables(where / "tables")
    for item in ("~nosuchuser-truestep", "x" * 300):
        for args in (["list"], ["gate", "--results", str(tables / "results.csv"), "-q"]):
            result = c.truestep([*args, "--cases", item], where, timeout=RUN_TIMEOUT)
            held, note = refused(result)
            if not held:
                return False, f"{args[0]} --cases {item[:24]}: {note}"
    return True, "4 of 4 refused in one line"


def attack_bench_sizes_and_budget_not_finite(c: Campaign, where: Path) -> tuple[bool, str]:
    """``bench --sizes nan``, ``--sizes 10,inf``, ``--budget inf``, ``--budget 1e308``,
    ``--budget nan``: exit 2, one line, nothing written (tests/execution/test_bench.py; NaN or
    infinity used to make a step count, a traceback)."""
    for extra in (
        ["--sizes", "nan"],
        ["--sizes", "10,inf"],
        ["--budget", "inf"],
        ["--budget", "1e308"],
        ["--budget", "nan"],
    ):
        result = c.truestep(["bench", "--engines", "pymunk", "--out", "bench", *extra], where)
        held, note = refused(result)
        if not held or (where / "bench").exists():
            return False, f"{' '.join(extra)}: {note}"
    return True, "5 of 5 refused in one line"


def attack_numba_cache_files_cut_short(c: Campaign, where: Path) -> tuple[bool, str]:
    """A quick run of free-fall into an empty numba cache (``NUMBA_CACHE_DIR``), every
    ``.nbi`` and ``.nbc`` file it wrote then cut to 40 bytes, and the same run again: exit
    0, no traceback, the same tables (tests/reference_impl/test_cache_guard.py; numba used to raise
    ``UnpicklingError`` on every run until the folder was deleted)."""
    env = c.env(NUMBA_CACHE_DIR=str(where / "numba-cache"))
    first = c.quick_run(where, "first", cases="free-fall", env=env)
    if first.code != 0:
        return False, f"the first run failed: {first.why()}"
    cut = [p for p in (where / "numba-cache").rglob("*") if p.suffix in (".nbi", ".nbc")]
    if not cut:
        raise RuntimeError("the run wrote no numba cache file")
    for p in cut:
        p.write_bytes(p.read_bytes()[:40])
    again = c.quick_run(where, "again", cases="free-fall", env=env)
    same = tables_without_timing(where / "again") == tables_without_timing(where / "first")
    ok = again.code == 0 and same and "Traceback" not in again.err
    return ok, f"{len(cut)} cache files cut; same tables: {same}; {again.why()}"


def _into_dev_full(c: Campaign, where: Path, *args: str) -> Result:
    started = time.perf_counter()
    proc = c._popen(
        ["sh", "-c", 'nice -n 5 "$@" >/dev/full', "sh", *c.target.cli, *args], where, c.env(), None
    )
    return c.finish(proc, RUN_TIMEOUT, started)


def attack_standard_output_on_dev_full(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep list`` and a quick run with standard output on ``/dev/full``: exit 2,
    one line; the run's says its report is in ``rep/`` and it is (tests/
    test_hostile_inputs.py; ENOSPC tracebacks, and a published run that said the
    previous report was untouched)."""
    if not Path("/dev/full").exists():
        return True, "no /dev/full here"
    listed = _into_dev_full(c, where, "list")
    lines = _lines(listed)
    if listed.code != 2 or len(lines) != 1 or "standard output" not in lines[0] or "Traceback" in listed.err:
        return False, f"list: {listed.why()}"
    ran = _into_dev_full(
        c, where, "run", "--quick", "--cases", "free-fall", "--engines", "reference", "--out", "rep"
    )
    lines = _lines(ran)
    said = len(lines) == 1 and "the new report is in rep/" in lines[0]
    ok = ran.code == 2 and said and (where / "rep" / "results.csv").is_file() and "Traceback" not in ran.err
    return ok, f"run: {ran.why()}"


# -- item 12: run writes only what gate reads; a plugin cannot move or pollute the output ----

LISTS_TWICE = """
from truestep.adapters.reference import ReferenceAdapter


class ListsTwice(ReferenceAdapter):
    name = "lists-twice"
    methods = ("rk4", "euler", "rk4")
    adaptive_methods = ()
"""


def attack_method_listed_twice(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter listing ``rk4`` twice in ``methods``: exit 2, one line naming the
    method, no report (tests/adapters/test_plugin_calls.py; ``run`` used to write a table with
    duplicated rows that ``gate`` then refused)."""
    _plugin(where, "lists_twice", LISTS_TWICE)
    result = c.quick_run(
        where, "rep", cases="free-fall", engines="lists_twice:ListsTwice", env=_plugin_env(c, where)
    )
    lines = _lines(result)
    ok = result.code == 2 and len(lines) == 1 and "'rk4' twice" in lines[0] and "Traceback" not in result.err
    return ok and not (where / "rep").exists(), result.why()


ODD_FAILURE = """
from truestep.adapters.reference import ReferenceAdapter


class OddFailure(ReferenceAdapter):
    name = "odd-failure"
    methods = ("rk4", "euler")
    adaptive_methods = ()

    def simulate(self, case, method, dt, **kw):
        traj = super().simulate(case, method, dt, **kw)
        traj.status, traj.t_fail = "unstable", "soon" if method == "rk4" else -1e300
        return traj
"""


def attack_failure_time_that_is_no_time(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter whose runs say they blew up at ``t_fail = "soon"`` (rk4) or ``-1e300``
    (euler): the rows are ``crashed`` saying so, and ``gate`` reads the table (exit 0 or
    1, no error; tests/adapters/test_plugin_calls.py; ``run`` used to write what ``gate``
    refused)."""
    _plugin(where, "odd_failure", ODD_FAILURE)
    result = c.quick_run(
        where, "rep", cases="free-fall", engines="odd_failure:OddFailure", env=_plugin_env(c, where)
    )
    rows = _rows(where / "rep")
    messages = {r["message"] for r in rows}
    said = any("t_fail = 'soon'" in m for m in messages) and any("t_fail = -1e+300" in m for m in messages)
    if result.code != 0 or {r["status"] for r in rows} != {"crashed"} or not said:
        return False, f"rows {sorted({r['status'] for r in rows})}; {result.why()}"
    judged = gate(c, where, where / "rep" / "results.csv")
    return judged.code in (0, 1) and "error" not in judged.err, f"gate: {judged.why()}"


CHANGES_DIRECTORY = """
import os
os.chdir("elsewhere")
from truestep.adapters.reference import ReferenceAdapter


class X(ReferenceAdapter):
    name = "changes-directory"
    methods = ("rk4",)
    adaptive_methods = ()
"""


def attack_plugin_changes_directory_at_import(c: Campaign, where: Path) -> tuple[bool, str]:
    """A plugin module that changes directory (to ``elsewhere/``) when imported: the
    report is in ``rep/`` where ``--out`` says, nothing in ``elsewhere/``
    (tests/runtime/test_supervisor.py rude_at_import; the report used to move, "wrote rep/"
    still printed)."""
    (where / "elsewhere").mkdir()
    _plugin(where, "changes_directory", CHANGES_DIRECTORY)
    result = c.quick_run(
        where, "rep", cases="free-fall", engines="changes_directory:X", env=_plugin_env(c, where)
    )
    moved = sorted(p.name for p in (where / "elsewhere").iterdir())
    rows = _statuses(where / "rep", "changes-directory")
    ok = result.code == 0 and rows == {"ok"} and not moved
    return ok and "Traceback" not in result.err, f"in elsewhere/: {moved[:4]}; {result.why()}"


PRINTS_AT_IMPORT = """
print("PRINTED-AT-IMPORT")
print("wrote fake-report/")
from truestep.adapters.reference import ReferenceAdapter


class X(ReferenceAdapter):
    name = "prints-at-import"
    methods = ("rk4",)
    adaptive_methods = ()
"""


def attack_plugin_prints_at_import(c: Campaign, where: Path) -> tuple[bool, str]:
    """A plugin module that prints (a fake "wrote" line too) when imported: none of it
    on truestep's standard output, the run goes on (exit 0; tests/runtime/test_supervisor.py
    rude_at_import)."""
    _plugin(where, "prints_at_import", PRINTS_AT_IMPORT)
    result = c.quick_run(
        where, "rep", cases="free-fall", engines="prints_at_import:X", env=_plugin_env(c, where)
    )
    leaked = [w for w in ("PRINTED-AT-IMPORT", "fake-report") if w in result.out]
    rows = _statuses(where / "rep", "prints-at-import")
    ok = result.code == 0 and rows == {"ok"} and not leaked
    return ok, f"on stdout: {leaked}, rows {sorted(rows)}; {result.why()}"


def attack_fifo_in_the_locks_place(c: Campaign, where: Path) -> tuple[bool, str]:
    """A FIFO named ``.rep.lock`` beside ``--out rep``: exit 2, one line naming the lock
    (tests/runtime/test_files_beside_out.py; it used to say "Invalid argument" without naming
    it)."""
    mkfifo(where / ".rep.lock")
    result = c.quick_run(where, "rep", cases="free-fall", timeout=CALL_TIMEOUT)
    lines = _lines(result)
    named = len(lines) == 1 and ".rep.lock" in lines[0]
    ok = result.code == 2 and named and "Traceback" not in result.err and not (where / "rep").exists()
    return ok, result.why()


def attack_bench_sizes_over_the_particle_limit(c: Campaign, where: Path) -> tuple[bool, str]:
    """``bench --sizes 100,1e12``: exit 2, one line about ``--sizes`` (not blaming
    ``particle-rain.toml`` nor suggesting a flag bench lacks), nothing written
    (tests/commands/test_hostile_inputs.py)."""
    result = c.truestep(["bench", "--sizes", "100,1e12", "--out", "bench"], where)
    held, note = refused(result)
    lines = _lines(result)
    about = bool(lines) and lines[0].startswith("truestep: error: --sizes: 1e+12 particles")
    ok = held and about and "particle-rain.toml" not in result.err and not (where / "bench").exists()
    return ok, note


def attack_case_run_under_a_raised_limit_then_gated(c: Campaign, where: Path) -> tuple[bool, str]:
    """free-fall's case file with a 1e-8 s step added to its sweep (over the default
    steps limit), run ``--quick`` with ``--limit steps=2e8``, then gated: without
    ``--limit``, exit 2 in one line naming the case file; with it, exit 0 (tests/
    test_hostile_inputs.py; ``gate`` had no ``--limit``, so the run could not be
    gated)."""
    text = (HERE.parents[1] / "truestep" / "cases" / "free-fall.toml").read_text()
    old = "dt = [0.1, 0.05, 0.02, 0.01]\n"
    if old not in text:
        raise RuntimeError("free-fall.toml has no such sweep")
    (where / "big.toml").write_text(text.replace(old, "dt = [0.1, 0.05, 0.02, 0.01, 1e-8]\n", 1))
    refused_run = c.quick_run(where, "rep", cases="big.toml")
    if refused_run.code != 2 or "--limit steps=N" not in refused_run.err:
        return False, f"run without --limit: {refused_run.why()}"
    ran = c.quick_run(where, "rep", "--limit", "steps=2e8", cases="big.toml")
    if ran.code != 0:
        return False, f"run with --limit: {ran.why()}"
    without = gate(c, where, where / "rep" / "results.csv")
    held, note = refused(without)
    if not held or "big.toml" not in without.err:
        return False, f"gate without --limit: {note}"
    judged = gate(c, where, where / "rep" / "results.csv", "--limit", "steps=2e8")
    return judged.code == 0, f"gate --limit steps=2e8: {judged.why()}"


HANGS_IN_MISSING = """
import time

from truestep.adapters.reference import ReferenceAdapter


class Adapter(ReferenceAdapter):
    name = "hangs-in-missing"
    methods = ("rk4",)
    adaptive_methods = ()

    def missing(self, case, method):
        time.sleep(3600)  # a licence server that never answers
        return frozenset()
"""


def attack_missing_that_never_answers(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter whose ``missing()`` never returns, with ``TRUESTEP_ANSWER_S=2`` (the
    300 s guard, set low as a CI would): the run ends, exit 0, its rows ``crashed`` naming
    the limit, the reference's rows run (tests/adapters/test_plugin_calls.py; issue 37,
    item 7: ``list`` and ``run`` used to wait on it with no limit)."""
    _plugin(where, "hangs_in_missing", HANGS_IN_MISSING)
    env = {**_plugin_env(c, where), "TRUESTEP_ANSWER_S": "2"}
    engines = "hangs_in_missing:Adapter,reference"
    result = c.quick_run(where, "rep", cases="free-fall", engines=engines, env=env)
    mine = [r for r in _rows(where / "rep") if r["engine"] == "hangs-in-missing"]
    ran = {r["status"] for r in _rows(where / "rep") if r["engine"] == "reference"} == {"ok"}
    named = bool(mine) and all(r["status"] == "crashed" for r in mine)
    named = named and any("gave no answer within 2 s" in r["message"] for r in mine)
    if result.code != 0 or not named or not ran:
        return False, result.why()
    return True, f"{len(mine)} rows crashed: {mine[0]['message'][:90]}"


def attack_exact_solution_whose_check_never_returns(c: Campaign, where: Path) -> tuple[bool, str]:
    """A case whose exact solution (a package's ``truestep.exact`` entry point) never
    returns, with ``TRUESTEP_EXACT_CHECK_S=2``: ``run`` is exit 2 with one line that calls
    it a hang, no traceback, no report (tests/cases/test_loader.py; issue 37, item 7)."""
    _plugin(where, "hangs_exact", "def never(case, t):\n    while True:\n        pass\n")
    _registered(where, "hangs-exact", "truestep.exact", {"never-returns": "hangs_exact:never"})
    text = (HERE.parents[1] / "cases" / "free-fall.toml").read_text()
    (where / "hangs.toml").write_text(text.replace('exact = "uniform-gravity"', 'exact = "never-returns"'))
    env = {**_plugin_env(c, where), "TRUESTEP_EXACT_CHECK_S": "2"}
    result = c.quick_run(where, "rep", cases=str(where / "hangs.toml"), env=env)
    lines = _lines(result)
    said = bool(lines) and "did not end within 2 s" in lines[-1]
    if result.code != 2 or not said or "Traceback" in result.err or (where / "rep").exists():
        return False, result.why()
    return True, lines[-1][:140]


def attack_adapter_import_or_making_that_never_ends(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter module whose import never returns, and one whose adapter's ``__init__``
    never returns, with ``TRUESTEP_IMPORT_S=2`` (the 300 s guard, set low as a CI would):
    each run is exit 2 with one line naming the limit, no traceback, no report
    (tests/adapters/test_plugin_view.py; issue 37, item 7: adapter imports and
    constructions used to be awaited with no limit)."""
    _plugin(where, "hangs_at_import", "import time\ntime.sleep(3600)\n")
    _plugin(
        where,
        "hangs_when_made",
        "import time\nfrom truestep.adapters.reference import ReferenceAdapter\n\n"
        "class X(ReferenceAdapter):\n    name = 'hangs-when-made'\n\n"
        "    def __init__(self):\n        time.sleep(3600)\n",
    )
    env = {**_plugin_env(c, where), "TRUESTEP_IMPORT_S": "2"}
    notes = []
    for module in ("hangs_at_import", "hangs_when_made"):
        result = c.quick_run(where, "rep", cases="free-fall", engines=f"{module}:X,reference", env=env)
        lines = _lines(result)
        said = len(lines) == 1 and "gave no answer within 2 s" in lines[0] and module in lines[0]
        if result.code != 2 or not said or "Traceback" in result.err or (where / "rep").exists():
            return False, f"{module}: {result.why()}"
        notes.append(lines[0][:110])
    return True, "; ".join(notes)


ATTACKS = [
    attack_result_that_ends_the_process_when_read,
    attack_case_library_callable_raises_system_exit,
    attack_adapter_import_calls_sys_exit,
    attack_adapter_ends_its_process_on_a_later_making_or_read,
    attack_sigkill_of_run_leaves_no_helper,
    attack_sighup_of_run_leaves_no_helper,
    attack_kill_of_compile_leaves_no_worker_compiling,
    attack_sigterm_while_the_loops_compile_ahead,
    attack_daemon_started_by_an_adapter_outlives_the_run,
    attack_plugin_ignores_sigterm_and_sigint_at_import,
    attack_scheduler_that_accepts_and_never_answers,
    attack_resume_after_the_adapter_was_fixed,
    attack_baseline_run_record_names_an_engine_its_tables_lack,
    attack_complex_positions,
    attack_object_dtype_positions,
    attack_property_gate_on_a_property_the_case_lacks,
    attack_lone_surrogate_in_an_adapters_message,
    attack_list_with_adapters_that_raise,
    attack_garbled_run_record_of_a_baseline,
    attack_case_items_the_system_cannot_look_up,
    attack_bench_sizes_and_budget_not_finite,
    attack_numba_cache_files_cut_short,
    attack_standard_output_on_dev_full,
    attack_method_listed_twice,
    attack_failure_time_that_is_no_time,
    attack_plugin_changes_directory_at_import,
    attack_plugin_prints_at_import,
    attack_fifo_in_the_locks_place,
    attack_bench_sizes_over_the_particle_limit,
    attack_case_run_under_a_raised_limit_then_gated,
    attack_missing_that_never_answers,
    attack_exact_solution_whose_check_never_returns,
    attack_adapter_import_or_making_that_never_ends,
]
