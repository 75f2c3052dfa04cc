"""Safe file access: atomic private writes (readers see the old file or the new one, never a
half of it) and bounded reads of regular files only (never through a link, never a FIFO).

Used by the agent (requests, pidfile, counters), the repository reader and the
commands that write secrets.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import stat
import tempfile
from pathlib import Path


class NotRegularFile(OSError):
    """Refused without reading: a link, FIFO, device or socket, or over the size limit."""


def file_kind(mode: int) -> str | None:
    """What a non-regular entry is, in words; None for a regular file or a folder."""
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return None


def read_regular(path: Path, limit: int, *, follow: bool = False) -> bytes:
    """The bytes of a regular file of at most `limit` bytes; NotRegularFile otherwise.

    O_NONBLOCK so that a FIFO is refused, not waited on; without `follow`, O_NOFOLLOW so that a
    link swapped in since the caller looked is refused, not followed. The size is checked
    before anything is read."""
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    if not follow:
        flags |= os.O_NOFOLLOW
    fd = os.open(path, flags)
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            kind = file_kind(info.st_mode) or "a folder"
            raise NotRegularFile(f"is {kind}, not a regular file")
        if info.st_size > limit:
            raise NotRegularFile(f"is {info.st_size:,} bytes, over the limit of {limit:,}")
        with os.fdopen(fd, "rb", closefd=False) as stream:
            data = stream.read(limit + 1)
        if len(data) > limit:
            raise NotRegularFile(f"is over the limit of {limit:,} bytes")
        return data
    finally:
        os.close(fd)


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
