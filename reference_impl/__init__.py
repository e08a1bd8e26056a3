"""The lecture's models in numpy: systems, solvers, forces, particles.

Imports no physics engine and nothing of the harness. numba's on-disk cache is read so
that a damaged file is compiled again rather than raised
(:mod:`~truestep.reference_impl.cache_guard`).
"""

from truestep.reference_impl.cache_guard import guard as _guard_numba_cache

_guard_numba_cache()
