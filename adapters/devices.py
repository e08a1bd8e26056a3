"""Where a run's engines compute: the CPU, or a GPU an engine can use (``truestep run --device``).

A run's device choice (:func:`parse`) names one device for every engine that takes one
(``cuda:0``), a device per engine (``newton=cuda:0``), or both
(``cuda:0,mujoco-warp=cpu``). An engine takes a device when its adapter class's
constructor has a ``device`` parameter (truestep's Warp engines, MuJoCo Warp and Newton,
and the reference, whose independent-particle scenes have a Warp kernel); every other
engine computes on the CPU whatever is asked. An engine whose class says
``device_named_only`` (the reference) moves only when the choice names it
(``reference=cuda:0``), never with a device for every engine (:func:`named_only`). :func:`resolve` checks a
choice against the run's engines and this machine before anything runs: a form it does
not know, an engine that is not in the run or takes no device, or a GPU that the machine
does not have is a :class:`DeviceError` (``truestep run`` says it in one line and exits
2). The devices resolved travel to every process of the run in the environment
(:data:`ENV`, :func:`chosen`): the run's forked children, and the worker processes a
``local:N`` cluster starts.

Whether the machine has a GPU is asked of Warp in a fresh interpreter
(:func:`cuda_devices`), never in truestep's process: Warp's start looks for CUDA, and
CUDA does not survive the fork that runs every sweep
(:mod:`truestep.adapters.warp_runtime`).
"""

from __future__ import annotations

import contextlib
import functools
import inspect
import os
import re
import subprocess
import sys
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field

CPU = "cpu"
"""The device every engine computes on unless a run asks for another."""

ENV = "TRUESTEP_DEVICES"
"""The environment variable that carries a run's resolved devices to its processes:
``engine=device`` pairs, comma-separated (:func:`chosen`)."""

FORM = re.compile(r"^(cpu|cuda(:\d+)?)$")
"""A device as Warp names it: ``cpu``, ``cuda`` (the first GPU), ``cuda:N``."""

PROBE_S = 120.0
"""How long the fresh interpreter that counts the GPUs may take, s (Warp's start with a
GPU loads its CUDA driver and reads each device)."""

_PROBE = (
    "import warp as wp\n"
    "wp.config.quiet = True\n"
    "wp.config.log_level = wp.LOG_ERROR\n"
    "wp.init()\n"
    "print(wp.get_cuda_device_count())\n"
)


class DeviceError(ValueError):
    """A device choice that cannot run here: what was asked, and why (one line)."""


@dataclass(frozen=True)
class DeviceChoice:
    """A parsed ``--device``: ``every``, the device of every engine that takes one
    (``None``: not asked), and ``engines``, a device per named engine (which wins)."""

    every: str | None = None
    engines: Mapping[str, str] = field(default_factory=dict)

    def of(self, engine: str) -> str | None:
        """The device asked for ``engine``, or ``None``."""
        return self.engines.get(engine, self.every)


def parse(text: str | Mapping[str, str] | None) -> DeviceChoice:
    """A device choice from ``--device`` text (``cuda:0``, ``newton=cuda:0``,
    ``cuda:0,mujoco-warp=cpu``) or a mapping engine -> device (the API's); ``None`` or
    empty text: nothing asked. Raises :class:`DeviceError` for a form it does not know."""
    if text is None:
        return DeviceChoice()
    if isinstance(text, Mapping):
        pairs = [(str(k), str(v)) for k, v in text.items()]
        every = None
    else:
        every, pairs = None, []
        for item in (part.strip() for part in str(text).split(",")):
            if not item:
                continue
            engine, sep, device = item.rpartition("=")
            if not sep:
                if every is not None:
                    raise DeviceError(f"{text!r}: two devices for every engine ({every}, {device})")
                every = _checked(device)
                continue
            pairs.append((engine.strip(), device.strip()))
    engines: dict[str, str] = {}
    for engine, device in pairs:
        if not engine:
            raise DeviceError(f"{text!r}: an engine=device pair without its engine")
        if engine in engines:
            raise DeviceError(f"{text!r}: two devices for engine {engine!r}")
        engines[engine] = _checked(device)
    return DeviceChoice(every, engines)


def _checked(device: str) -> str:
    """``device`` when it is a form Warp names (:data:`FORM`), else a :class:`DeviceError`."""
    device = device.strip()
    if not FORM.match(device):
        raise DeviceError(f"{device!r} is not a device: cpu, cuda or cuda:N (N the GPU's index)")
    return device


def takes_device(adapter_class: type) -> bool:
    """Whether an engine can be put on a device: its adapter's constructor has a ``device``
    parameter."""
    try:
        return "device" in inspect.signature(adapter_class).parameters
    except (TypeError, ValueError):  # a constructor without a signature Python can read
        return False


def named_only(adapter_class: type) -> bool:
    """Whether an engine moves off the CPU only when a run names it (``reference=cuda:0``),
    not with every engine (``cuda:0``): its adapter class's ``device_named_only`` (the
    reference's, which on a GPU models fewer scenes)."""
    return bool(getattr(adapter_class, "device_named_only", False))


