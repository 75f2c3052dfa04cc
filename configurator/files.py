"""Atomic, private file writes: readers see the old file or the new one, never a half of it.

Used by the agent (requests, pidfile, counters) and by the commands that write secrets.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import tempfile
from pathlib import Path


def write_atomic(path: Path, data: bytes, mode: int = 0o600, *, durable: bool = True) -> None:
    """Readers see the old file or the new one, never a half-written one.

    `durable=False` skips the fsyncs, for files that mean nothing after a power cut anyway
    (a pidfile names a process of the previous boot; a launch request is sent again): on a
    robot's SD card each fsync can cost tens of milliseconds of a restart.
    """
    fd, tmp = _create_temp(path)
    try:
        try:
            os.fchmod(fd, mode)
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            if durable:
                os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    if not durable:
        return
    # The rename itself must survive a power cut too.
    dir_fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


_temp_ids = itertools.count()
_TEMP_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC


def _create_temp(path: Path) -> tuple[int, str]:
    """A new private file beside `path`: named by process and counter (no random names to
    draw on every write), with mkstemp for the rare leftover of a dead process."""
    tmp = f"{path.parent}/.{path.name}.{os.getpid()}-{next(_temp_ids)}.tmp"
    try:
        return os.open(tmp, _TEMP_FLAGS, 0o600), tmp
    except FileExistsError:
        return tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
