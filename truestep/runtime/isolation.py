"""Run simulations in child processes, so a crash or a hang becomes a row.

Each call forks a fresh process (engine parameters cannot leak from one run into the
next, as pybullet's would between clients of one process), waits at most its timeout and
reports what happened. :func:`run_isolated` runs one child at a time: timed runs never
share the CPU with other runs of the harness. :func:`run_isolated_all` keeps up to
``workers`` children busy at once, for work whose wall time is not measured (stability
searches, bounce tests).

No child outlives its parent: each one asks the kernel for SIGKILL when its parent dies
(Linux, :func:`truestep.runtime.oscalls.die_with_parent`), ignores SIGINT (the parent decides)
and takes SIGTERM by default; the parent kills the live ones when it is interrupted
(:func:`kill_children`, :mod:`truestep.runtime.interrupts`).

What runs in a child is contained: the child leads a process group of its own and
adopts every orphaned process below it (:func:`truestep.runtime.oscalls.become_subreaper`), and
whatever the adapter started there (helpers, a daemon that left the group with
``setsid``) is killed when the call ends, after a normal finish, a crash, a timeout or
an interruption (:func:`truestep.runtime.process_tree.kill_tree`). Its standard output and error
(the file descriptors, so its own subprocesses' too) go to a pipe whose last
:data:`OUTPUT_TAIL` bytes come back in :attr:`Outcome.output`, never to truestep's own
output; standard input is ``/dev/null``. Its result comes back as data
(:func:`truestep.runtime.plain_data.loads`): arrays, plain values and truestep's own
records, never an object that runs code of its own while it is read here.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import functools
import gc
import itertools
import multiprocessing as mp
import os
import re
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from multiprocessing.connection import wait
from typing import Any, Protocol

from truestep.runtime import faults, plain_data
from truestep.runtime.oscalls import become_subreaper, die_with_parent
from truestep.runtime.process_tree import has_children, kill_group, kill_tree, reap_children


@dataclass
class Outcome:
    """What became of an isolated call: ``ok`` with its value, or why not; ``output``:
    the end of what it wrote to its standard output and error."""

    status: str  # ok | crashed | timeout
    value: Any = None
    message: str = ""
    output: str = ""
    seconds: float = 0.0
    """Wall time (s) from the child's fork to its end (its result read, its death seen or
    its time up); 0 for a call never started. Not the time its outcome was handed on: an
    untimed outcome may wait for a gap between timed calls (:class:`Lanes`)."""


OUTPUT_TAIL = 4000
"""The bytes of a child's standard output and error kept (its last ones)."""
PIPE_BYTES = 2**20
"""The capture pipe's buffer: what an engine's C code may write in one call while it
holds the interpreter lock, before the thread that drains the pipe can run."""


Call = tuple[Callable[..., Any], tuple, float]
"""``(fn, args, timeout_s)``: one isolated call."""


class Backlog(Protocol):
    """Untimed isolated calls that may run whenever a core is free: ``len`` of them, the
    ``k``-th made by ``call(k)`` just before it starts and handed to ``done(k, outcome)``
    when it ends (:class:`truestep.execution.analyses.UntimedPart`)."""

    def __len__(self) -> int: ...

    def call(self, k: int) -> Call: ...

    def done(self, k: int, out: Outcome) -> None: ...


_RUN_DEADLINE: list[float | None] = [None]
"""When the whole run's budget ends (``time.monotonic()``), if it has one."""
BUDGET_SPENT = "the run's budget (truestep run --budget) was spent before this finished"


def set_run_budget(seconds: float | None) -> None:
    """Give every isolated call from now on at most ``seconds`` (s) in all, counted from
    now (``None``: no run-wide budget). A call that would outlast it is cut at the end
    of the budget, and calls after it are not started: both are ``timeout`` outcomes that
    say so."""
    _RUN_DEADLINE[0] = None if seconds is None else time.monotonic() + seconds


def _budget_left() -> float:
    end = _RUN_DEADLINE[0]
    return float("inf") if end is None else end - time.monotonic()


_LIVE: dict[int, Any] = {}
"""The children started by this process and not yet joined, by pid."""


