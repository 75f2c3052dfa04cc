"""A pid-file lock: one holder per file (an agent per work directory, an `up` per folder), held
with flock so that the kernel drops it when its holder dies and a held lock is never stale; the
holder's pid is written in it for whoever finds it held."""

from __future__ import annotations

import fcntl
import os
from pathlib import Path


class PidLock:
    """The lock on `path`, taken by this process with `take` until `release`."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fd: int | None = None

    def take(self) -> str | None:
        """None when this process holds the lock now (its pid written in the file); else the
        pid its holder wrote ("?" before it has written it). Raises OSError when the file
        cannot be opened."""
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "?"
            os.close(fd)
            return holder
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
        self._fd = fd
        return None

    def holder(self) -> int | None:
        """The pid of the lock's holder (0 if it has not written it yet), None when nobody
        holds it or there is no lock file."""
        try:
            return lock_holder(self.path)
        except FileNotFoundError:
            return None

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def lock_holder(path: Path) -> int | None:
    """The pid written in a held flock file (0 if not written yet), None when nobody holds it:
    the kernel drops the lock of a dead holder, so a held lock is never stale. Raises OSError
    when the file cannot be opened."""
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError:
            raw = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
            return int(raw) if raw.isdigit() else 0
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)