def cuda_devices(python: str | None = None) -> int:
    """The CUDA devices Warp finds on this machine, asked in a fresh interpreter (``python``,
    default this one): 0 where Warp is not installed, finds no driver, or does not answer
    within :data:`PROBE_S`."""
    try:
        done = subprocess.run(
            [python or sys.executable, "-c", _PROBE],
            capture_output=True,
            text=True,
            timeout=PROBE_S,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired):
        return 0
    lines = done.stdout.strip().splitlines()
    if done.returncode != 0 or not lines or not lines[-1].strip().isdigit():
        return 0
    return int(lines[-1])


def _index(device: str) -> int:
    """The GPU index of a CUDA device (``cuda`` is ``cuda:0``)."""
    return int(device.partition(":")[2] or 0)


def resolve(
    choice: DeviceChoice,
    engines: Iterable[str],
    classes: Mapping[str, type],
    *,
    gpus: int | None = None,
) -> dict[str, str]:
    """The device of each of the run's ``engines`` that takes one and is asked off the CPU
    (engine -> device; empty: every engine on the CPU, as a run without ``--device``).

    ``classes``: the adapter class of each engine (:func:`takes_device`); ``gpus``: the
    machine's CUDA devices (default: :func:`cuda_devices`, asked only where a GPU is).
    Raises :class:`DeviceError` for an engine named that is not in the run, one that takes
    no device asked off the CPU, a device for every engine where none of the run's takes
    one, and a GPU this machine does not have."""
    engines = list(engines)
    for engine, device in choice.engines.items():
        if engine not in engines:
            raise DeviceError(
                f"{engine}={device}: {engine!r} is not one of the run's engines ({', '.join(engines)})"
            )
        if device != CPU and not takes_device(classes[engine]):
            raise DeviceError(
                f"{engine}={device}: {engine} computes on the CPU only (its adapter takes no device)"
            )
    able = [e for e in engines if takes_device(classes[e])]
    if choice.every not in (None, CPU) and not [e for e in able if not named_only(classes[e])]:
        raise DeviceError(
            f"{choice.every}: none of the run's engines ({', '.join(engines)}) takes a device; "
            "those that do: MuJoCo Warp and Newton (mujoco-warp, newton); the reference when named "
            "(reference=cuda:0)"
        )
    wanted = {
        e: d
        for e in able
        if (d := choice.engines.get(e) if named_only(classes[e]) else choice.of(e)) not in (None, CPU)
    }
    if not wanted:
        return {}
    have = cuda_devices() if gpus is None else gpus
    for engine, device in wanted.items():
        if _index(device) >= have:
            found = "no CUDA device" if not have else f"{have} CUDA device(s), cuda:0 to cuda:{have - 1}"
            raise DeviceError(
                f"{engine}={device}: this machine has {found} (as Warp finds them); "
                "run without --device to compute on the CPU"
            )
    return wanted


def chosen(engine: str) -> str | None:
    """The device this run resolved for ``engine`` (from :data:`ENV`), or ``None``."""
    return in_use().get(engine)


def words(devices: Mapping[str, str]) -> str:
    """``devices`` as :data:`ENV` and ``--device`` write them: ``engine=device``, comma-separated."""
    return ",".join(f"{e}={d}" for e, d in sorted(devices.items()))


@contextlib.contextmanager
def used(devices: Mapping[str, str]) -> Iterator[None]:
    """:data:`ENV` set to ``devices`` inside the block (its value before put back after):
    the adapters made in it, here and in the processes it starts, compute there."""
    before = os.environ.get(ENV)
    if devices:
        os.environ[ENV] = words(devices)
    else:
        os.environ.pop(ENV, None)
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(ENV, None)
        else:
            os.environ[ENV] = before


def in_use() -> dict[str, str]:
    """The devices this run resolved (:data:`ENV`): engine -> device, empty when every
    engine computes on the CPU."""
    out: dict[str, str] = {}
    for item in os.environ.get(ENV, "").split(","):
        name, sep, device = item.partition("=")
        if sep and name and FORM.match(device):
            out[name] = device
    return out


def device_of(adapter: object) -> str:
    """The device an adapter computes on: its ``device`` attribute where it has one (a Warp
    engine's), else the CPU."""
    device = getattr(adapter, "device", None)
    return device if isinstance(device, str) and device else CPU


def engine_device(engine: str) -> str:
    """The device engine ``engine``'s adapter computes on in this run (:func:`device_of`),
    made once per engine and run's devices (:data:`ENV`); empty where it cannot be made."""
    return _engine_device(engine, os.environ.get(ENV, ""))


@functools.cache
def _engine_device(engine: str, _devices: str) -> str:
    from truestep.adapters import get_adapter

    try:
        return device_of(get_adapter(engine))
    except Exception:  # an engine that cannot be made: its rows say why, not where
        return ""
