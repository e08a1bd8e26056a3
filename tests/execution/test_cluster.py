"""Sweeps on a Dask cluster: the same answers as a local run, every row exactly once
when a worker dies, ``crashed`` rows for a sweep that kills every worker it is given,
and one clear error when the scheduler cannot be reached or goes away.

These start real clusters (a ``LocalCluster`` of two single-threaded worker processes,
and real ``dask scheduler`` / ``dask worker`` processes on 127.0.0.1).
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import distributed  # noqa: F401 - its config defaults must exist before dask.config.set
import pandas as pd
import pytest

from truestep.cli import main
from truestep.execution.cluster import KILL_WORKER
from truestep.execution.runner import MACHINE_COLUMNS
from truestep.runtime.folder import MARKER, MARKER_TEXT

CASES = "free-fall,harmonic-oscillator"
TIMING = set(MACHINE_COLUMNS)
"""The columns a cluster run may differ in: wall times, how often they were taken, where."""


def _run(out: Path, *extra: str) -> int:
    return main(
        ["run", "--quick", "--cases", CASES, "--engines", "reference,pymunk", "--out", str(out), *extra]
    )


def _same_but_timing(a: Path, b: Path) -> None:
    for name in ("results", "stability", "restitution"):
        x, y = pd.read_csv(a / f"{name}.csv"), pd.read_csv(b / f"{name}.csv")
        cols = [c for c in x.columns if c not in TIMING]
        pd.testing.assert_frame_equal(x[cols], y[cols], check_exact=True, obj=name)


@pytest.fixture(autouse=True)
def short_leases():
    """A dead worker's lease on its host's timed-run semaphore ends after 2 s here, not
    the default 30 s (the scheduler of a ``LocalCluster`` runs in this process)."""
    import dask

    with dask.config.set(
        {
            "distributed.scheduler.locks.lease-timeout": "2s",
            "distributed.scheduler.locks.lease-validation-interval": "0.5s",
        }
    ):
        yield


@pytest.fixture(scope="module")
def local_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("local") / "out"
    assert _run(out) == 0
    return out


def test_a_local_cluster_with_a_worker_killed_mid_run_gives_a_local_run_s_tables(
    local_run: Path, tmp_path: Path, monkeypatch
) -> None:
    """Two single-threaded workers; one dies as it starts a sweep. That sweep runs again
    on the other, every row is there exactly once, and every column but the timing ones
    and ``host`` equals the local run's."""
    deaths = tmp_path / "deaths"
    deaths.mkdir()
    monkeypatch.setenv(KILL_WORKER, f"harmonic-oscillator/reference/rk4:1:{deaths}")
    out = tmp_path / "cluster"
    assert _run(out, "--scheduler", "local:2") == 0
    assert len(list(deaths.iterdir())) == 1  # one worker died in that sweep
    results = pd.read_csv(out / "results.csv")
    keys = ["case", "engine", "method", "dt_kind", "dt"]
    assert not results.duplicated(keys).any()
    _same_but_timing(local_run, out)  # the sweep ran again elsewhere, to the same rows
    ran = results[results["status"].isin(["ok", "unstable"])]
    assert ran["host"].notna().all() and set(ran["host"]) == {socket.gethostname()}


def test_a_sweep_that_kills_every_worker_is_crashed_rows(tmp_path: Path, monkeypatch) -> None:
    import dask

    deaths = tmp_path / "deaths"
    deaths.mkdir()
    monkeypatch.setenv(KILL_WORKER, f"free-fall/reference/euler:99:{deaths}")
    out = tmp_path / "cluster"
    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
        assert (
            main(
                [
                    "run",
                    "--quick",
                    "--cases",
                    "free-fall",
                    "--engines",
                    "reference",
                    "--out",
                    str(out),
                    "--scheduler",
                    "local:2",
                ]
            )
            == 0
        )
    results = pd.read_csv(out / "results.csv")
    euler = results[
        (results["case"] == "free-fall") & (results["method"] == "euler") & (results["engine"] == "reference")
    ]
    assert len(euler) == 4 and set(euler["status"]) == {"crashed"}
    assert euler["message"].str.contains("worker died").all()
    others = results[~results.index.isin(euler.index) & results["status"].isin(["ok"])]
    assert len(others) > 20  # every other sweep of the case ran


def test_an_unreachable_scheduler_is_one_line(tmp_path: Path, capsys, monkeypatch) -> None:
    from truestep.execution import cluster

    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 2.0)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # nothing listens here once closed
    assert _run(tmp_path / "out", "--scheduler", f"tcp://127.0.0.1:{port}") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot connect" in err[0]
    assert _run(tmp_path / "out", "--scheduler", "local:zero") == 2
    assert "local:N" in capsys.readouterr().err


def test_a_server_that_accepts_and_never_answers_is_one_line_within_the_limit(
    tmp_path: Path, capsys, monkeypatch
) -> None:
    """Dask's own timeout covers the TCP connection only: a server that accepts and says
    nothing held ``Client`` forever (still running at 400 s). Now the first answer has a
    limit too."""
    import threading
    import time

    from truestep.execution import cluster

    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 1.0)
    monkeypatch.setattr(cluster, "CONNECT_MARGIN_S", 1.0)
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(8)
        held: list[socket.socket] = []
        threading.Thread(target=lambda: held.extend(server.accept() for _ in range(8)), daemon=True).start()
        began = time.monotonic()
        assert _run(tmp_path / "out", "--scheduler", f"tcp://127.0.0.1:{server.getsockname()[1]}") == 2
        assert time.monotonic() - began < 30
    err = [line for line in capsys.readouterr().err.strip().splitlines() if line.startswith("truestep:")]
    assert len(err) == 1 and "no answer within 2 s" in err[0] and "no Dask scheduler answers" in err[0]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_the_scheduler_going_away_ends_the_run_with_one_error_and_keeps_the_sweeps(tmp_path: Path) -> None:
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    bin_dir = Path(sys.executable).parent
    env = {**os.environ, "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
    scheduler = subprocess.Popen(
        [bin_dir / "dask", "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    worker = subprocess.Popen(
        [bin_dir / "dask", "worker", address, "--nthreads", "1", "--no-dashboard"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    out = tmp_path / "out"
    out.mkdir()
    (out / MARKER).write_text(MARKER_TEXT)
    (out / "index.md").write_text("the previous report")
    try:
        run = subprocess.Popen(
            [
                bin_dir / "truestep",
                "run",
                "--quick",
                "--cases",
                "free-fall,harmonic-oscillator,spring-chain,damped-oscillator",
                "--engines",
                "reference,pymunk,pybullet",
                "--out",
                str(out),
                "--scheduler",
                address,
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        journal = tmp_path / ".out.partial"
        deadline = time.monotonic() + 120
        while not list(journal.glob("sweep-*.json")) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert list(journal.glob("sweep-*.json")), "no sweep finished on the cluster"
        scheduler.send_signal(signal.SIGKILL)
        _, stderr = run.communicate(timeout=120)
    finally:
        for p in (worker, scheduler):
            p.kill()
            p.wait()
    lines = [line for line in stderr.splitlines() if line.startswith("truestep:")]
    assert run.returncode == 2, stderr[-2000:]
    assert "Traceback" not in stderr and len(lines) == 1, stderr[-2000:]
    assert "lost the scheduler" in lines[0] and "--resume" in lines[0]
    assert (out / "index.md").read_text() == "the previous report"
    assert list(journal.glob("sweep-*.json"))  # nothing already finished is lost