class _Capture:
    """Standard output and error of this process (file descriptors 1 and 2) into a pipe
    drained by a thread that keeps the last :data:`OUTPUT_TAIL` bytes; standard input
    from ``/dev/null``."""

    def __init__(self) -> None:
        read, write = os.pipe()  # text buffered before the fork is flushed into it too
        with contextlib.suppress(OSError, AttributeError):  # room for a chatty C library
            fcntl.fcntl(write, fcntl.F_SETPIPE_SZ, PIPE_BYTES)
        self.saved = (os.dup(1), os.dup(2))
        os.dup2(write, 1)
        os.dup2(write, 2)
        os.close(write)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.close(null)
        self.streams = (sys.stdout, sys.stderr)  # maybe not on fds 1 and 2 (pytest's)
        sys.stdout = open(1, "w", buffering=1, closefd=False, errors="backslashreplace")
        sys.stderr = open(2, "w", buffering=1, closefd=False, errors="backslashreplace")
        self.tail = bytearray()
        self.thread = threading.Thread(target=self._drain, args=(read,), daemon=True)
        self.thread.start()

    def _drain(self, fd: int) -> None:
        try:
            while chunk := os.read(fd, 65536):
                self.tail += chunk
                del self.tail[:-OUTPUT_TAIL]
        except OSError:
            pass
        finally:
            os.close(fd)

    def stop(self) -> str:
        """Put standard output and error back, kill what is left below this process
        (its copies of the pipe), and return what was written."""
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        with contextlib.suppress(OSError, AttributeError):  # C stdio's buffers too
            ctypes.CDLL(None).fflush(None)
        sys.stdout, sys.stderr = self.streams
        os.dup2(self.saved[0], 1)
        os.dup2(self.saved[1], 2)
        for fd in self.saved:
            os.close(fd)
        _kill_below()
        self.thread.join(timeout=2.0)
        return bytes(self.tail).decode("utf-8", "replace")


def _kill_below() -> None:
    """Kill every process below this one, and this process group's other members."""
    if has_children():
        kill_tree(os.getpid())
        reap_children()


_IN_CHILD = [False]
"""Whether this process is an isolated child (:func:`in_isolated_child`)."""


def in_isolated_child() -> bool:
    """Whether this process is one truestep forked to make an isolated call (or a process
    below one): where plugin code may run, contained."""
    return _IN_CHILD[0]


def _child(conn, parent: int, fn: Callable[..., Any], args: tuple) -> None:
    _IN_CHILD[0] = True
    gc.freeze()  # what the child inherited: its collector never walks (and copies) those pages
    die_with_parent(parent)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with contextlib.suppress(OSError):
        os.setpgid(0, 0)
    become_subreaper()
    capture = _Capture()
    try:
        reply: tuple = ("ok", fn(*args))
    except BaseException as err:  # everything: the parent turns it into a row
        tb = traceback.extract_tb(err.__traceback__)
        where = f" at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else ""
        reply = ("crashed", f"{type(err).__name__}: {str(err)[:MESSAGE_CHARS]}{where}")
    output = capture.stop()
    try:
        conn.send((*reply, output))
    except Exception as err:  # a value that cannot be pickled: the call's row says so
        conn.send(
            ("crashed", f"its result cannot be sent back: {type(err).__name__}: {str(err)[:200]}", output)
        )
    finally:
        conn.close()


MESSAGE_CHARS = 1000
"""The most characters of an exception's message a crashed row keeps."""


def _end(proc: Any) -> None:
    """Kill a child, everything below it and its process group, and reap it."""
    kill_tree(proc.pid)
    proc.kill()
    proc.join()
    kill_group(proc.pid)


@dataclass
class Running:
    """A call started by :func:`start_isolated`, to be collected by :func:`finish_isolated`."""

    index: int
    proc: Any
    conn: Any
    deadline: float
    timeout: float
    by_budget: bool = False
    started: float = 0.0
    """``time.perf_counter()`` just before the fork."""


def _start(index: int, call: Call) -> Running:
    fn, args, timeout = call
    started = time.perf_counter()
    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(child, os.getpid(), fn, args), daemon=True)
    proc.start()
    pid = proc.pid
    assert pid is not None  # a started process has one
    with contextlib.suppress(OSError):  # as the child does: no moment outside its group
        os.setpgid(pid, pid)
    _LIVE[pid] = proc
    faults.note_child(pid)
    child.close()
    left = _budget_left()
    return Running(
        index,
        proc,
        parent,
        time.monotonic() + min(timeout, left),
        timeout,
        by_budget=left < timeout,
        started=started,
    )


