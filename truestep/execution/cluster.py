"""Sweeps on a Dask cluster (``truestep run --scheduler ADDRESS|local:N``).

Dask's distributed scheduler spreads the work; truestep grows no scheduler of its own.
What it adds is what keeps the numbers honest:

- **One task per case, engine and method sweep.** The task runs :func:`truestep.execution.runner.run_sweep`
  on a worker exactly as a local run does (each sweep in its own forked process, each
  step again alone if that process dies), and returns the rows and energy traces.
- **One timed run per host at a time.** A sweep holds a per-host
  :class:`distributed.Semaphore` with one lease (``truestep-timed-<host>``) while it
  runs, so two timed runs never share a machine, however many workers (and threads) run
  there. This is chosen over worker resources because it holds for workers started in
  any way (``dask worker`` with any ``--nworkers`` / ``--nthreads``): resources would
  need exactly one worker per host to be started with them, which nothing checks.
- **A case's sweeps on one host.** Every sweep of a case is pinned to the workers of one
  host (hosts taken in turn, case by case; a sweep may move elsewhere only if that host
  is lost), so the ratios a case's gates read (a speed-up of one engine over another)
  compare rows timed on the same machine. Every row records its ``host``.
- **Untimed work on every worker.** Stability searches and bounce drops
  (:func:`truestep.runtime.isolation.run_untimed`) go to every worker, with no semaphore.
- **Faults.** A worker lost mid-task (killed, a crashed engine that takes the worker
  down, out of memory) has its tasks run again elsewhere by the scheduler; each sweep's
  rows come back exactly once. A sweep that kills workers
  ``distributed.scheduler.allowed-failures`` times over ends as ``crashed`` rows, as a
  process that dies does locally. A scheduler that goes away ends the run with one
  :class:`ClusterError`; the finished sweeps are already in the run's journal, so
  ``truestep run --resume`` continues from them.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import threading
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from truestep.execution.sweep_job import SweepJob, host_name
from truestep.runtime.isolation import Call, Outcome

KILL_WORKER = "TRUESTEP_KILL_WORKER"
"""Fault injection for tests: ``CASE/ENGINE/METHOD:N:DIR`` makes the first ``N`` workers
that start that sweep die at once (``os._exit``), counted by files in ``DIR``."""
LOCAL_PREFIX = "local:"
SEMAPHORE_PREFIX = "truestep-timed-"
CONNECT_TIMEOUT_S = 20.0
CONNECT_MARGIN_S = 5.0
"""Seconds past :data:`CONNECT_TIMEOUT_S` that a scheduler's first answer may take."""
"""How long to wait for a scheduler to answer, s."""


class ClusterError(Exception):
    """The cluster cannot be reached or went away; ``str()`` is one line for the CLI."""

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(message.split()))


_PRELOADED: list[bool] = [False]


def _allow_children() -> None:
    """Let a worker process fork the children every run is isolated in.

    Dask's worker processes are daemonic (``distributed.worker.daemon``), and
    :mod:`multiprocessing` refuses to start children from a daemonic process. The
    children truestep starts die with their parent (``PR_SET_PDEATHSIG`` in
    :mod:`truestep.runtime.isolation`) and are always joined, which is what the refusal guards.
    """
    process = mp.current_process()
    if process.daemon:
        # the refusal, lifted (see above); _config is multiprocessing's own, untyped
        process._config["daemon"] = False  # type: ignore[attr-defined]


def sweep_task(job: SweepJob) -> tuple[int, list[dict], dict, str]:
    """Run one sweep on this worker, holding this host's timed-run semaphore.

    Returns ``(index, rows, traces, host)``; every row carries ``host``.
    """
    from distributed import Semaphore

    from truestep.execution.runner import run_sweep

    _allow_children()
    _maybe_die(job)
    _prepare_worker()
    host = host_name()
    traces: dict = {}
    with Semaphore(max_leases=1, name=SEMAPHORE_PREFIX + host):
        rows = run_sweep(
            job.case,
            job.engine,
            job.method,
            job.dts,
            adaptive=job.adaptive,
            timing=job.timing,
            traces=traces if job.want_traces else None,
        )
    for row in rows:
        row["host"] = host
    return job.index, rows, traces, host


def _maybe_die(job: SweepJob) -> None:
    """Die here, as a worker killed mid-task would, if :data:`KILL_WORKER` says so."""
    spec = os.environ.get(KILL_WORKER)
    if not spec:
        return
    target, times, folder = spec.split(":", 2)
    if target != f"{job.case.name}/{job.engine}/{job.method}":
        return
    deaths = Path(folder)
    if len(list(deaths.glob("death-*"))) < int(times):
        (deaths / f"death-{os.getpid()}").touch()
        os._exit(1)


def worker_numerics() -> dict:
    """This worker's floating-point environment, with its threads pinned as a task's are
    (:func:`truestep.numerics.fingerprint`)."""
    from truestep.numerics import fingerprint, pin_threads

    pin_threads()
    return fingerprint()


