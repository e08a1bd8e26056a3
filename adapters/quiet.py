"""Import an engine that prints on the process's standard output as it loads."""

from __future__ import annotations

import ctypes
import importlib
import os
import sys
from types import ModuleType


def import_quietly(name: str) -> ModuleType:
    """Import module ``name`` with file descriptor 1 pointed at ``/dev/null``.

    C code's ``printf`` bypasses ``sys.stdout``, and into a pipe it is buffered until the
    process exits: the C buffer is flushed before the descriptor is restored, so nothing
    the import printed reaches the command's output (``truestep list`` is read by tools).
    """
    if name in sys.modules:
        return sys.modules[name]
    sys.stdout.flush()
    saved, devnull = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        module = importlib.import_module(name)
        ctypes.CDLL(None).fflush(None)
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)
    return module