_EXITING: list[Any] = []
"""Children whose result is in and who are exiting (:func:`_finish` with ``reap_later``):
reaped by :func:`reap_exited` without waiting for them."""


def reap_exited(*, wait: bool = False) -> None:
    """Reap the children of :data:`_EXITING` that have exited (every one, waiting, with
    ``wait``), and kill what is left in their process groups. A child's exit takes as long
    as its fork (the kernel tears its copy of this process down, some ms for a process
    holding every engine); the parent goes on meanwhile."""
    for proc in list(_EXITING):
        proc.join(None if wait else 0)
        if proc.exitcode is None:
            continue
        _EXITING.remove(proc)
        kill_group(proc.pid)
        _LIVE.pop(proc.pid, None)


def _finish(run: Running, *, timed_out: bool, reap_later: bool = False) -> Outcome:
    out = _outcome(run, timed_out=timed_out, reap_later=reap_later)
    out.seconds = time.perf_counter() - run.started
    return out


def _outcome(run: Running, *, timed_out: bool, reap_later: bool) -> Outcome:
    try:
        if timed_out:
            return Outcome(
                "timeout", message=BUDGET_SPENT if run.by_budget else f"no result within {run.timeout:g} s"
            )
        try:
            data = run.conn.recv_bytes()
        except (EOFError, OSError, ValueError):
            _end(run.proc)
            return Outcome("crashed", message=f"engine process died (exit code {run.proc.exitcode})")
        try:
            status, value, output = plain_data.loads(data)
        except plain_data.Refused as err:
            return Outcome("crashed", message=plain_data.refused_words(err))
        except Exception as err:  # bytes that are no result of _child's: said, not raised
            words = f"its result could not be read: {type(err).__name__}: {err}"
            return Outcome("crashed", message=words[:300])
        return (
            Outcome("ok", value, output=output)
            if status == "ok"
            else Outcome("crashed", message=value, output=output)
        )
    finally:
        run.conn.close()
        if timed_out:
            _end(run.proc)
        if reap_later and not timed_out:
            _EXITING.append(run.proc)
            reap_exited()
        else:
            run.proc.join()
            kill_group(run.proc.pid)
            _LIVE.pop(run.proc.pid, None)


def kill_children() -> None:
    """SIGKILL every child this process started and has not joined yet, with everything
    below it, and reap them."""
    for pid, proc in list(_LIVE.items()):
        if proc._parent_pid == os.getpid():  # not a copy inherited through a fork
            _end(proc)
        _LIVE.pop(pid, None)
    _EXITING.clear()


def run_isolated_all(
    calls: Sequence[Call], workers: int = 1, done: Callable[[int, Outcome], None] | None = None
) -> list[Outcome]:
    """Run every ``fn(*args)`` in its own forked child, at most ``workers`` at a time.

    Returns the outcomes in the order of ``calls``; never raises for what happens inside a
    child. ``done(index, outcome)`` is called as each one finishes.
    """
    outcomes: list[Outcome | None] = [None] * len(calls)
    pending = list(enumerate(calls))[::-1]
    running: list[Running] = []
    try:
        while pending or running:
            while pending and len(running) < max(1, workers):
                if _budget_left() <= 0:  # not started: this call's row says why
                    index, _ = pending.pop()
                    spent = outcomes[index] = Outcome("timeout", message=BUDGET_SPENT)
                    if done is not None:
                        done(index, spent)
                    continue
                running.append(_start(*pending.pop()))
            if not running:
                continue
            now = time.monotonic()
            ready = wait([r.conn for r in running], timeout=max(0.0, min(r.deadline for r in running) - now))
            for r in list(running):
                timed_out = r.conn not in ready and time.monotonic() >= r.deadline
                if r.conn in ready or timed_out:
                    running.remove(r)
                    finished = outcomes[r.index] = _finish(r, timed_out=timed_out, reap_later=True)
                    if done is not None:
                        done(r.index, finished)
    finally:
        for r in running:
            _end(r.proc)
            r.conn.close()
            _LIVE.pop(r.proc.pid, None)
        reap_exited(wait=True)
    return outcomes  # type: ignore[return-value]


