"""The scaling table's defaults, in a module of their own so that ``truestep --help``
shows them without loading the benchmark (:mod:`truestep.execution.bench`)."""

from __future__ import annotations

SIZES: tuple[float, ...] = (1e2, 1e3, 1e4, 1e5, 1e6)
"""Particle counts of the table, by default."""

BUDGET_S = 35.0
"""Default seconds for every run of the table (all engines, methods and sizes)."""

__all__ = ["BUDGET_S", "SIZES"]
