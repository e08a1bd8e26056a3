"""Reading a file that someone handed over: a regular file only, its size capped before a
byte is read.

Every path truestep opens for reading (case files, gates files, tables, baselines, the
checkpoints of an interrupted run, the marker of a report folder) goes through
:func:`read_regular`. A FIFO would block the read forever, a link to ``/dev/zero`` or
``/dev/urandom`` would never end it, and a sparse file of terabytes would exhaust the
memory: each is refused with one line (:class:`FileRefused`) before it is opened for
reading, and a file that grows past the cap while it is read is refused as well.
"""

from __future__ import annotations

import errno
import os
import stat


class FileRefused(OSError):
    """A path that is not read: missing, not a regular file, or over its size cap.

    ``str(err)`` is one line, ``"<path>: <reason>"``; ``reason`` alone is in
    :attr:`reason`.
    """

    def __init__(self, path: str | os.PathLike, reason: str) -> None:
        self.path, self.reason = os.fspath(path), reason
        super().__init__(f"{self.path}: {reason}")

    def __str__(self) -> str:
        return f"{self.path}: {self.reason}"


def _kind(mode: int) -> str:
    """What a non-regular file is, in words."""
    for test, name in (
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISLNK, "a symbolic link"),
    ):
        if test(mode):
            return name
    return "not a regular file"


def _size(n: int) -> str:
    return f"{n / 2**20:.1f} MiB" if n >= 2**20 else f"{n} bytes"


def read_regular(path: str | os.PathLike, cap: int, *, follow_links: bool = True) -> bytes:
    """The bytes of the regular file ``path``, at most ``cap`` of them.

    Symbolic links are followed (``follow_links=False``: a link is refused), but what
    they lead to must be a regular file. The file is checked before it is opened, opened
    without blocking (a FIFO swapped in meanwhile cannot hang the open), checked again
    on the open descriptor, and read up to ``cap + 1`` bytes. Raises
    :class:`FileRefused` (one line) for a missing path, anything but a regular file, a
    file over ``cap`` bytes, or a read that fails.
    """
    path = os.fspath(path)
    try:
        st = os.stat(path) if follow_links else os.lstat(path)
    except FileNotFoundError:
        raise FileRefused(path, "no such file") from None
    except OSError as err:
        raise FileRefused(path, f"cannot be read: {err.strerror or err}") from None
    if not stat.S_ISREG(st.st_mode):
        raise FileRefused(path, f"is {_kind(st.st_mode)}, not a regular file: not read")
    if st.st_size > cap:
        raise FileRefused(path, f"{_size(st.st_size)}, over the {_size(cap)} this file may have")
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    if not follow_links:
        flags |= getattr(os, "O_NOFOLLOW", 0)
    try:
        fd = os.open(path, flags)
    except OSError as err:
        if err.errno == errno.ELOOP:
            raise FileRefused(path, "is a symbolic link: not read") from None
        raise FileRefused(path, f"cannot be read: {err.strerror or err}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise FileRefused(path, f"is {_kind(st.st_mode)}, not a regular file: not read")
        chunks, total = [], 0
        while total <= cap:
            chunk = os.read(fd, min(1 << 20, cap + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
    except OSError as err:
        if isinstance(err, FileRefused):
            raise
        raise FileRefused(path, f"cannot be read: {err.strerror or err}") from None
    finally:
        os.close(fd)
    if total > cap:
        raise FileRefused(path, f"grew past the {_size(cap)} this file may have while it was read")
    return b"".join(chunks)


def is_regular(path: str | os.PathLike) -> bool:
    """Whether ``path`` leads to a regular file (links followed), without opening it."""
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False


__all__ = ["FileRefused", "is_regular", "read_regular"]
