"""What an isolated run starts dies with it, and what it prints stays with it: an
adapter's own processes (a child, a daemon that left the process group) never outlive
the call, after a normal finish, a crash, a timeout or SIGTERM; its output is captured,
shown in a failed row's message, and never reaches truestep's own output."""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from kill_helpers import still_running

from truestep.adapters.reference import ReferenceAdapter
from truestep.runtime.isolation import finish_isolated, run_isolated, start_isolated


def _spawn(pids: Path, how: str, then: str = "return") -> str:
    """Start a process that sleeps (a plain child, or a daemon: double fork and setsid),
    note its pid in ``pids``, print on every channel, then return or misbehave."""
    if how == "child":
        proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
        pid = proc.pid
    else:
        first = os.fork()
        if first == 0:
            os.setsid()
            if os.fork() == 0:
                pids.write_text(str(os.getpid()))
                time.sleep(120)
            os._exit(0)
        os.waitpid(first, 0)
        deadline = time.monotonic() + 5
        while not pids.exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        pid = int(pids.read_text())
    pids.write_text(str(pid))
    print("PRINTED-STDOUT", flush=True)
    print("PRINTED-STDERR", file=sys.stderr, flush=True)
    os.write(1, b"WRITTEN-FD1\n")
    subprocess.run(["echo", "ECHOED"], check=True)
    ctypes.CDLL(None).printf(b"C-PRINTF\n")
    if then == "raise":
        raise RuntimeError("gave up")
    if then == "hang":
        time.sleep(120)
    return "done"


def _pid(pids: Path) -> list[int]:
    return [int(pids.read_text())] if pids.exists() else []


def test_what_a_call_starts_dies_with_it_and_its_output_stays_with_it(tmp_path, capfd):
    for how in ("child", "daemon"):
        for then, status in (("return", "ok"), ("raise", "crashed"), ("hang", "timeout")):
            pids = tmp_path / f"{how}-{then}"
            out = run_isolated(_spawn, (pids, how, then), 3.0 if then == "hang" else 60.0)
            assert out.status == status, out
            assert _pid(pids) and still_running(_pid(pids)) == [], (how, then)
            if then != "hang":
                for word in ("PRINTED-STDOUT", "PRINTED-STDERR", "WRITTEN-FD1", "ECHOED", "C-PRINTF"):
                    assert word in out.output, (word, out.output)
    seen = capfd.readouterr()
    assert "PRINTED" not in seen.out + seen.err and "ECHOED" not in seen.out + seen.err


SIGTERMED = """
import sys, time
from pathlib import Path
from truestep.runtime.interrupts import Interrupted, handled
from test_containment import _spawn
from truestep.runtime.isolation import start_isolated
with handled():
    try:
        start_isolated(_spawn, (Path(sys.argv[1]), sys.argv[2], "hang"), 120.0)
        time.sleep(60)
    except Interrupted:
        sys.exit(3)
"""


def test_sigterm_to_truestep_kills_what_the_adapter_started(tmp_path):
    for how in ("child", "daemon"):
        pids = tmp_path / how
        parent = subprocess.Popen(
            [sys.executable, "-c", SIGTERMED, str(pids), how],
            cwd=Path(__file__).parent,
            env={**os.environ, "PYTHONPATH": os.pathsep.join(str(p) for p in Path(__file__).parents[:2])},
        )
        deadline = time.monotonic() + 60
        while not pids.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.2)
        parent.send_signal(signal.SIGTERM)
        assert parent.wait(20) == 3
        assert _pid(pids) and still_running(_pid(pids)) == [], how


class Chatty(ReferenceAdapter):
    """The reference, printing and starting a helper in every run; its last step raises."""

    name = "chatty-test"
    methods = ("rk4",)
    adaptive_methods = ()

    def simulate(self, case, method, dt):
        print(f"wrote fake/ ({dt} rows) CHATTY", flush=True)
        subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
        if dt == min(case.quick_dts):
            raise RuntimeError("the last step failed")
        return super().simulate(case, method, dt)


def test_a_failed_rows_message_shows_the_engines_output(tmp_path, capfd):
    from truestep.adapters import resolve_engine
    from truestep.cases import load_cases
    from truestep.execution.runner import Timing, run_sweep

    resolve_engine("test_containment:Chatty")
    case = load_cases("free-fall")[0]
    before = {p for p in os.listdir("/proc") if p.isdigit()}
    rows = run_sweep(case, "chatty-test", "rk4", case.quick_dts, adaptive=False, timing=Timing(max_repeats=1))
    assert [r["status"] for r in rows] == ["ok"] * (len(rows) - 1) + ["crashed"]
    assert "the last step failed" in rows[-1]["message"]
    assert "engine output: " in rows[-1]["message"] and "CHATTY" in rows[-1]["message"]
    assert "CHATTY" not in rows[0].get("message", "")
    seen = capfd.readouterr()
    assert "CHATTY" not in seen.out + seen.err
    left = [int(p) for p in {p for p in os.listdir("/proc") if p.isdigit()} - before]
    assert [
        p
        for p in still_running(left, 1.0)
        if "sleep(120)" in Path(f"/proc/{p}/cmdline").read_text(errors="replace")
    ] == []


def test_start_isolated_children_lead_their_own_process_group():
    run = start_isolated(time.sleep, (30,), 0.5)
    try:
        assert os.getpgid(run.proc.pid) == run.proc.pid
    finally:
        assert finish_isolated(run).status == "timeout"
