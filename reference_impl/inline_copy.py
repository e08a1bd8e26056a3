"""numba's inliner made to copy a function's IR as one object, not block by block.

numba inlines a function compiled with ``inline='always'`` into its caller as IR, and
copies the callee's IR first (``InlineWorker.inline_ir``, twice: a copy to splice in and
an unmutated one to hand back). It deep-copies each block on its own, with a fresh memo,
so every block's copy drags along its own copy of the function's ``Scope`` and of every
variable the scope holds: the cost grows with blocks times variables, and for the
compiled loops of :mod:`~truestep.reference_impl.integrate_kernels` (a driver, a
method's step, the derivative and the force kernels, inlined into one another) it was a large share of the
time a loop takes to compile. :func:`install` gives the block copies of one
``inline_ir`` call one memo, so the blocks of a copy share one copied scope, as the
blocks of the original share one scope. The IR spliced into the caller is the same,
statement for statement, so the machine code and every number computed with it are too
(the compiled-against-numpy equality tests and the quick run's ``--identical`` gate check
it); a loop compiles in less time, by the share those copies took.

numba's own issues name this cost (numba#8989, numba#9204); its later versions may copy
differently, and then the memo given here is simply not used.
"""

from __future__ import annotations

import copy
import functools
import threading
from typing import Any

from numba.core import inline_closurecall

_LOCAL = threading.local()
"""The memo of the ``inline_ir`` call under way in this thread (``memo``), if any."""


class _SharedMemoCopy:
    """Stands in for the :mod:`copy` module inside numba's inliner: ``deepcopy`` without
    a memo of its own takes the memo of the ``inline_ir`` call under way; everything else
    is :mod:`copy`'s."""

    def __getattr__(self, name: str) -> Any:
        return getattr(copy, name)

    @staticmethod
    def deepcopy(x: Any, memo: dict | None = None) -> Any:
        """:func:`copy.deepcopy` with the memo of the inlining under way."""
        return copy.deepcopy(x, getattr(_LOCAL, "memo", None) if memo is None else memo)


def install() -> None:
    """Give the block copies of each ``InlineWorker.inline_ir`` call one memo (once per
    process)."""
    worker: Any = inline_closurecall.InlineWorker
    if getattr(worker, "_truestep_one_memo", False):
        return
    inline_ir = worker.inline_ir

    @functools.wraps(inline_ir)
    def with_one_memo(self: Any, *args: Any, **kwargs: Any) -> Any:
        outer = getattr(_LOCAL, "memo", None)
        _LOCAL.memo = {}
        try:
            return inline_ir(self, *args, **kwargs)
        finally:
            _LOCAL.memo = outer

    worker.inline_ir = with_one_memo
    inline_closurecall.copy = _SharedMemoCopy()  # type: ignore[assignment]  # the module's name for copy
    worker._truestep_one_memo = True
