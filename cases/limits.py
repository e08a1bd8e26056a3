"""What a case may cost, checked when it loads, before anything is allocated or run.

A case's cost is derived from its file: the particles (groups, blocks, meshes, emitter
pools), the springs, the steps of its finest run (``duration / dt``, and of its
stability search and reference run), the records it keeps, the work (particle and
spring updates over the finest run) and the memory its records need. A case over a
limit is refused at load with the numbers (:class:`~truestep.cases.errors.CaseError`).

The defaults (:data:`DEFAULT`) hold every shipped case with room to spare; a case file
raises its own with a ``[limits]`` table (same keys), up to a :data:`CEILING` it cannot
raise, and ``truestep run --limit KEY=VALUE`` (or :func:`override`) raises or lowers them
for a whole run, over the case files' own (beyond the ceiling only with
``--trust-limits``). Every time step a case names is at least :data:`MIN_STEP_S`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from truestep.cases.fields import Fields


@dataclass(frozen=True)
class Limits:
    """The most a case may cost.

    particles : particles in the scene (emitter pools count their capacity)
    springs : springs, anchors included
    steps : steps of one run at the finest step of the sweep (and of a stability run)
    records : states one run keeps (``[run] max_records``)
    work : particle and spring updates of the finest run, ``(particles + springs) x steps``
    memory_mb : MiB the kept states of one run need, ``records x particles x 48 B``
    timeout_s : the largest per-step ``[run] timeout`` a case may ask for, s
    """

    particles: int = 1_000_000
    springs: int = 5_000_000
    steps: int = 20_000_000
    records: int = 100_000
    work: float = 2e10
    memory_mb: float = 4096.0
    timeout_s: float = 3600.0


DEFAULT = Limits()
CEILING = Limits(
    particles=10_000_000,
    springs=50_000_000,
    steps=200_000_000,
    records=1_000_000,
    work=2e11,
    memory_mb=16384.0,
    timeout_s=21600.0,
)
"""The most a case file's ``[limits]`` may raise each limit to (ten times the default; the
timeout to the default budget of a whole run, 6 h). Only the command line goes beyond,
with ``truestep run --trust-limits --limit KEY=VALUE``: a case file is data from
anywhere, and cannot ask for a run of days or an array of terabytes."""
MIN_STEP_S = 1e-9
"""The smallest time step (or emitter frame, or stability bracket, or reference step) a
case may name, s, and the shortest duration: below it a step count is meaningless for an
animation and a float time cannot advance by it over a run of seconds."""
KEYS = tuple(f.name for f in dataclasses.fields(Limits))
_FLOATS = {"work", "memory_mb", "timeout_s"}
TRUST_FLAG = "--trust-limits"


def read_limits(f: Fields, base: Limits) -> Limits:
    """A case file's ``[limits]`` table over ``base`` (every key optional, positive, at
    most its :data:`CEILING`)."""
    if not f.has("limits"):
        return base
    t = f.sub("limits")
    values: dict[str, Any] = {}
    for key in KEYS:
        if t.has(key):
            ceiling = getattr(CEILING, key)
            values[key] = t.number(key, positive=True) if key in _FLOATS else t.integer(key, minimum=1)
            if values[key] > ceiling:
                raise t.error(
                    key,
                    f"{values[key]:.3g} is over the ceiling of {ceiling:.3g} a case "
                    f"file may raise it to (only truestep run {TRUST_FLAG} --limit "
                    f"{key}=N goes beyond it)",
                )
    t.done()
    return dataclasses.replace(base, **values)


class LimitError(ValueError):
    """A limit item or value that cannot be used (``--limit``, a ``[limits]`` table): one
    line that says which and why."""


def check_ceilings(values: dict[str, float], *, trusted: bool, where: str = "--limit") -> None:
    """Refuse (:class:`LimitError`, one line) a limit in ``values`` over its :data:`CEILING`
    unless the inputs are ``trusted`` (``--trust-limits``)."""
    for key, value in values.items():
        ceiling = getattr(CEILING, key)
        if not trusted and value > ceiling:
            raise LimitError(
                f"{where} {key}={value:.3g} is over the ceiling of {ceiling:.3g}; "
                f"add {TRUST_FLAG} if the cases of this run are trusted"
            )


def parse_override(items: list[str], *, trusted: bool = False) -> dict[str, float]:
    """``["steps=1e8", "particles=2e6"]`` -> ``{"steps": 1e8, ...}``; :class:`LimitError` says why
    (a value over its :data:`CEILING` needs ``trusted``)."""
    out: dict[str, float] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or key not in KEYS:
            raise LimitError(
                f"--limit: expected KEY=VALUE with KEY one of {', '.join(KEYS)}, got {item[:40]!r}"
            )
        try:
            value = float(raw)
        except ValueError:
            raise LimitError(f"--limit {key}: not a number: {raw[:40]!r}") from None
        if not 0 < value < float("inf"):
            raise LimitError(f"--limit {key}: must be a positive finite number, got {raw[:40]!r}")
        out[key] = value
    check_ceilings(out, trusted=trusted)
    return out


def override(limits: Limits, values: dict[str, float]) -> Limits:
    """``limits`` with ``values`` (from :func:`parse_override`) put over it."""
    typed: dict[str, Any] = {k: (float(v) if k in _FLOATS else int(v)) for k, v in values.items()}
    return dataclasses.replace(limits, **typed)


class Budget:
    """The particles and springs a scene has claimed so far, checked against the limits
    as each part is read (before its arrays are built)."""

    def __init__(self, limits: Limits) -> None:
        self.limits = limits
        self.particles = 0
        self.springs = 0

    def take(self, f: Fields, field: str, particles: int = 0, springs: int = 0) -> None:
        """Claim ``particles`` and ``springs`` for the part ``f`` reads; raise naming
        ``field`` and the numbers if the scene would go over a limit."""
        self.particles += int(particles)
        self.springs += int(springs)
        if self.particles > self.limits.particles:
            raise f.error(
                field,
                f"the scene would have {self.particles:.3g} particles, over "
                f"the limit of {self.limits.particles:.3g} (raise it with [limits] "
                "particles or --limit particles=N)",
            )
        if self.springs > self.limits.springs:
            raise f.error(
                field,
                f"the scene would have {self.springs:.3g} springs, over "
                f"the limit of {self.limits.springs:.3g} (raise it with [limits] "
                "springs or --limit springs=N)",
            )
