"""One ``truestep run`` per output folder: a lock file beside ``--out``.

``.<name>.lock`` beside the folder (symbolic links resolved, so two spellings of one
folder share it) is locked with ``flock`` for the whole run and holds the pid, start
time and command of the run that holds it. A second run on the same folder is refused at
once with one line naming the first (:class:`LockBusy`). The kernel drops the lock when
its process dies, however it dies: a lock file left by a killed run is taken over (and
``--resume`` of that run works). The lock is taken on the file's open description, so
the forked children of the run share it without holding it after the run is gone; the
file is removed when the run ends.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import stat
import sys
import time
from pathlib import Path

from truestep.runtime.files import FileRefused, read_regular
from truestep.runtime.publish import beside

MAX_LOCK_BYTES = 4096
"""The most read of a lock file, for the line that names the run holding it."""


class LockBusy(Exception):
    """Another run holds the lock; ``str()`` is one line naming it."""


def lock_path(out: Path) -> Path:
    """``.<name>.lock`` beside ``out`` (symbolic links resolved)."""
    return beside(out, "lock")


def _holder(path: Path) -> str:
    """Who holds the lock at ``path``, as the run wrote it there."""
    try:
        info = json.loads(read_regular(path, MAX_LOCK_BYTES, follow_links=False))
        pid, started = int(info["pid"]), float(info["started"])
    except (FileRefused, ValueError, KeyError, TypeError):
        return "another truestep run (it has not said which yet)"
    when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(started))
    return f"truestep run pid {pid}, started {when}"


class RunLock:
    """The lock of one output folder, held from :meth:`acquire` to :meth:`release`."""

    def __init__(self, out: Path) -> None:
        self.out = Path(os.path.realpath(out))
        self.path = lock_path(out)
        self.fd: int | None = None
        self.took_over: int | None = None

    def acquire(self) -> None:
        """Take the lock or raise :class:`LockBusy` at once. A lock file whose run is gone
        is taken over (its pid is kept in :attr:`took_over`)."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
            except OSError as err:
                if err.errno == errno.ELOOP:
                    raise LockBusy(
                        f"{self.path} is a symbolic link, not truestep's lock file; remove it"
                    ) from None
                raise
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode) or st.st_nlink != 1:
                os.close(fd)
                what = "a hard link to another file" if stat.S_ISREG(st.st_mode) else "not a regular file"
                raise LockBusy(f"{self.path} is {what}, not truestep's lock file; remove it")
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                raise LockBusy(
                    f"{self.out} is in use by {_holder(self.path)}: one run per --out at a time"
                ) from None
            except OSError:
                os.close(fd)
                raise
            try:  # the file may have been removed by its holder between open and flock
                same = os.fstat(fd).st_ino == os.lstat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        self.took_over = self._previous(fd)
        record = json.dumps(
            {"pid": os.getpid(), "started": time.time(), "argv": [a[:200] for a in sys.argv[:20]]}
        ).encode()
        os.ftruncate(fd, 0)
        os.pwrite(fd, record, 0)
        self.fd = fd

    @staticmethod
    def _previous(fd: int) -> int | None:
        """The pid a run that is gone left in the lock file, if any."""
        try:
            info = json.loads(os.pread(fd, MAX_LOCK_BYTES, 0) or b"{}")
            pid = int(info["pid"])
        except (ValueError, KeyError, TypeError, OSError):
            return None
        return pid if pid != os.getpid() else None

    def release(self) -> None:
        """Remove the lock file and let go of the lock (idempotent)."""
        if self.fd is None:
            return
        try:
            if os.fstat(self.fd).st_ino == os.lstat(self.path).st_ino:
                self.path.unlink()
        except OSError:
            pass
        os.close(self.fd)
        self.fd = None

    def __enter__(self) -> RunLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
