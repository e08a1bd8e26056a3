"""The machine a run's timings were measured on, in words a reader can compare.

Timing columns are only comparable between runs on the same kind of CPU: the same
code took 2.1-2.7x as long on a 2-core AMD EPYC as on a 2-core Intel Xeon (stop 71's
note). The floating-point environment that decides the *non-timing* numbers is
:func:`truestep.numerics.fingerprint`; this record decides nothing and is kept apart
from it, so that two CPUs that compute the same numbers stay comparable bit for bit.

Reads ``/proc/cpuinfo`` on Linux; elsewhere the standard library's
:func:`platform.processor`. Imports nothing heavy.
"""

from __future__ import annotations

import os
import platform
from collections.abc import Mapping
from functools import cache
from pathlib import Path

CPUINFO = Path("/proc/cpuinfo")
"""Where Linux names the CPU."""
MODEL_KEYS = ("model name", "hardware", "cpu model", "processor")
"""The ``/proc/cpuinfo`` fields that name the CPU, most telling first: ``model name`` on
x86-64 and recent ARM kernels, ``Hardware`` on older ARM, ``cpu model`` on MIPS;
``processor`` only where it holds a name, not the index x86 gives it."""


def usable_cores() -> int:
    """The cores this process may run on (its affinity, not the machine's count)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def cpu_model(cpuinfo: str | None = None) -> str:
    """The CPU's name as the system gives it (``"AMD EPYC"``,
    ``"Intel(R) Xeon(R) Processor @ 2.10GHz"``), whitespace runs made one; ``"unknown"``
    where the system names none. ``cpuinfo``: the text of ``/proc/cpuinfo`` (read when
    ``None``)."""
    if cpuinfo is None:
        return _system_cpu_model()
    fields: dict[str, str] = {}
    for line in cpuinfo.splitlines():
        key, sep, value = line.partition(":")
        key, value = key.strip().lower(), " ".join(value.split())
        if sep and value and key not in fields and not value.isdigit():
            fields[key] = value
    return next((fields[k] for k in MODEL_KEYS if k in fields), "unknown")


@cache
def _system_cpu_model() -> str:
    try:
        text = CPUINFO.read_text(errors="replace")
    except OSError:
        text = ""
    name = cpu_model(text) if text else "unknown"
    return name if name != "unknown" else (" ".join(platform.processor().split()) or "unknown")


def describe() -> dict[str, str | int]:
    """The machine as ``run.json`` records it (``machine``): the CPU's name, its
    architecture, the cores the run could use, the operating system and its release."""
    return {
        "cpu": cpu_model(),
        "architecture": platform.machine(),
        "cores": usable_cores(),
        "system": f"{platform.system()} {platform.release()}",
    }


def line(machine: Mapping | None = None) -> str:
    """:func:`describe` (or a recorded one) in words: ``"AMD EPYC (x86_64), 2 cores,
    Linux 6.1.0"``."""
    m = describe() if machine is None else machine
    cpu, arch = m.get("cpu", "unknown"), m.get("architecture", "?")
    return f"{cpu} ({arch}), {m.get('cores', '?')} cores, {m.get('system', '?')}"


def timed_alike(a: Mapping | None, b: Mapping | None) -> bool:
    """Whether two recorded machines (``run.json``'s ``machine``) time alike: the same CPU,
    architecture and usable cores. The operating system's release is left out: a kernel
    update moves no timing the way another CPU does. A run that recorded no machine (an
    earlier release's) is taken as alike: nothing says otherwise."""
    if not a or not b:
        return True
    return all(a.get(k) == b.get(k) for k in ("cpu", "architecture", "cores"))
