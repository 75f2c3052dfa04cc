"""The agent's work directory: its file names, the persisted `seq` and a lock.

Everything the agent must remember across its own restarts lives here, nowhere else.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import sys
import threading
import time
from pathlib import Path

from robotconf.contract.files import write_atomic
from robotconf.contract.pidlock import PidLock
from robotconf.contract.trust import euid, owner_trusted

__all__ = ["write_atomic"]  # kept here too: the agent's modules import it from its workdir

REQUEST_FILE = "launch-request.json"
STAGED_FILE = "launch-request.json.next"  # the next request, written before the old brain stops
LOG_FILE = "brain.log"
PID_FILE = "brain.pid"
SEQ_FILE = "agent.seq"
LOCK_FILE = "agent.lock"
ISSUED_FILE = "newest-issued-at"
RESTART_ISSUED_FILE = "newest-restart-issued-at"  # the restarts' watermark (RestartLedger)
RESTARTS_AHEAD_FILE = "restarts-ahead"  # restarts carried out that were dated ahead of the clock
SOCKET_FILE = "brain.sock"  # the brain's reports (ROBOTCONF_BRAIN_SOCKET), mode 0600
HOLD_FILE = "brain.hold"  # the brain's "not now" (ROBOTCONF_HOLD_FILE): defers a stop


def hold_exists(path: Path) -> bool:
    """Whether the brain holds: `path` exists as anything at all (a file, a directory, a
    symlink, even a dangling one), looked at with lstat and never followed or read. A look
    that fails for another reason than absence counts as held: max_defer bounds it. One that
    another user owns is no hold: only the brain (the agent's user) or root may defer a stop
    (contract/trust.py)."""
    try:
        info = os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        return False
    except OSError:
        return True
    return owner_trusted(info.st_uid, euid())


def remove_hold(path: Path) -> str | None:
    """Removes a hold a previous brain left, of any kind (it must not defer its successor's
    first stop); what went wrong, if anything. A symlink is removed, never followed; a
    directory with all it holds, its descriptors walked without following a symlink (the
    brain's own scratch, in the agent's own work directory). A tree that cannot be removed
    is renamed aside (`brain.hold.stale-*`, said in the answer), so the brain is not born held."""
    try:
        os.unlink(path)
    except FileNotFoundError:
        return None
    except IsADirectoryError:
        return _remove_hold_tree(path)
    except OSError as exc:
        return f"cannot remove the hold file {path}: {exc.strerror}"
    return None


def _remove_hold_tree(path: Path) -> str | None:
    failed: list[str] = []

    def note(name: str, exc: BaseException) -> None:
        failed.append(f"{name}: {getattr(exc, 'strerror', None) or exc}")

    if not shutil.rmtree.avoids_symlink_attacks:  # Linux has the fd-based walk
        failed.append("no safe way to remove a tree here")
    elif sys.version_info >= (3, 12):
        shutil.rmtree(path, onexc=lambda _f, name, exc: note(name, exc))
    else:
        shutil.rmtree(path, onerror=lambda _f, name, info: note(name, info[1]))
    if not os.path.lexists(path):
        return None
    why = failed[0] if failed else "made again meanwhile"
    aside = path.with_name(f"{path.name}.stale-{time.time_ns()}")
    try:
        os.rename(path, aside)
    except OSError as exc:
        return f"cannot remove the hold directory {path}: {exc.strerror} ({why})"
    return f"cannot remove all of the hold directory {path} ({why}): renamed to {aside.name}"


class SeqStore:
    """The connection counter (`seq`, docs/architecture.md#the-mqtt-contract), persisted so a
    restarted agent keeps counting up.

    `advance()` runs on paho's network thread right before each connection attempt, the
    agent's thread reads `current`: hence the lock.
    """

    def __init__(self, path: Path) -> None:
        self._path = path
        self._lock = threading.Lock()
        self._current = self._read()
        self._floor = self._current

    def _read(self) -> int:
        try:
            return max(0, int(self._path.read_text(encoding="ascii").strip()))
        except (OSError, ValueError):
            return 0

    @property
    def current(self) -> int:
        with self._lock:
            return self._current

    def observe(self, seq: int) -> None:
        """A seq seen on the broker: the next connection must count past it."""
        with self._lock:
            self._floor = max(self._floor, seq)

    def advance(self) -> int:
        with self._lock:
            self._current = max(self._current, self._floor) + 1
            value = self._current
        # Losing the file only weakens late-will detection after a restart; keep connecting.
        with contextlib.suppress(OSError):
            write_atomic(self._path, f"{value}\n".encode("ascii"), mode=0o644)
        return value


class IssuedStore:
    """The issue time of the newest signed request accepted (or restart carried out), kept
    across agent restarts so that an old, validly signed one replayed later does nothing."""

    def __init__(self, path: Path) -> None:
        self._path = path
        try:
            self.newest: float | None = float(path.read_text(encoding="ascii").strip())
        except (OSError, ValueError):
            self.newest = None

    def accepted(self, issued_at: float | None) -> None:
        if issued_at is None or (self.newest is not None and issued_at <= self.newest):
            return
        self.newest = issued_at
        # Losing the file weakens replay protection only across a restart; keep working.
        with contextlib.suppress(OSError):
            write_atomic(self._path, f"{issued_at!r}\n".encode("ascii"), mode=0o600)


class RestartLedger:
    """The restarts carried out, as replay protection needs them across agent restarts: the
    watermark (one number, in the file older agents wrote) and those dated ahead of the robot's
    clock (`issued_at requested_by`, one a line). Both fsynced."""

    def __init__(self, workdir: Path) -> None:
        self._watermark_path = workdir / RESTART_ISSUED_FILE
        self._ahead_path = workdir / RESTARTS_AHEAD_FILE
        numbers = [n for n, _ in _read_entries(self._watermark_path)]
        self.watermark: float | None = numbers[0] if numbers else None
        self.ahead: frozenset[tuple[float, str]] = frozenset(
            (issued, by) for issued, by in _read_entries(self._ahead_path) if by
        )

    def record(self, watermark: float | None, ahead: frozenset[tuple[float, str]]) -> None:
        """Remembers a new state, in an order that leaves the files refusing more, never less,
        should the agent die between two writes: what is added first, what is forgotten last."""
        union = self.ahead | ahead
        if union != self.ahead:
            self._write_ahead(union)
        if watermark is not None and watermark != self.watermark:
            self.watermark = watermark
            _write_quietly(self._watermark_path, f"{watermark!r}\n")
        if ahead != union:
            self._write_ahead(ahead)  # what the watermark or the age limit refuses anyway

    def _write_ahead(self, ahead: frozenset[tuple[float, str]]) -> None:
        self.ahead = ahead
        text = "".join(f"{issued!r} {by}\n" for issued, by in sorted(ahead))
        _write_quietly(self._ahead_path, text)


def _write_quietly(path: Path, text: str) -> None:
    # Losing the file weakens replay protection only across a restart; keep working.
    with contextlib.suppress(OSError):
        write_atomic(path, text.encode("ascii"), mode=0o600)


def _read_entries(path: Path) -> list[tuple[float, str]]:
    """`number [word]` lines of a file (a finite number); none when it is missing or damaged."""
    try:
        entries = [
            (float(number), rest.strip())
            for number, _, rest in (
                line.strip().partition(" ")
                for line in path.read_text(encoding="ascii").splitlines()
                if line.strip()
            )
        ]
    except (OSError, ValueError, UnicodeDecodeError):
        return []
    return [(n, word) for n, word in entries if math.isfinite(n)]


class WorkdirLock(PidLock):
    """One agent per work directory: a second one would take the first one's brain for an orphan."""

    def __init__(self, workdir: Path) -> None:
        super().__init__(workdir / LOCK_FILE)

    def acquire(self) -> str | None:
        """None when acquired, else why not."""
        holder = self.take()
        if holder is None:
            return None
        return f"another agent (pid {holder}) is using {self.path.parent}"
