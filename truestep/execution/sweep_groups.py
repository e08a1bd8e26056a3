"""Sweeps that share one process: the sweeps of one built-in engine on one case (its
methods), so that a run forks a process per case and engine, not per method.

A fork of truestep's process, which holds every engine, its loaded kernels and the run's
tables, costs it about 11 ms on the 2-core machine (write-protecting some 800 MB of pages),
and the child as much again in pages copied and torn down: for a quick run's 222 sweeps,
some 5 s of CPU in a run of 22 s. A sweep's runs already share their process
(:func:`truestep.execution.runner.simulate_sweep`: every adapter builds and tears down its
scene per run, so no engine state outlives a run); the sweeps of one engine on one case
share theirs the same way. A plugin's sweeps keep a process each: its code is not
truestep's to vouch for.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence

GROUP_ROWS = 24
"""The most runs (steps of sweeps) one process takes together: a cap on the work one
failure sends to be made again alone (:func:`truestep.execution.runner.simulate_sweeps`)."""
GROUP_BYTES = 256e6
"""The most bytes of records the runs of one process hand back together (a particle-rain
run's positions and velocities are 48 MB: five of them a process, where one sweep holds two)."""


def weight(runs: int, record_bytes: float) -> float:
    """A sweep's share of a group: its ``runs`` of :data:`GROUP_ROWS`, or its records
    (``runs`` times ``record_bytes``) of :data:`GROUP_BYTES`, whichever is more."""
    return max(runs / GROUP_ROWS, runs * record_bytes / GROUP_BYTES)


def group_sweeps(keys: Sequence[Hashable | None], weights: Sequence[float]) -> list[list[int]]:
    """Indices of sweeps gathered into groups, each run by one process.

    ``keys[i]`` is what the ``i``-th sweep must share with the others of its group (its
    engine, case, part and timing), or ``None`` for a sweep that keeps a process of its
    own; ``weights[i]`` its share of a group (:func:`weight`). Sweeps of one key join the
    group that key has open while their shares add up to at most 1 (a sweep over it is a
    group of its own). Groups come in the order of their first sweep, and each lists its
    sweeps in their order, so that the lanes run them in the order planned."""
    groups: list[list[int]] = []
    open_group: dict[Hashable, tuple[list[int], float]] = {}
    for i, key in enumerate(keys):
        held = open_group.get(key) if key is not None else None
        if held is not None and held[1] + weights[i] <= 1.0:
            held[0].append(i)
            open_group[key] = (held[0], held[1] + weights[i])
            continue
        group = [i]
        groups.append(group)
        if key is not None:
            open_group[key] = (group, weights[i])
    return groups
