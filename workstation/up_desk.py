"""`robotconf up`'s desk file: where its broker, login and signing key are, so that `status`,
`logs`, `restart` and `draft` find them without options; trusted only when it is the user's own
(docs/how-to/production-broker.md#files-checked-before-trusted) and only while that `up` runs.

Liveness is proven by nothing the file says: `up` holds an exclusive flock on the desk file
itself for as long as it runs (the kernel drops it when `up` dies), and a reader asks the
kernel about the very file it read.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import stat
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from robotconf.contract.trust import Trust, UntrustedFile, euid, folder_refusal, open_trusted

DESK_FILE = Path(".robotconf") / "up" / "desk.json"
MAX_DESK_BYTES = 16 * 1024  # a few paths; anything larger is not up's
_PATHS = ("password_file", "signing_key", "ca_file", "cert_file", "key_file")
OwnerOf = Callable[[Path], int]  # a folder's owner (os.lstat; a stand-in in unit tests)


@dataclass(frozen=True)
class UpDesk:
    """What a desk command needs to reach a running `up`: a URL and paths, never a secret."""

    broker: str
    prefix: str
    pid: int  # the `up` that wrote it, for the notes; its liveness is the file's lock
    username: str | None = None
    password_file: Path | None = None
    signing_key: Path | None = None
    ca_file: Path | None = None
    cert_file: Path | None = None
    key_file: Path | None = None
    insecure: bool = False

    def as_json(self) -> dict[str, Any]:
        found: dict[str, Any] = {
            "broker": self.broker,
            "prefix": self.prefix,
            "pid": self.pid,
            "username": self.username,
            "insecure": self.insecure,
        }
        for name in _PATHS:
            value = getattr(self, name)
            found[name] = None if value is None else str(value)
        return found


class DeskLease:
    """A written desk file and the exclusive flock `up` holds on it while it runs."""

    def __init__(self, path: Path, fd: int) -> None:
        self.path = path
        self._fd: int | None = fd

    def remove(self) -> None:
        """Removes the desk file when it is still this one (another `up` may have written its
        own since), then lets go of the lock."""
        if self._fd is None:
            return
        with contextlib.suppress(OSError):
            if os.path.samestat(os.lstat(self.path), os.fstat(self._fd)):
                self.path.unlink()
        self.release()

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def write_desk(root: Path, desk: UpDesk) -> DeskLease:
    """Writes `root`'s desk file (0600, replaced whole so that no reader sees half of it),
    locked before it is in place: no reader ever finds it unlocked while this `up` runs."""
    path = root / DESK_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.name}.{os.getpid()}")
    partial.unlink(missing_ok=True)
    fd = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # a new file: nobody else holds it
    text = json.dumps(desk.as_json(), indent=2) + "\n"
    view = memoryview(text.encode("utf-8"))
    while view:
        view = view[os.write(fd, view) :]
    os.replace(partial, path)
    return DeskLease(path, fd)


def find_desk(start: Path, *, owner_of: OwnerOf | None = None) -> tuple[UpDesk | None, str | None]:
    """The desk file of a running `up` in `start` or a folder above it, else None; and a note
    when a file was found but not trusted (not the user's own, its `up` is not running, or
    unreadable). The walk stops at a folder neither the user nor root owns, as git's
    safe.directory does: another user's folder may hold a file planted for the user."""
    owner = owner_of or (lambda folder: os.lstat(folder).st_uid)
    me = euid()
    start = start.absolute()
    for folder in (start, *start.parents):
        try:
            refused = folder_refusal(owner(folder), me, str(folder))
        except OSError:
            return None, None
        if refused is not None:
            return None, _planted(folder, refused)
        path = folder / DESK_FILE
        if not os.path.lexists(path):
            continue
        return _judge(path, owner, me)
    return None, None


def _planted(folder: Path, refused: str) -> str | None:
    """A note when the folder the walk stopped at holds a desk file (else silence)."""
    if os.path.lexists(folder / DESK_FILE):
        return f"{_shown(folder / DESK_FILE)} ignored: {refused}"
    return None


def _judge(path: Path, owner: OwnerOf, me: int) -> tuple[UpDesk | None, str | None]:
    shown = _shown(path)
    for folder in (path.parent.parent, path.parent):  # .robotconf, .robotconf/up
        refused = _folder_problem(folder, owner, me)
        if refused is not None:
            return None, f"{shown} ignored: {refused}"
    try:
        fd = open_trusted(path, Trust.CONFIG, MAX_DESK_BYTES, follow=False)
    except UntrustedFile as exc:
        return None, f"{shown} {exc}; ignored"
    except OSError as exc:
        return None, f"cannot read {shown} ({exc.strerror}); ignored"
    try:
        desk = _parse(fd)
        if desk is None:
            return None, f"{shown} is not robotconf up's desk file: ignored"
        if not _held(fd):
            return None, (
                f"{shown} is stale: the robotconf up that wrote it (pid {desk.pid}) is not "
                "running; ignored"
            )
        return desk, None
    finally:
        os.close(fd)


def _folder_problem(folder: Path, owner: OwnerOf, me: int) -> str | None:
    try:
        mode = os.lstat(folder).st_mode
        if not stat.S_ISDIR(mode):
            return f"{folder} is not a folder (a link?): a desk file is only looked for in one"
        return folder_refusal(owner(folder), me, str(folder))
    except OSError as exc:
        return f"cannot look at {folder} ({exc.strerror})"


def _parse(fd: int) -> UpDesk | None:
    try:
        raw = os.pread(fd, MAX_DESK_BYTES + 1, 0)
        data = json.loads(raw) if len(raw) <= MAX_DESK_BYTES else None
        if not isinstance(data, dict):
            return None
        paths = {name: Path(data[name]) if data.get(name) else None for name in _PATHS}
        return UpDesk(
            broker=str(data["broker"]),
            prefix=str(data["prefix"]),
            pid=int(data["pid"]),
            username=str(data["username"]) if data.get("username") else None,
            insecure=data.get("insecure") is True,
            **paths,
        )
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _held(fd: int) -> bool:
    """True while some process holds the exclusive lock `up` takes on this very file: only a
    process that could open the user's own 0600 file can, and the kernel drops a dead
    holder's lock, so a killed `up` is never taken for a running one."""
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return False
    fcntl.flock(fd, fcntl.LOCK_UN)
    return False


def _shown(path: Path) -> str:
    with contextlib.suppress(ValueError):
        return str(path.relative_to(Path.cwd()))
    return str(path)
