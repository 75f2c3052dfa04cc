"""`robotconf up`'s desk file: where its broker, login and signing key are, so that `status`,
`logs`, `restart` and `draft` find them without options; trusted only while that `up` runs."""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

DESK_FILE = Path(".robotconf") / "up" / "desk.json"
MAX_DESK_BYTES = 16 * 1024  # a few paths; anything larger is not up's
_PATHS = ("password_file", "signing_key", "ca_file", "cert_file", "key_file")


@dataclass(frozen=True)
class UpDesk:
    """What a desk command needs to reach a running `up`: a URL and paths, never a secret."""

    broker: str
    prefix: str
    pid: int
    lock: Path  # up's lock file: held by that `up` for as long as it runs
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
            "lock": str(self.lock),
            "username": self.username,
            "insecure": self.insecure,
        }
        for name in _PATHS:
            value = getattr(self, name)
            found[name] = None if value is None else str(value)
        return found


def write_desk(root: Path, desk: UpDesk) -> Path:
    """Writes `root`'s desk file (0600, replaced whole so that no reader sees half of it)."""
    path = root / DESK_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.name}.{os.getpid()}")
    partial.unlink(missing_ok=True)
    fd = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as out:
        json.dump(desk.as_json(), out, indent=2)
        out.write("\n")
    os.replace(partial, path)
    return path


def remove_desk(root: Path, pid: int) -> None:
    """Removes the desk file when it is still this `up`'s (another may have written it since)."""
    path = root / DESK_FILE
    found = _read(path)
    if found is not None and found.pid == pid:
        path.unlink(missing_ok=True)


def find_desk(start: Path) -> tuple[UpDesk | None, str | None]:
    """The desk file of a running `up` in `start` or a folder above it, else None; and a note
    when a file was found but not trusted (its `up` is not running, or it is unreadable)."""
    start = start.absolute()
    for folder in (start, *start.parents):
        path = folder / DESK_FILE
        if not path.is_file():
            continue
        shown = _shown(path)
        desk = _read(path)
        if desk is None:
            return None, f"{shown} is not robotconf up's desk file: ignored"
        if not _running(desk):
            return None, (
                f"{shown} is stale: the robotconf up that wrote it (pid {desk.pid}) is not "
                "running; ignored"
            )
        return desk, None
    return None, None


def _read(path: Path) -> UpDesk | None:
    try:
        with path.open("rb") as source:
            raw = source.read(MAX_DESK_BYTES + 1)
        data = json.loads(raw) if len(raw) <= MAX_DESK_BYTES else None
        if not isinstance(data, dict):
            return None
        paths = {name: Path(data[name]) if data.get(name) else None for name in _PATHS}
        return UpDesk(
            broker=str(data["broker"]),
            prefix=str(data["prefix"]),
            pid=int(data["pid"]),
            lock=Path(data["lock"]),
            username=str(data["username"]) if data.get("username") else None,
            insecure=data.get("insecure") is True,
            **paths,
        )
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _running(desk: UpDesk) -> bool:
    """True while the `up` that wrote `desk` holds its lock: the kernel drops a flock when its
    holder dies, so a killed `up` is never taken for a running one."""
    from contract.pidlock import lock_holder

    try:
        return lock_holder(desk.lock) == desk.pid
    except OSError:
        return False


def _shown(path: Path) -> str:
    with contextlib.suppress(ValueError):
        return str(path.relative_to(Path.cwd()))
    return str(path)
