"""numba's on-disk cache read so that a damaged file is a cache miss, not a traceback.

numba reads a cached function's index (``*.nbi``) and data (``*.nbc``) with ``pickle``;
a file cut short (a full disk, a killed write, a copy interrupted) raises
``UnpicklingError`` out of the first call of the function, on every run, until the
cache folder is deleted by hand. :func:`guard` makes numba take such a file as absent:
the function is compiled again and the file written afresh. Nothing else changes: a
file that reads is used as numba would use it.
"""

from __future__ import annotations

import pickle
from typing import Any

from numba.core import caching

DAMAGED = (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError, IndexError)
"""What reading a damaged cache file raises."""


def guard() -> None:
    """Install the guard on numba's cache reader (once per process)."""
    cls: Any = caching.IndexDataCacheFile
    if getattr(cls, "_truestep_guarded", False):
        return
    load_index, load_data = cls._load_index, cls._load_data

    def _load_index(self: Any) -> dict:
        try:
            return load_index(self)
        except DAMAGED:  # an index cut short: no entry, so compiled again and rewritten
            return {}

    def _load_data(self: Any, name: str) -> Any:
        try:
            return load_data(self, name)
        except DAMAGED as err:  # numba's load() takes an OSError as a missing entry
            raise OSError(f"damaged numba cache file {name}: {type(err).__name__}") from err

    cls._load_index, cls._load_data = _load_index, _load_data
    cls._truestep_guarded = True
