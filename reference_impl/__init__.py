"""The lecture's models in numpy: systems, solvers, forces, particles.

Imports no physics engine and nothing of the harness. numba's on-disk cache is read so
that a damaged file is compiled again rather than raised, and a function of this package
is compiled again whenever any of its modules changed
(:mod:`~truestep.reference_impl.cache_guard`); numba's inliner copies a function's IR as
one object (:mod:`~truestep.reference_impl.inline_copy`).
"""

from truestep.reference_impl.cache_guard import guard as _guard_numba_cache
from truestep.reference_impl.cache_guard import stamp_by_folder as _stamp_numba_cache_by_folder
from truestep.reference_impl.inline_copy import install as _copy_inlined_ir_once

_guard_numba_cache()
_stamp_numba_cache_by_folder()
_copy_inlined_ir_once()
