"""Named metrics a case can ask for (``properties = [...]``) and gate on."""

from __future__ import annotations

from collections.abc import Callable

from adapters.base import Trajectory
from cases.case import Case

PROPERTIES: dict[str, Callable[[Case, Trajectory], float]] = {}