def untimed_task(call: Call) -> Outcome:
    """One untimed isolated call (a stability search, a bounce drop) on this worker."""
    from truestep.runtime.isolation import run_isolated_all

    _allow_children()
    _prepare_worker()
    return run_isolated_all([call])[0]


def _prepare_worker() -> None:
    """Once a worker: every BLAS and OpenMP runtime held to one thread for the worker's
    life (it runs truestep's tasks; :func:`truestep.numerics.pin_threads`) and what every
    forked run needs loaded (:func:`truestep.execution.runner.preload`)."""
    from truestep.execution.runner import preload
    from truestep.numerics import pin_threads

    if not _PRELOADED[0]:
        pin_threads()
        preload()
        _PRELOADED[0] = True


def _client_within(client: Callable[..., Any], address: str, seconds: float) -> Any:
    """``client(address)`` made in a thread of its own, and given up on after ``seconds``
    plus a margin: Dask's own ``timeout`` covers the TCP connection, not the scheduler's
    first answer, and a server that accepts and never answers holds ``Client`` forever."""
    made: list[Any] = []
    failed: list[BaseException] = []

    def connect() -> None:
        try:
            made.append(client(address, timeout=seconds))
        except BaseException as err:  # handed to the caller's thread
            failed.append(err)

    thread = threading.Thread(target=connect, name="truestep-connect", daemon=True)
    thread.start()
    thread.join(seconds + CONNECT_MARGIN_S)
    if failed:
        raise failed[0]
    if not made:
        raise ClusterError(
            f"--scheduler {address}: no answer within {seconds + CONNECT_MARGIN_S:g} s "
            "(something accepts connections there, but no Dask scheduler answers)"
        )
    return made[0]


