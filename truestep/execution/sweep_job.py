"""One sweep as a unit of work (a case, an engine and a method over its steps), and the host
it runs on: what the runner hands to a cluster (:mod:`truestep.execution.cluster`) and what a worker
runs (:func:`truestep.execution.runner.run_sweep`)."""

from __future__ import annotations

import socket
from dataclasses import dataclass
from typing import Any

from truestep.cases.case import Case


@dataclass(frozen=True)
class SweepJob:
    """One case, engine and method over its sweep: what one task runs."""

    index: int
    case: Case
    engine: str
    method: str
    dts: list[float]
    adaptive: bool
    timing: Any
    want_traces: bool


def host_name() -> str:
    """The name of the machine this process runs on (the ``host`` column)."""
    return socket.gethostname()
