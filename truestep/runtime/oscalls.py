"""Linux system calls the standard library lacks, through ctypes: exchanging two paths at
once (``renameat2`` with ``RENAME_EXCHANGE``), dying with the parent
(``prctl(PR_SET_PDEATHSIG)``) and adopting orphaned descendants
(``prctl(PR_SET_CHILD_SUBREAPER)``). Elsewhere they report that they are not available."""

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


QUIET_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
"""The signals a forked helper ends on at once, without a word (:func:`helper_of`)."""


def helper_of(parent: int) -> None:
    """In a forked helper (a compile beside the run): die with ``parent``
    (:func:`die_with_parent`), and end at once, printing nothing, on any of
    :data:`QUIET_SIGNALS`, where it would otherwise run the handler it inherited (truestep's,
    which raises, and a traceback of the helper follows the parent's one line)."""
    for sig in QUIET_SIGNALS:
        signal.signal(sig, signal.SIG_DFL)
    die_with_parent(parent)


def become_subreaper() -> bool:
    """Make this process the parent of every orphaned process below it (a descendant
    whose own parent exits, a daemon that double-forks) instead of ``init``, so that
    they stay in its tree to be found and killed; ``False`` where not available."""
    libc = _libc()
    return libc is not None and libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0
