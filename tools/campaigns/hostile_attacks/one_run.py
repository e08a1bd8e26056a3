"""Two runs on one ``--out``."""

from __future__ import annotations

import time
from pathlib import Path

from hostile_attacks.common import (
    RUN_TIMEOUT,
    Campaign,
    tables_without_timing,
)


def two_runs(
    c: Campaign, where: Path, second: list[str], out_second: str = "rep", cwd_second: Path | None = None
) -> tuple[bool, str]:
    """A slow run on ``rep``, then a second command while it runs: the second is refused
    at once naming the first, and the first finishes its report."""
    started = time.perf_counter()
    first = c.start(
        ["run", "--quick", "--engines", "hostile_adapters:Sleeper", "--cases", "free-fall", "--out", "rep"],
        where,
    )
    deadline = time.monotonic() + RUN_TIMEOUT
    while not (where / ".rep.partial").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    other = c.truestep(second, cwd_second or where, timeout=RUN_TIMEOUT)
    one = c.finish(first, RUN_TIMEOUT, started)
    first_ok = one.code == 0 and (where / "rep" / "results.csv").is_file()
    quick = other.seconds < 30
    ok = other.clean_refusal and quick and first_ok and "pid" in other.err
    return ok, f"second: {other.why()}; first: exit {one.code}"


def attack_second_run_on_the_same_out(c: Campaign, where: Path) -> tuple[bool, str]:
    """Two ``truestep run`` on one ``--out`` at once."""
    return two_runs(
        c, where, ["run", "--quick", "--engines", "reference", "--cases", "free-fall", "--out", "rep"]
    )


def attack_resume_while_the_run_is_alive(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--resume`` of a run that is still running."""
    return two_runs(
        c,
        where,
        [
            "run",
            "--quick",
            "--engines",
            "hostile_adapters:Sleeper",
            "--cases",
            "free-fall",
            "--resume",
            "rep",
        ],
    )


def attack_second_run_through_a_link(c: Campaign, where: Path) -> tuple[bool, str]:
    """A second run on the same folder, named through a symbolic link to its parent."""
    (where / "alias").symlink_to(where)
    return two_runs(
        c, where, ["run", "--quick", "--engines", "reference", "--cases", "free-fall", "--out", "alias/rep/"]
    )


def attack_resume_after_a_kill(c: Campaign, where: Path) -> tuple[bool, str]:
    """A run killed (SIGKILL) mid-sweep, so whatever lock it held is stale: ``--resume``
    finishes it."""
    result = c.quick_run(where, "rep", env=c.env(TRUESTEP_KILL_AT="sweep:20"))
    if not result.killed:
        return False, f"the run was not killed: {result.why()}"
    again = c.quick_run(where, "rep", "--resume")
    same = tables_without_timing(where / "rep") == tables_without_timing(c.base_report())
    return again.code == 0 and same, again.why()


def attack_new_run_after_a_kill(c: Campaign, where: Path) -> tuple[bool, str]:
    """A run killed (SIGKILL) mid-sweep, then a new run (no --resume) on the same folder."""
    result = c.quick_run(where, "rep", env=c.env(TRUESTEP_KILL_AT="sweep:10"))
    if not result.killed:
        return False, f"the run was not killed: {result.why()}"
    again = c.quick_run(where, "rep")
    return again.code == 0, again.why()


ATTACKS = [
    attack_second_run_on_the_same_out,
    attack_resume_while_the_run_is_alive,
    attack_second_run_through_a_link,
    attack_resume_after_a_kill,
    attack_new_run_after_a_kill,
]
