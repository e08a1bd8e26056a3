"""What the kill tests look at: a report directory's bytes, scratch folders left beside
it, child processes still alive, and tables without their timing columns."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pandas as pd

from truestep.execution.runner import MACHINE_COLUMNS as TIMING_COLUMNS


def snapshot(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (hidden ones too) by relative path, with its bytes; of
    ``run.json`` all but its ``seconds`` (each phase's wall time, which no two runs share)."""
    return {
        str(p.relative_to(root)): _timeless(p) if p.name == "run.json" else p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def _timeless(path: Path) -> bytes:
    try:
        record = json.loads(path.read_text())
    except ValueError:
        return path.read_bytes()
    if isinstance(record, dict):
        record.pop("seconds", None)
    return json.dumps(record, sort_keys=True).encode()


def scratch_left(out: Path) -> list[str]:
    """Staging and old folders of ``out`` beside it (the journal does not count, nor the
    lock file a killed run leaves for the next run to take over)."""
    return sorted(
        n
        for n in os.listdir(out.parent)
        if n.startswith(f".{out.name}.") and not n.endswith((".partial", ".lock"))
    )


def _running(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] not in ("Z", "X")


def pids_in(pid_file: Path) -> list[int]:
    """The pids a run recorded (``TRUESTEP_CHILD_PIDS``), one a line."""
    return [int(x) for x in pid_file.read_text().split()] if pid_file.exists() else []


def still_running(pids: list[int], wait_s: float = 5.0) -> list[int]:
    """Those of ``pids`` still running (not gone, not zombies) after up to ``wait_s``
    seconds."""
    deadline = time.monotonic() + wait_s
    alive = [p for p in pids if _running(p)]
    while alive and time.monotonic() < deadline:
        time.sleep(0.05)
        alive = [p for p in alive if _running(p)]
    return alive


def non_timing(path: Path) -> pd.DataFrame:
    """A table without its timing columns."""
    df = pd.read_csv(path)
    return df.drop(columns=[c for c in TIMING_COLUMNS if c in df])


def assert_same_tables(a: Path, b: Path) -> None:
    """results, stability and restitution of two runs agree in every non-timing column
    (NaN equal to NaN)."""
    for name in ("results", "stability", "restitution"):
        pd.testing.assert_frame_equal(
            non_timing(a / f"{name}.csv"), non_timing(b / f"{name}.csv"), check_exact=True, obj=name
        )
