"""Import or start an engine that prints a banner on the process's output as it loads."""

from __future__ import annotations

import contextlib
import ctypes
import importlib
import os
import re
import sys
import tempfile
from collections.abc import Iterator
from types import ModuleType


@contextlib.contextmanager
def without_banner(banner: str = r"$^") -> Iterator[None]:
    """Run the block with file descriptors 1 and 2 pointed at a temporary file, then
    write back to standard error whatever it printed except the lines that match
    ``banner`` (a regular expression: the engine's greeting).

    C code's ``printf`` bypasses ``sys.stdout``, and into a pipe it is buffered until the
    process exits: the C buffer is flushed before the descriptors are restored, so the
    banner reaches neither the command's output (``truestep list`` is read by tools) nor
    its log, and anything else the block says (a warning) still reaches standard error.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with tempfile.TemporaryFile() as sink:
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            try:
                yield
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                ctypes.CDLL(None).fflush(None)
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
        sink.seek(0)
        said = sink.read().decode("utf-8", "replace").splitlines()
    rest = [line for line in said if line.strip() and not re.search(banner, line)]
    if rest:
        print("\n".join(rest), file=sys.stderr)


def import_quietly(name: str, banner: str = r"$^") -> ModuleType:
    """Import module ``name`` without its ``banner`` lines (:func:`without_banner`)."""
    if name in sys.modules:
        return sys.modules[name]
    with without_banner(banner):
        return importlib.import_module(name)
