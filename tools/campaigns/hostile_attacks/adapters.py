"""Hostile adapters: their processes, their output, their clocks."""

from __future__ import annotations

import csv
import os
import signal
import time
from collections.abc import Callable
from pathlib import Path

from hostile_attacks.common import (
    RUN_TIMEOUT,
    Campaign,
    Result,
)


def adapter_run(
    c: Campaign,
    where: Path,
    cls: str,
    *extra: str,
    cases: str = "free-fall",
    env: dict[str, str] | None = None,
) -> Result:
    return c.quick_run(
        where,
        "rep",
        *extra,
        cases=cases,
        engines=f"hostile_adapters:{cls}",
        env=env or c.env(HOSTILE_PIDS=str(where / "pids")),
    )


def alive(pids: list[int]) -> list[int]:
    out = []
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state not in ("Z", "X"):
            out.append(pid)
    return out


def pids_of(where: Path) -> list[int]:
    path = where / "pids"
    return [int(x) for x in path.read_text().split()] if path.exists() else []


def left_behind(where: Path) -> list[int]:
    deadline = time.monotonic() + 5.0
    left = alive(pids_of(where))
    while left and time.monotonic() < deadline:
        time.sleep(0.1)
        left = alive(left)
    for pid in left:  # the campaign cleans up after the target
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return left


def _no_orphans(cls: str) -> Callable[[Campaign, Path], tuple[bool, str]]:
    def attack(c: Campaign, where: Path) -> tuple[bool, str]:
        result = adapter_run(c, where, cls)
        started, left = pids_of(where), left_behind(where)
        if not started:
            return False, f"the adapter started nothing: {result.why()}"
        return not left and result.code == 0, (
            f"{len(left)} of the adapter's {len(started)} processes outlived the run; {result.why()}"
        )

    attack.__name__ = f"attack_{cls.lower()}_children_outlive_a_finished_run"
    attack.__doc__ = f"The {cls} adapter leaves processes behind after a normal run."
    return attack


def attack_adapter_children_outlive_sigterm(c: Campaign, where: Path) -> tuple[bool, str]:
    """SIGTERM to truestep while the Spawner adapter's processes run."""
    started = time.perf_counter()
    proc = c.start(
        ["run", "--quick", "--engines", "hostile_adapters:Spawner", "--cases", "free-fall", "--out", "rep"],
        where,
        env=c.env(HOSTILE_PIDS=str(where / "pids")),
    )
    deadline = time.monotonic() + RUN_TIMEOUT
    while not pids_of(where) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    result = c.finish(proc, 60, started)
    left = left_behind(where)
    return not left and pids_of(where) != [], (
        f"{len(left)} of the adapter's processes outlived the run; {result.why()}"
    )


def attack_adapter_output_mixed_into_truestep_output(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter that prints (a fake ``wrote ...`` line, stderr, fd 1, a subprocess,
    C printf): none of it may reach truestep's standard output or error."""
    result = adapter_run(c, where, "Chatty")
    leaked = [w for w in ("CHATTY", "fake-report") if w in result.out + result.err]
    return not leaked and result.code == 0, f"leaked {leaked}; {result.why()}"


def row_statuses(folder: Path, engine: str) -> list[tuple[str, str]]:
    path = folder / "results.csv"
    if not path.is_file():
        return []
    return [(r["status"], r.get("message", "")) for r in csv.DictReader(path.open()) if r["engine"] == engine]


def _crashed_rows(cls: str, engine: str, what: str) -> Callable[[Campaign, Path], tuple[bool, str]]:
    def attack(c: Campaign, where: Path) -> tuple[bool, str]:
        result = adapter_run(c, where, cls)
        rows = row_statuses(where / "rep", engine)
        bad = [s for s, _ in rows if s != "crashed"]
        return bool(rows) and not bad, (
            f"rows {sorted(set(s for s, _ in rows))}; {rows[0][1][:120] if rows else result.why()}"
        )

    attack.__name__ = f"attack_{cls.lower()}_{what}"
    attack.__doc__ = f"The {cls} adapter: {what.replace('_', ' ')}; every row must be crashed."
    return attack


def attack_crash_output_shown_in_the_row(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter that prints a diagnostic and raises: the row's message shows it."""
    result = adapter_run(c, where, "LoudCrash")
    rows = row_statuses(where / "rep", "loud-crash")
    shown = bool(rows) and all(s == "crashed" and "DIAG-7731" in m for s, m in rows)
    return shown and "DIAG-7731" not in result.out + result.err, (
        f"{rows[0][1][:160] if rows else result.why()}"
    )


ATTACKS = [
    _no_orphans("Spawner"),
    _no_orphans("Daemon"),
    _no_orphans("Forker"),
    attack_adapter_children_outlive_sigterm,
    attack_adapter_output_mixed_into_truestep_output,
    _crashed_rows("EarlyClock", "early-clock", "records_from_minus_10_s"),
    _crashed_rows("FrozenClock", "frozen-clock", "records_frozen_at_0"),
    _crashed_rows("NegativeWall", "negative-wall", "wall_time_of_minus_5_s"),
    _crashed_rows("NanWall", "nan-wall", "wall_time_nan"),
    attack_crash_output_shown_in_the_row,
]
