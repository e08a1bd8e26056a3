"""The ``truestep`` command runs its work in a worker that a small supervisor watches
(issue 37, items 5-7): plugin code that ends the process, ignores the signals that stop a
run, changes directory, prints at import, or leaves processes behind cannot end the
command quietly or outlive it. Each test runs the real command on a plugin written to do
one of those things."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest
from kill_helpers import still_running

from truestep.runtime.supervisor import GRACE_ENV

RUN = ["run", "--quick", "--cases", "free-fall"]

PLUGINS = {
    "exits_at_import": """
        import sys
        sys.exit(0)
    """,
    "os_exit_at_import": """
        import os
        os._exit(0)
    """,
    "crashes_at_import": """
        import ctypes
        ctypes.string_at(0)
    """,
    "interrupts_at_import": """
        import os, signal
        os.kill(os.getpid(), signal.SIGINT)
    """,
    "exits_in_missing": """
        import os
        from truestep.adapters.reference import ReferenceAdapter

        class X(ReferenceAdapter):
            name = "exits-in-missing"

            def missing(self, case, method):
                os._exit(0)
    """,
    "crashes_in_skip": """
        import os, signal
        from truestep.adapters.reference import ReferenceAdapter

        class X(ReferenceAdapter):
            name = "crashes-in-skip"

            def skip(self, case, method):
                os.kill(os.getpid(), signal.SIGSEGV)
    """,
    "exits_in_prepare": """
        import os
        from truestep.adapters.reference import ReferenceAdapter

        class X(ReferenceAdapter):
            name = "exits-in-prepare"

            def prepare(self, case, method):
                os._exit(0)
    """,
    "exits_when_made": """
        import os
        from truestep.adapters.reference import ReferenceAdapter

        class X(ReferenceAdapter):
            name = "exits-when-made"

            def __init__(self):
                os._exit(0)
    """,
    "exits_in_a_later_prepare": """
        import os
        from pathlib import Path
        from truestep.adapters.reference import ReferenceAdapter

        class X(ReferenceAdapter):
            name = "exits-in-a-later-prepare"

            def prepare(self, case, method):
                mark = Path("prepared-once")
                if mark.exists():
                    os._exit(0)
                mark.write_text("")
    """,
    "sys_exit_in_missing": """
        import sys
        from truestep.adapters.reference import ReferenceAdapter

        class X(ReferenceAdapter):
            name = "sys-exit-in-missing"

            def missing(self, case, method):
                sys.exit(0)
    """,
    "sys_exit_in_methods": """
        import sys
        from truestep.adapters.reference import ReferenceAdapter

        class X(ReferenceAdapter):
            name = "sys-exit-in-methods"

            @property
            def methods(self):
                sys.exit(0)
    """,
    "rude_at_import": """
        import os, signal, time
        from pathlib import Path
        from truestep.adapters.reference import ReferenceAdapter

        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGHUP, signal.SIG_IGN)
        HERE = os.getcwd()
        os.chdir("/")
        print("PRINTED-AT-IMPORT")

        class X(ReferenceAdapter):
            name = "rude-at-import"
            methods = ("rk4",)
            adaptive_methods = ()

            def simulate(self, case, method, dt, **kw):
                Path(HERE, "started").write_text(str(os.getpid()))
                time.sleep(120)
    """,
    "stuck_in_compiled_code": """
        import subprocess, sys
        from pathlib import Path
        from truestep.runtime.isolation import in_isolated_child

        if not in_isolated_child():  # the command's own process, after the forked trial import
            helper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
            Path("helper.pid").write_text(str(helper.pid))
            sum(range(10**12))  # compiled code, in which no signal handler runs
    """,
    "blocks_term_at_import": """
        import signal
        from pathlib import Path
        from truestep.adapters.reference import ReferenceAdapter

        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})

        class X(ReferenceAdapter):
            name = "blocks-term"
            methods = ("rk4",)
            adaptive_methods = ()

            def simulate(self, case, method, dt, **kw):
                import time

                Path("started").write_text("")
                time.sleep(120)
    """,
    "daemon_at_construction": """
        import os, time
        from pathlib import Path
        from truestep.adapters.reference import ReferenceAdapter

        class X(ReferenceAdapter):
            name = "daemon-at-construction"
            methods = ("rk4",)
            adaptive_methods = ()

            def __init__(self):  # in the process that makes the adapter's view, and in each run's
                if Path("daemon.pid").exists():
                    return
                if os.fork() == 0:
                    os.setsid()
                    if os.fork() == 0:
                        Path("daemon.pid").write_text(str(os.getpid()))
                        time.sleep(120)
                    os._exit(0)
                while not Path("daemon.pid").exists():
                    time.sleep(0.01)
    """,
    "helper_then_sleep": """
        import os, subprocess, sys, time
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
    """,
    "made_and_read_only_apart": """
        import os
        from pathlib import Path
        from truestep.adapters.reference import ReferenceAdapter
        from truestep.runtime.isolation import in_isolated_child

        def _where(what):
            if not in_isolated_child():
                Path(f"outside-{os.getpid()}").write_text(what)
                os._exit(0)  # were this truestep's own process, the command would end here

        class X(ReferenceAdapter):
            name = "made-and-read-only-apart"
            methods = ("rk4", "euler")
            adaptive_methods = ()

            def __init__(self):
                _where("__init__")
                super().__init__()

            @property
            def speed_claim(self):
                _where("speed_claim")
                return True
    """,
}


@pytest.fixture
def plugins(tmp_path) -> Path:
    for name, text in PLUGINS.items():
        (tmp_path / f"{name}.py").write_text(textwrap.dedent(text))
    return tmp_path


def _start(where: Path, *args: str, grace: int = 30) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(where), GRACE_ENV: str(grace)}
    return subprocess.Popen(
        [sys.executable, "-m", "truestep", *args],
        cwd=where,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_for(path: Path, timeout: float = 60.0) -> int:
    deadline = time.monotonic() + timeout
    while not path.exists() or not path.read_text():
        assert time.monotonic() < deadline, f"{path.name} never appeared"
        time.sleep(0.05)
    time.sleep(0.2)
    return int(path.read_text())


def _wait_for_file(path: Path, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        assert time.monotonic() < deadline, f"{path.name} never appeared"
        time.sleep(0.05)


def _lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("truestep:")]


def test_a_plugin_that_ends_its_process_when_asked_what_it_runs_makes_crashed_rows(plugins):
    """Issue 37, item 5: an adapter of another package is asked ``missing``, ``duplicate``
    and ``skip`` in a forked process; where that process ends (``os._exit(0)``, a crash),
    every row of the engine is ``crashed``, saying how, and the run goes on. Before,
    ``os._exit(0)`` in ``missing()`` ended the command: exit 3 and no report."""
    said = {
        "exits-in-missing": "ended the process it was asked in (exit status 0)",
        "crashes-in-skip": "ended the process it was asked in (killed by SIGSEGV)",
    }
    proc = _start(
        plugins, *RUN, "--engines", "exits_in_missing:X,crashes_in_skip:X,reference", "--out", "rep"
    )
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    rows = pd.read_csv(plugins / "rep" / "results.csv")
    for engine, how in said.items():
        mine = rows[rows["engine"] == engine]
        assert len(mine) and (mine["status"] == "crashed").all(), mine
        assert mine["message"].str.contains(how, regex=False).all(), mine["message"].tolist()
    assert (rows.loc[rows["engine"] == "reference", "status"] == "ok").all()


def test_a_plugin_whose_prepare_ends_its_process_is_let_go_and_its_runs_go_on(plugins):
    """A plugin's ``prepare`` runs in a forked process first, and in truestep's own (whose
    forked runs inherit what it loaded) only where that process lived through it; one that
    ends it is let go, as one that raises is, and the runs prepare in their own processes
    (here they need nothing: the reference's rows). Before, exit 3 and no report."""
    proc = _start(plugins, *RUN, "--engines", "exits_in_prepare:X,reference", "--out", "rep")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    rows = pd.read_csv(plugins / "rep" / "results.csv")
    mine = rows[rows["engine"] == "exits-in-prepare"]
    assert len(mine) and (mine["status"] == "ok").all(), mine[["method", "status", "message"]]


def test_a_plugin_whose_prepare_ends_its_process_on_a_later_call_is_let_go_too(plugins):
    """Issue 37, item 5: a plugin's ``prepare`` runs in a forked process only, never in
    truestep's own, so one that lives through its first call and ends its process on a
    later one (here: once a file it wrote is there) ends that forked process alone; the
    run goes on and every row is ``ok``. Before, the first call was a forked probe and the
    second ran in truestep's process: exit 3 and no report."""
    proc = _start(plugins, *RUN, "--engines", "exits_in_a_later_prepare:X,reference", "--out", "rep")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert (plugins / "prepared-once").exists()
    rows = pd.read_csv(plugins / "rep" / "results.csv")
    mine = rows[rows["engine"] == "exits-in-a-later-prepare"]
    assert len(mine) and (mine["status"] == "ok").all(), mine[["method", "status", "message"]]


def test_a_plugin_whose_adapter_ends_its_process_when_made_is_one_line(plugins):
    """Issue 37, item 5: an adapter of another package is made first in a forked process
    (as its module is first imported in one): one whose ``__init__`` ends that process is
    exit 2 with one line naming it, nothing written. Before, the command's process ended:
    exit 3, with a line that named no plugin."""
    proc = _start(plugins, *RUN, "--engines", "exits_when_made:X,reference", "--out", "rep")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 2, err
    (line,) = _lines(err)
    assert line == (
        "truestep: error: engine 'exits-when-made': making its adapter exits_when_made.X ended "
        "the process it was first tried in (exit status 0)"
    ), err
    assert "Traceback" not in err and not (plugins / "rep").exists()


def test_sys_exit_at_import_or_in_a_call_is_one_line(plugins):
    proc = _start(plugins, *RUN, "--engines", "exits_at_import:X", "--out", "rep")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 2 and "importing exits_at_import called sys.exit(0)" in err, err
    # a property read in the forked process that makes the adapter's view (issue 37, item 5)
    proc = _start(plugins, *RUN, "--engines", "sys_exit_in_methods:X", "--out", "rep")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 2, err
    (line,) = _lines(err)
    assert line == (
        "truestep: error: engine 'sys-exit-in-methods': reading its adapter sys_exit_in_methods.X's "
        "methods called sys.exit(0)"
    ), err
    assert "Traceback" not in err and not (plugins / "rep").exists()
    # in a call whose answer makes rows, the rows say so and the run goes on
    proc = _start(plugins, *RUN, "--engines", "sys_exit_in_missing:X,reference", "--out", "rep")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    rows = (plugins / "rep" / "results.csv").read_text()
    assert "sys-exit-in-missing: missing() raised SystemExit: 0" in rows


KILLERS = {
    "os_exit_at_import": "ended the process it was first tried in (exit status 0)",
    "crashes_at_import": "ended the process it was first tried in (killed by SIGSEGV)",
    "interrupts_at_import": "interrupted its own process (SIGINT)",
}
"""A plugin module whose import ends its process, and how truestep says so."""


def test_a_plugin_whose_import_ends_its_process_is_left_out_and_the_command_goes_on(plugins):
    """Issue 37, item 5: another package's module is imported first in a forked process;
    one whose import ends or interrupts that process is an engine left out, in one line,
    and truestep's process goes on: ``list`` lists every engine, naming those; a run that
    names one is exit 2 with that line, never exit 0 without a report or 130."""
    info = plugins / "killers-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: killers\nVersion: 1.0\n")
    entries = "".join(f"{name.replace('_', '-')} = {name}:X\n" for name in KILLERS)
    (info / "entry_points.txt").write_text(f"[truestep.adapters]\n{entries}")
    proc = _start(plugins, "list")
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    for name, said in KILLERS.items():
        line = next(x for x in out.splitlines() if x.strip().startswith(name.replace("_", "-")))
        assert f"importing {name} {said}" in line, out
    assert "reference" in out and "Traceback" not in err
    for name, said in KILLERS.items():
        proc = _start(plugins, *RUN, "--engines", f"{name}:X,reference", "--out", "rep")
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 2, err
        (line,) = _lines(err)
        assert f"importing {name} {said}" in line and "Traceback" not in err
        assert not (plugins / "rep").exists()