def run_lanes(
    timed: Sequence[int],
    untimed: Sequence[int],
    call: Callable[[int], Call],
    done: Callable[[int, Outcome], None],
    cores: int,
) -> None:
    """Run two lanes of isolated calls at once (:meth:`Lanes.run` on ``cores`` cores, with
    no backlog)."""
    with Lanes(cores) as lanes:
        lanes.run(timed, untimed, call, done)


@dataclass
class _Child:
    """A running child of :class:`Lanes`: its run, whether it is timed, and whose it is
    (the index and ``done`` of a :meth:`Lanes.run` call, or a backlog's)."""

    run: Running
    timed: bool
    index: int
    done: Callable[[int, Outcome], None]
    own: bool


class Lanes:
    """Two lanes of isolated calls on ``cores`` cores, and a ``backlog`` of untimed work
    (:class:`Backlog`) that fills the cores they leave, across every :meth:`run` until
    :meth:`finish` runs the rest on all of them. A context manager: leaving it ends the
    children still running. Never raises for what happens inside a child; the run's
    budget holds as in :func:`run_isolated_all`."""

    def __init__(self, cores: int, backlog: Sequence[Backlog] = ()) -> None:
        self.cores = max(1, cores)
        self._backlog = [(b, k) for b in backlog for k in range(len(b))][::-1]
        self._running: dict[int, _Child] = {}
        self._held: list[tuple[_Child, Outcome]] = []  # untimed outcomes waiting for a gap
        self._slots = itertools.count()

    def __enter__(self) -> Lanes:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """End every child still running (a run interrupted, or left unfinished)."""
        for child in self._running.values():
            _end(child.run.proc)
            child.run.conn.close()
            _LIVE.pop(child.run.proc.pid, None)
        self._running.clear()
        reap_exited(wait=True)

    def run(
        self,
        timed: Sequence[int],
        untimed: Sequence[int],
        call: Callable[[int], Call],
        done: Callable[[int, Outcome], None],
    ) -> None:
        """Run the calls ``timed`` and ``untimed``, each made by ``call(j)`` just before its
        child is forked and handed to ``done(j, outcome)`` when it ends; return once all
        are done (backlog children may still run).

        The ``timed`` lane runs one call at a time, in order, and keeps a core to itself: it
        starts only while at most ``cores - 1`` untimed children run. While it runs, this
        process only starts the untimed call that takes the place of one just ended (on the
        core that child left free: the untimed cores never wait for a long timed call) and
        otherwise waits; the untimed outcomes' ``done`` waits for the gap between two timed
        calls. The ``untimed`` lane, then the backlog, keep the other cores busy (all of
        them once the timed lane is done); on one core the untimed lane runs after the
        timed lane."""
        timed_left, untimed_left = list(timed)[::-1], list(untimed)[::-1]

        def own_left() -> bool:
            return bool(timed_left or untimed_left or any(c.own for c in self._running.values()))

        with self._closed_on_error():
            while own_left() or any(c.own for c, _ in self._held):
                self._step(timed_left, untimed_left, call, done)
            self._deliver()

    def finish(self) -> None:
        """Run the rest of the backlog on every core; return once it is all done."""
        with self._closed_on_error():
            while self._backlog or self._running or self._held:
                self._step([], [], _no_call, _no_done)

    def free_core(self) -> None:
        """Wait (collecting what ends, starting nothing) until at most ``cores - 1``
        children run: a core for a timed run made outside the lanes."""
        with self._closed_on_error():
            while len(self._running) > self.cores - 1:
                self._collect(timed_busy=False)
            self._deliver()

    @contextlib.contextmanager
    def _closed_on_error(self) -> Iterator[None]:
        """End every child if the block raises (an interruption, a ``done`` that fails)."""
        try:
            yield
        except BaseException:
            self.close()
            raise

    def _step(
        self,
        timed_left: list[int],
        untimed_left: list[int],
        call: Callable[[int], Call],
        done: Callable[[int, Outcome], None],
    ) -> None:
        """Deliver held outcomes in a gap, start what may start, wait for one to end."""
        timed_busy = any(c.timed for c in self._running.values())
        if not timed_busy:
            self._deliver()
        room = max(0, self.cores - 1) if timed_left or timed_busy else self.cores
        while self._untimed_running() < room and (untimed_left or self._backlog):
            if untimed_left:
                j = untimed_left.pop()
                self._start(j, functools.partial(call, j), done, timed=False, own=True)
            else:
                backlog, k = self._backlog.pop()
                self._start(k, functools.partial(backlog.call, k), backlog.done, timed=False, own=False)
        if not timed_busy and timed_left and len(self._running) <= self.cores - 1:
            j = timed_left.pop()
            self._start(j, functools.partial(call, j), done, timed=True, own=True)
        if self._running:
            self._collect(timed_busy=any(c.timed for c in self._running.values()))

    def _untimed_running(self) -> int:
        return sum(1 for c in self._running.values() if not c.timed)

    def _start(
        self,
        index: int,
        make: Callable[[], Call],
        done: Callable[[int, Outcome], None],
        *,
        timed: bool,
        own: bool,
    ) -> None:
        if _budget_left() <= 0:  # not started: this call's row says why
            done(index, Outcome("timeout", message=BUDGET_SPENT))
            return
        run = _start(index, make())
        self._running[next(self._slots)] = _Child(run, timed, index, done, own)

    def _collect(self, *, timed_busy: bool) -> None:
        """Wait for a child to end (or its time to run out) and hand its outcome on: an
        untimed one's is held while a timed call runs."""
        runs = [c.run for c in self._running.values()]
        now = time.monotonic()
        ready = wait([r.conn for r in runs], timeout=max(0.0, min(r.deadline for r in runs) - now))
        for slot, child in list(self._running.items()):
            r = child.run
            timed_out = r.conn not in ready and time.monotonic() >= r.deadline
            if r.conn in ready or timed_out:
                del self._running[slot]
                finished = _finish(r, timed_out=timed_out, reap_later=True)
                if not child.timed and timed_busy:
                    self._held.append((child, finished))
                else:
                    child.done(child.index, finished)

    def _deliver(self) -> None:
        held, self._held = self._held, []
        for child, outcome in held:
            child.done(child.index, outcome)


