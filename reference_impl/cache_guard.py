"""numba's on-disk cache made safe: a damaged file, or a changed module of the reference
implementation, is a cache miss.

numba reads a cached function's index (``*.nbi``) and data (``*.nbc``) with ``pickle``;
a file cut short (a full disk, a killed write, a copy interrupted) raises
``UnpicklingError`` out of the first call of the function, on every run, until the
cache folder is deleted by hand. :func:`guard` makes numba take such a file as absent:
the function is compiled again and the file written afresh. Nothing else changes: a
file that reads is used as numba would use it.

numba also takes a function's cached code as current while the function's own file is
unchanged, yet that code holds every kernel it calls or inlines, from whatever module
(a step holds the force kinds, the collision pass, the methods). :func:`stamp_by_folder`
makes the source stamp of every function of the reference implementation the hash of
every module under its folder (:data:`FINGERPRINT`): a change to any of them compiles
every one of its functions afresh, and nothing is taken stale from the cache.
"""

from __future__ import annotations

import hashlib
import os
import pickle
from pathlib import Path
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


def source_fingerprint(folder: Path) -> str:
    """A hash of the name and source of every Python module under ``folder`` (its
    subfolders too), in the order of their paths."""
    digest = hashlib.sha256()
    for path in sorted(folder.rglob("*.py")):
        digest.update(path.relative_to(folder).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:12]


FOLDER = Path(__file__).parent
"""The reference implementation's folder."""
FINGERPRINT = source_fingerprint(FOLDER)
"""A hash of the source of every module of the reference implementation: the source stamp
of each of its functions in numba's cache (:func:`stamp_by_folder`)."""


class FolderStampedLocator(caching._CacheLocator):
    """numba's locator of a function's cache (the one numba would use, ``inner``) for a
    function of the reference implementation, whose source stamp is :data:`FINGERPRINT`."""

    def __init__(self, inner: Any) -> None:
        self._inner = inner

    def ensure_cache_path(self) -> None:
        self._inner.ensure_cache_path()

    def get_cache_path(self) -> str:
        return self._inner.get_cache_path()

    def get_source_stamp(self) -> Any:
        return ("truestep.reference_impl", FINGERPRINT)

    def get_disambiguator(self) -> str:
        return self._inner.get_disambiguator()

    @classmethod
    def from_function(cls, py_func: Any, py_file: str) -> FolderStampedLocator | None:
        """This locator for a function defined under :data:`FOLDER`, else ``None`` (numba
        goes on to its own locators)."""
        here = os.path.realpath(FOLDER)
        if not os.path.realpath(py_file).startswith(here + os.sep):
            return None
        others: list[Any] = caching.CacheImpl._locator_classes
        for other in others:
            if other is not cls:
                inner = other.from_function(py_func, py_file)
                if inner is not None:
                    return cls(inner)
        return None


def stamp_by_folder() -> None:
    """Put :class:`FolderStampedLocator` first among numba's cache locators (once per
    process)."""
    classes: list[Any] = caching.CacheImpl._locator_classes
    if FolderStampedLocator not in classes:
        classes.insert(0, FolderStampedLocator)