def test_a_plugin_cannot_take_the_signals_the_directory_or_standard_output(plugins):
    proc = _start(plugins, *RUN, "--engines", "rude_at_import:X", "--out", "rep")
    _wait_for(plugins / "started")
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, err
    (line,) = _lines(err)
    assert "interrupted by SIGTERM" in line
    assert "PRINTED-AT-IMPORT" in err and "PRINTED-AT-IMPORT" not in out
    assert (plugins / ".rep.partial").is_dir()  # the journal beside --out, not under /


def test_a_plugin_cannot_block_sigterm_at_import(plugins):
    """A plugin module that blocks SIGTERM (its signal mask) while it is imported: the
    mask is put back after the import, as its handlers are, and SIGTERM stops the run at
    once, with its line. Before, it was held back until the supervisor's grace ended."""
    proc = _start(plugins, *RUN, "--engines", "blocks_term_at_import:X", "--out", "rep", grace=60)
    _wait_for_file(plugins / "started")
    began = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "interrupted by SIGTERM" in _lines(err)[-1]
    assert time.monotonic() - began < 30


def test_a_worker_stuck_in_compiled_code_is_killed_after_the_grace_with_what_it_started(plugins):
    """The supervisor's backstop: a worker in which no signal handler can run (a plugin's
    import in compiled code that never returns to Python) is killed when the grace ends,
    with every process it started, and the command says so."""
    proc = _start(plugins, *RUN, "--engines", "stuck_in_compiled_code:X", "--out", "rep", grace=2)
    helper = _wait_for(plugins / "helper.pid")
    began = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "had not stopped 2 s later" in _lines(err)[-1]
    assert time.monotonic() - began < 30
    assert still_running([helper]) == []


