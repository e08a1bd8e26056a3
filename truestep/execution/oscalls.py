"""Linux system calls the standard library lacks, through ctypes: exchanging two paths at
once (``renameat2`` with ``RENAME_EXCHANGE``), dying with the parent
(``prctl(PR_SET_PDEATHSIG)``), adopting orphaned descendants
(``prctl(PR_SET_CHILD_SUBREAPER)``) and backing memory with huge pages
(``madvise(MADV_COLLAPSE)``). Elsewhere they report that they are not available."""

from __future__ import annotations

import ctypes
import errno
import os
import signal
import sys
from functools import cache

AT_FDCWD = -100
RENAME_EXCHANGE = 2
PR_SET_PDEATHSIG = 1
PR_SET_CHILD_SUBREAPER = 36
MADV_COLLAPSE = 25
HUGE_PAGE = 2 << 20
"""The size of a transparent huge page on x86-64 and most arm64 kernels (bytes)."""


@cache
def _libc() -> ctypes.CDLL | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True)
    except OSError:
        return None


def exchange(a: os.PathLike | str, b: os.PathLike | str) -> bool:
    """Swap the directory entries ``a`` and ``b`` in one step (both must exist).

    ``False`` where the system or the file system cannot (no ``renameat2``, ``ENOSYS``,
    ``EINVAL``, ``ENOTSUP``); any other failure raises :class:`OSError`.
    """
    libc = _libc()
    fn = getattr(libc, "renameat2", None) if libc is not None else None
    if fn is None:
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    if fn(AT_FDCWD, os.fsencode(a), AT_FDCWD, os.fsencode(b), RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), os.fspath(a), None, os.fspath(b))


def die_with_parent(parent: int, sig: int = signal.SIGKILL) -> None:
    """In a child process: be sent ``sig`` (SIGKILL unless told) when the parent dies, and
    exit at once if ``parent`` (its pid before the fork) is already gone."""
    libc = _libc()
    if libc is not None:
        libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
    if os.getppid() != parent:
        os._exit(1)


def become_subreaper() -> bool:
    """Make this process the parent of every orphaned process below it (a descendant
    whose own parent exits, a daemon that double-forks) instead of ``init``, so that
    they stay in its tree to be found and killed; ``False`` where not available."""
    libc = _libc()
    return libc is not None and libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0


def anonymous_bytes() -> int:
    """This process's resident anonymous memory (bytes; ``RssAnon``), 0 where unknown."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("RssAnon:"):
                    return int(line.split()[1]) << 10
    except (OSError, ValueError):
        pass
    return 0


def collapse_to_huge_pages() -> int:
    """Back this process's private anonymous memory with transparent huge pages where the
    kernel can (``madvise(MADV_COLLAPSE)``, Linux 6.1 and later): each 2 MiB then takes
    one page-table entry instead of 512, so a ``fork`` of a process that holds every
    engine copies a few hundred entries, not ~10^5 (measured: 10 ms a fork down to 2.4 ms
    at 300 MiB). The contents do not change. Returns the bytes asked for in ranges the
    kernel accepted; 0 where it cannot (another system, an older kernel, huge pages off).
    """
    libc = _libc()
    if libc is None:
        return 0
    madvise = libc.madvise
    madvise.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    madvise.restype = ctypes.c_int
    collapsed = 0
    try:
        with open("/proc/self/maps", encoding="ascii", errors="replace") as maps:
            ranges = [line.split() for line in maps]
    except OSError:
        return 0
    for fields in ranges:
        anonymous = len(fields) < 6 or fields[5] == "[heap]"
        if len(fields) < 2 or fields[1] != "rw-p" or not anonymous:
            continue
        start, end = (int(x, 16) for x in fields[0].split("-"))
        start = (start + HUGE_PAGE - 1) & ~(HUGE_PAGE - 1)
        end &= ~(HUGE_PAGE - 1)
        if end > start and madvise(start, end - start, MADV_COLLAPSE) == 0:
            collapsed += end - start
    return collapsed
