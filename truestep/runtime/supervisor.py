"""The ``truestep`` command as two processes: a small supervisor that runs no plugin code,
and the worker it forks, which runs the command.

An adapter, a case library or an exact solution is code truestep did not write, and some
of it runs in the command's own process (imports, ``missing()``, ``prepare()``). Code
there can end that process (``os._exit(0)``: exit status 0, no report and no line), leave
processes behind (a daemon double-forked from ``prepare()``), or ignore the signals that
stop a run. The supervisor (:func:`supervised`) is what the user's shell or CI waits on:

- the worker tells it, through a pipe, the exit code it is about to return; a worker that
  ends without saying one did not finish, and the supervisor says so in one line on
  standard error and exits :data:`DID_NOT_FINISH` (or 128 + the signal that ended it);
- SIGTERM, SIGINT and SIGHUP sent to the command are passed on to the worker, which stops
  as it always has (the children killed, the previous report kept, one line); a worker
  still running :data:`GRACE_S` seconds later is killed with everything below it;
- the supervisor adopts every orphaned process below it (``PR_SET_CHILD_SUBREAPER``) and
  kills what is left once the worker has ended;
- the worker is sent SIGTERM if the supervisor dies, even by SIGKILL
  (``PR_SET_PDEATHSIG``), and stops as above, taking the processes it started with it.

The supervisor forks before truestep imports numpy or any engine, so it holds little.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import os
import signal
import sys
from collections.abc import Callable
from typing import NoReturn

from truestep.runtime.oscalls import become_subreaper, die_with_parent
from truestep.runtime.process_tree import kill_tree, reap_children

DID_NOT_FINISH = 3
"""The exit code of a command whose process ended before it finished, without a signal
(code it ran called ``os._exit``, say)."""
GRACE_ENV = "TRUESTEP_STOP_GRACE_S"
"""The environment variable that sets :data:`GRACE_S` (whole seconds, at least 1)."""


def _grace_s() -> int:
    try:
        return max(1, int(os.environ.get(GRACE_ENV, "30")))
    except ValueError:
        return 30


GRACE_S = _grace_s()
"""Seconds a worker has to stop after a signal is passed on to it, before it and every
process below it are killed (30 unless :data:`GRACE_ENV` says)."""
FORWARDED = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
"""The signals the supervisor passes on to the worker."""


def supervised(work: Callable[[], int]) -> int:
    """``work()`` in a forked worker process, watched as the module docstring says; the
    exit code the command ends with, returned in the supervisor only (the worker exits
    with ``work()``'s code once it has told the supervisor, so that code after a call of
    the command's entry point runs once). Where the system cannot fork, ``work()`` here."""
    if not hasattr(os, "fork"):
        return work()
    read, write = os.pipe()
    become_subreaper()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    parent = os.getpid()
    pid = os.fork()
    if pid == 0:
        os.close(read)
        return _work(work, write, parent)
    os.close(write)
    return _supervise(pid, read)


def _work(work: Callable[[], int], write: int, parent: int) -> NoReturn:
    """In the worker: run ``work``, say its exit code on ``write`` (1 for an exception,
    whose traceback Python then prints as usual) and exit with it."""
    die_with_parent(parent, signal.SIGTERM)
    try:
        code = work()
    except SystemExit as err:  # argparse's --help, --version and usage errors
        _say_code(write, _exit_code(err.code))
        raise
    except KeyboardInterrupt:
        _say_code(write, 128 + signal.SIGINT)
        raise
    except BaseException:
        _say_code(write, 1)
        raise
    _say_code(write, code)
    _exit_at_once(code)  # the worker ends here: only the supervisor returns to the caller


def _exit_at_once(code: int) -> NoReturn:
    """End the worker as Python would, less the teardown of its objects: the exit
    handlers run and every buffered stream (Python's and C's) is flushed, then the process
    exits without freeing what it holds. Freeing a process that holds every engine, their
    scenes and a run's tables one object at a time held up the exit of a quick run
    that had written its report (mypy's ``hard_exit`` does the same for the same reason)."""
    with contextlib.suppress(Exception):
        atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    with contextlib.suppress(Exception):  # an engine's C stdio buffers
        ctypes.CDLL(None).fflush(None)
    os._exit(code)


def _say_code(write: int, code: int) -> None:
    with contextlib.suppress(OSError):
        os.write(write, b"%d\n" % code)
    with contextlib.suppress(OSError):
        os.close(write)


def _exit_code(code: object) -> int:
    """The exit status ``sys.exit(code)`` gives."""
    if code is None:
        return 0
    return code if isinstance(code, int) else 1


def _supervise(pid: int, read: int) -> int:
    """In the supervisor: pass signals on, wait for the worker, clean up, and decide."""
    fired: list[int] = []
    gave_up: list[bool] = []

    def forward(signum: int, _frame: object) -> None:
        if not fired:
            fired.append(signum)
            signal.alarm(GRACE_S)
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signum)

    def give_up(_signum: int, _frame: object) -> None:
        gave_up.append(True)
        kill_tree(pid)
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)

    for sig in FORWARDED:
        signal.signal(sig, forward)
    signal.signal(signal.SIGALRM, give_up)
    _, status = os.waitpid(pid, 0)
    signal.alarm(0)
    said = _read_all(read)
    kill_tree(os.getpid())  # what the worker left: adopted by this process, a subreaper
    reap_children()
    if said:
        return int(said.split()[-1])
    return _unfinished(status, fired[0] if fired else None, gave_up=bool(gave_up))


def _read_all(fd: int) -> bytes:
    """What the worker wrote before it ended, without waiting for more: a process it forked
    (a daemon) may still hold the pipe's other end."""
    os.set_blocking(fd, False)
    chunks = []
    with contextlib.suppress(OSError):
        while chunk := os.read(fd, 4096):
            chunks.append(chunk)
    os.close(fd)
    return b"".join(chunks).strip()


def _unfinished(status: int, passed_on: int | None, *, gave_up: bool) -> int:
    """The line and exit code of a worker that ended without saying its code;
    ``passed_on``: the first signal passed on to it, if any; ``gave_up``: whether the
    supervisor then killed it."""
    if passed_on is not None and gave_up:
        _say(
            f"truestep: interrupted by {signal.Signals(passed_on).name}: the command had not "
            f"stopped {GRACE_S} s later, and was killed with every process it started"
        )
        return 128 + passed_on
    if passed_on is not None and os.WIFSIGNALED(status) and os.WTERMSIG(status) == passed_on:
        _say(
            f"truestep: interrupted by {signal.Signals(passed_on).name}"
        )  # a command without a line of its own
        return 128 + passed_on
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        _say(
            f"truestep: error: the command's process was ended by {signal.Signals(sig).name} "
            "before it finished (a crash in an engine's or a plugin's compiled code, or a "
            "kill from outside)"
        )
        return 128 + sig
    code = os.WEXITSTATUS(status)
    _say(
        f"truestep: error: the command's process exited with status {code} before it "
        "finished: code it ran ended it (an adapter, a case library or an exact solution "
        "calling os._exit, say); nothing it did not finish was published"
    )
    return DID_NOT_FINISH


def _say(line: str) -> None:
    with contextlib.suppress(Exception):
        print(line, file=sys.stderr, flush=True)