def test_a_plugin_s_adapter_is_made_and_read_only_in_forked_processes(plugins):
    """Issue 37, item 5: truestep's process holds only data of a plugin's adapter, read in
    a forked process (a view); its construction and its properties run in forked
    processes only, never in truestep's own, through a whole run with its stability
    searches. The plugin here ends any process that is not an isolated child and leaves a
    file saying so: before, every later ``get_adapter`` made it in truestep's process, and
    a construction or a property that ended that process ended the command (exit 3)."""
    proc = _start(
        plugins,
        "run",
        "--quick",
        "--cases",
        "free-fall,harmonic-oscillator",
        "--engines",
        "made_and_read_only_apart:X,reference",
        "--out",
        "rep",
    )
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert sorted(p.read_text() for p in plugins.glob("outside-*")) == []
    rows = pd.read_csv(plugins / "rep" / "results.csv")
    mine = rows[rows["engine"] == "made-and-read-only-apart"]
    assert set(mine["method"]) == {"rk4", "euler"} and (mine["status"] == "ok").all(), mine
    limits = pd.read_csv(plugins / "rep" / "stability.csv")
    assert (limits["engine"] == "made-and-read-only-apart").any(), limits


def test_a_daemon_started_when_the_adapter_is_made_does_not_outlive_the_run(plugins):
    proc = _start(plugins, *RUN, "--engines", "daemon_at_construction:X", "--out", "rep")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert still_running([int((plugins / "daemon.pid").read_text())]) == []


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGHUP])
def test_sigkill_or_sighup_of_the_command_leaves_no_process_of_its_run(plugins, sig):
    proc = _start(plugins, *RUN, "--engines", "helper_then_sleep:X", "--out", "rep")
    helper = _wait_for(plugins / "helper.pid")
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert still_running([helper], 10.0) == []
    if sig == signal.SIGHUP:
        assert proc.returncode == 128 + sig and "interrupted by SIGHUP" in _lines(err)[-1], err
    else:
        assert proc.returncode == -sig


def test_code_after_a_call_of_the_entry_point_runs_once(tmp_path):
    """``truestep.command.main`` called from a script: the worker exits when the command
    is done, and only the supervisor returns to the script."""
    script = (
        "from truestep import command\n"
        "code = command.main(['list', '--cases', 'free-fall', '--engines', 'reference'])\n"
        "print('AFTER', code)\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines().count("AFTER 0") == 1, done.stdout