class Cluster:
    """A connection to a Dask scheduler (or a :class:`~distributed.LocalCluster` of
    ``N`` single-threaded worker processes for ``local:N``) that runs sweeps and untimed
    calls. Use as a context manager; :meth:`close` shuts a local cluster down."""

    def __init__(self, address: str) -> None:
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise ClusterError(
                "--scheduler needs Dask's distributed scheduler: pip install 'truestep[dask]'"
            ) from None
        self.address = address
        self._local = None
        _quiet_distributed_logs()
        try:
            if address.startswith(LOCAL_PREFIX):
                n = _workers(address)
                self._local = LocalCluster(
                    n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=50
                )
                self.client = Client(self._local, timeout=CONNECT_TIMEOUT_S)
            else:
                self.client = _client_within(Client, address, CONNECT_TIMEOUT_S)
        except ClusterError:
            raise
        except Exception as err:  # any failure to connect is the one error
            self.close()
            raise ClusterError(
                f"--scheduler {address}: cannot connect: {type(err).__name__}: {str(err)[:160]}"
            ) from None
        try:
            self._check_numerics()
        except BaseException:
            self.close()
            raise

    def _check_numerics(self) -> None:
        """Refuse workers whose floating-point environment differs from this machine's
        (:func:`truestep.numerics.fingerprint`): their rows would not be the rows a local
        run gives. The message names the first such worker and what differs."""
        from truestep.numerics import differences, fingerprint, pin_threads

        pin_threads()
        here = fingerprint()
        try:
            theirs = self.client.run(worker_numerics)
        except Exception as err:  # a worker that cannot answer is a connection failure
            raise ClusterError(
                f"--scheduler {self.address}: cannot ask the workers for their "
                f"numerics: {type(err).__name__}: {str(err)[:120]}"
            ) from None
        for worker, fp in sorted(theirs.items()):
            diff = differences(here, fp)
            if diff:
                raise ClusterError(
                    f"--scheduler {self.address}: worker {worker} would not give this "
                    f"machine's numbers ({'; '.join(diff)[:200]}); install the same packages "
                    'there and start its workers after `eval "$(truestep env)"`'
                )

    def __enter__(self) -> Cluster:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the client (and a local cluster)."""
        client = getattr(self, "client", None)
        for thing in (client, self._local):
            if thing is not None:
                try:
                    thing.close()
                except Exception:  # closing what may already be gone
                    pass

    def hosts(self) -> list[str]:
        """The hosts the workers run on, as the scheduler names them (the host part of
        their addresses), in order. A task restricted to a host may run on any worker
        there, a worker restarted after a crash included (its port is new, its host not)."""
        hosts = {_host_of(address) for address in self.client.scheduler_info()["workers"]}
        return sorted(hosts)

    def sweeps(self, jobs: Sequence[SweepJob]) -> Iterator[tuple[int, list[dict], dict]]:
        """Run every job as a task; yield ``(index, rows, traces)`` as each finishes.

        The cases are dealt to the hosts in turn, and each host is given one sweep at a
        time, the next when it finishes: a host times one run at a time anyway, and a
        sweep that waits on no worker is not taken down with a worker that dies (dask
        counts every task on a dying worker towards its ``allowed-failures``). A task the
        scheduler gave up on (it killed workers again and again) yields ``crashed`` rows
        for each of its steps; a lost scheduler raises :class:`ClusterError`.
        """
        from distributed import as_completed

        try:
            hosts = self.hosts()
            if not hosts:
                raise ClusterError(f"--scheduler {self.address}: no workers")
            by_case: dict[str, str] = {}
            queues: dict[str, list[SweepJob]] = {h: [] for h in hosts}
            for job in jobs:
                host = by_case.setdefault(job.case.name, hosts[len(by_case) % len(hosts)])
                queues[host].append(job)
            for queue in queues.values():
                queue.reverse()  # popped from the end: in plan order
            running: dict = {}

            def submit(host: str):
                job = queues[host].pop()
                future = self.client.submit(
                    sweep_task,
                    job,
                    key=f"sweep-{job.index}-{job.case.name}-{job.engine}-{job.method}",
                    workers=[host],
                    allow_other_workers=True,
                    pure=False,
                )
                running[future] = (job, host)
                return future

            pending = as_completed([submit(h) for h in hosts if queues[h]])
            for future in pending:
                job, host = running.pop(future)
                if queues[host]:
                    pending.add(submit(host))
                try:
                    index, rows, traces, _ = future.result()
                except Exception as err:  # the task failed, not the run
                    if _scheduler_gone(err):
                        raise
                    yield job.index, _crashed_rows(job, err), {}
                    continue
                finally:
                    future.release()
                yield index, rows, traces
        except ClusterError:
            raise
        except Exception as err:  # the scheduler went away mid-run
            raise ClusterError(
                f"--scheduler {self.address}: lost the scheduler: {type(err).__name__}: {str(err)[:120]}"
            ) from None

    def untimed(self, calls: Sequence[Call], done: Callable[[int, Outcome], None] | None) -> list[Outcome]:
        """Every call as a task on any worker; outcomes in the order of ``calls``."""
        from distributed import as_completed

        outcomes: list[Outcome | None] = [None] * len(calls)
        try:
            futures = {self.client.submit(untimed_task, call, pure=False): k for k, call in enumerate(calls)}
            for future in as_completed(futures):
                k = futures[future]
                try:
                    outcome = future.result()
                except Exception as err:  # the task failed, not the run
                    if _scheduler_gone(err):
                        raise
                    outcome = Outcome("crashed", message=_killed(err))
                outcomes[k] = outcome
                if done is not None:
                    done(k, outcome)
        except Exception as err:  # the scheduler went away mid-run
            raise ClusterError(
                f"--scheduler {self.address}: lost the scheduler: {type(err).__name__}: {str(err)[:120]}"
            ) from None
        return outcomes  # type: ignore[return-value]


def _quiet_distributed_logs() -> None:
    """Silence Dask's own loggers for the rest of the process: their reconnect attempts
    and shutdown messages (with tracebacks, some logged from the client's event loop after
    it is closed) would bury the run's one line about a lost scheduler or worker, and
    truestep says what happened itself."""
    names = [n for n in logging.root.manager.loggerDict if n.split(".")[0] in ("distributed", "tornado")]
    for name in ["distributed", "tornado", *names]:
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def _host_of(address: str) -> str:
    """``"tcp://10.0.0.5:40123"`` -> ``"10.0.0.5"`` (IPv6 brackets kept off)."""
    rest = address.split("://", 1)[-1]
    return rest.rsplit(":", 1)[0].strip("[]")


def _workers(address: str) -> int:
    raw = address[len(LOCAL_PREFIX) :]
    if not raw.isdigit() or not 1 <= int(raw) <= 256:
        raise ClusterError(
            f"--scheduler: expected tcp://HOST:PORT or local:N (N from 1 to 256), got {address[:60]!r}"
        )
    return int(raw)


def _scheduler_gone(err: BaseException) -> bool:
    from distributed.client import FutureCancelledError
    from distributed.comm.core import CommClosedError

    return isinstance(err, CommClosedError | FutureCancelledError | OSError | TimeoutError)


def _killed(err: BaseException) -> str:
    from distributed.scheduler import KilledWorker

    if isinstance(err, KilledWorker):
        return (
            f"the task's worker died each time it ran (distributed's allowed-failures "
            f"reached): {str(err)[:120]}"
        )
    return f"{type(err).__name__}: {str(err)[:160]}"


def _crashed_rows(job: SweepJob, err: BaseException) -> list[dict]:
    return [
        {
            "case": job.case.name,
            "engine": job.engine,
            "method": job.method,
            "dt": dt,
            "dt_kind": "tolerance" if job.adaptive else "step",
            "status": "crashed",
            "message": _killed(err),
            "host": "",
        }
        for dt in job.dts
    ]