def _no_call(j: int) -> Call:
    raise AssertionError(f"no call {j} in this lane")


def _no_done(j: int, out: Outcome) -> None:
    raise AssertionError(f"no call {j} in this lane")


_UNTIMED: list[Any] = [None]
"""The cluster untimed calls go to (:func:`set_untimed_runner`), if any."""


def set_untimed_runner(cluster: Any) -> None:
    """Send the calls of :func:`run_untimed` to ``cluster`` (a
    :class:`truestep.execution.cluster.Cluster`), or back to this machine's cores (``None``)."""
    _UNTIMED[0] = cluster


def run_untimed(
    calls: Sequence[Call], workers: int, done: Callable[[int, Outcome], None] | None = None
) -> list[Outcome]:
    """Work whose wall time is not measured (stability searches, bounce drops): on every
    worker of the cluster set by :func:`set_untimed_runner`, else as
    :func:`run_isolated_all` with ``workers`` children at once."""
    if _UNTIMED[0] is not None:
        return _UNTIMED[0].untimed(calls, done)
    return run_isolated_all(calls, workers, done)


def start_isolated(fn: Callable[..., Any], args: tuple, timeout: float) -> Running:
    """Start ``fn(*args)`` in a forked child and return at once (untimed work only)."""
    return _start(0, (fn, args, timeout))


def finish_isolated(run: Running) -> Outcome:
    """Wait for a started call until its result arrives or its time runs out."""
    ready = wait([run.conn], timeout=max(0.0, run.deadline - time.monotonic()))
    return _finish(run, timed_out=not ready)


def how_it_ended(message: str) -> str:
    """``exit status N`` or ``killed by SIGNAME`` from the message of an isolated call whose
    process ended before it answered (else the message)."""
    found = re.search(r"exit code (-?\d+)", message)
    if found is None:
        return message
    code = int(found.group(1))
    if code >= 0:
        return f"exit status {code}"
    try:
        return f"killed by {signal.Signals(-code).name}"
    except ValueError:
        return f"killed by signal {-code}"


def run_isolated(fn: Callable[..., Any], args: tuple, timeout: float) -> Outcome:
    """Call ``fn(*args)`` in a forked child, alone; never raises for what happens inside it."""
    return run_isolated_all([(fn, args, timeout)])[0]


def untimed_workers() -> int:
    """How many children may run at once for work that is not timed: the usable cores."""
    from truestep.runtime.machine import usable_cores

    return usable_cores()
