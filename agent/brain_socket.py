"""The brain's socket (`brain.sock` in the work folder, mode 0600): the relay's edge.

Non-blocking and driven by the agent's one selector loop: the listener and each connection are
watched descriptors, and `service()` does at most one accept round and one read per connection
per pass, so a brain that floods never holds the loop (nor another robot's agent in the same
process). What it reads is bounded: `max_connections` at once (more are closed at once), lines
of `MAX_LINE_BYTES` (a longer one is skipped to its end), and `bytes_per_second` (a token
bucket: past it the connections are not read until it refills, so what the brain writes waits
in its own buffer and is the brain's to drop). What it refuses it counts; the lines it hands on
are the relay's (agent/relay.py) to judge.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import stat
from dataclasses import dataclass, field
from pathlib import Path

from robotconf.agent.relay import TokenBucket
from robotconf.contract.goals import MAX_LINE_BYTES

log = logging.getLogger("robotconf.agent")

MAX_CONNECTIONS = 4  # a brain's connections at once: the library holds one
BYTES_PER_SECOND = 256 * 1024  # read from one brain at most, all its connections together
READ_CHUNK = 64 * 1024  # one read of one connection in one pass
ACCEPTS_PER_PASS = 8
MAX_SOCKET_PATH = 107  # bytes of a Unix socket's path (sun_path, with its NUL)


@dataclass
class _Connection:
    sock: socket.socket
    serial: int
    buffer: bytearray = field(default_factory=bytearray)
    skipping: bool = False  # inside a line over MAX_LINE_BYTES: dropped up to its end


@dataclass
class Taken:
    """What one pass read: whole lines in order, and how many things were refused."""

    lines: list[bytes] = field(default_factory=list)
    refused: int = 0


class BrainSocket:
    """The listening socket and the brain's connections to it."""

    def __init__(
        self,
        path: Path,
        max_connections: int = MAX_CONNECTIONS,
        bytes_per_second: int = BYTES_PER_SECOND,
    ) -> None:
        self.path = path
        self.max_connections = max_connections
        self.listener: socket.socket | None = None
        self.error: str | None = None
        self.accepting = False  # only while a brain runs
        self._connections: dict[int, _Connection] = {}  # fd -> connection
        self._serial = 0
        self._bytes = TokenBucket(bytes_per_second, bytes_per_second)

    # ------------------------------------------------------------ lifecycle

    def open(self) -> str | None:
        """Creates the socket before any brain starts: a stale one (a previous agent's) is
        removed, the new one is the agent user's only (0600). What went wrong, if anything:
        then goals are not relayed, and the brain runs as before."""
        path = self.path
        if len(os.fsencode(path)) > MAX_SOCKET_PATH:
            self.error = (
                f"cannot create the brain's socket {path}: the path is longer than "
                f"{MAX_SOCKET_PATH} bytes (a Unix socket's limit); choose a shorter workdir"
            )
            return self.error
        try:
            self._remove_stale()
            listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        except OSError as exc:
            self.error = f"cannot create the brain's socket {path}: {exc.strerror or exc}"
            return self.error
        try:
            listener.setblocking(False)
            # Bound under a umask that leaves only the owner's bits: never, even for a moment,
            # a socket others may connect to (the workdir is 0700 as well).
            old = os.umask(0o177)
            try:
                listener.bind(os.fsdecode(path))
            finally:
                os.umask(old)
            os.chmod(path, 0o600)
            listener.listen(ACCEPTS_PER_PASS)
        except OSError as exc:
            listener.close()
            self.error = f"cannot create the brain's socket {path}: {exc.strerror or exc}"
            return self.error
        self.listener = listener
        self.error = None
        return None

    def _remove_stale(self) -> None:
        try:
            info = os.lstat(self.path)
        except FileNotFoundError:
            return
        if stat.S_ISDIR(info.st_mode):
            raise IsADirectoryError(21, "a directory is in its place", str(self.path))
        os.unlink(self.path)

    def close(self) -> None:
        self.drop_connections()
        if self.listener is not None:
            self.listener.close()
            self.listener = None
            with contextlib.suppress(OSError):
                os.unlink(self.path)

    def drop_connections(self) -> None:
        """Closes every connection: the brain that made them is gone."""
        for connection in self._connections.values():
            connection.sock.close()
        self._connections.clear()

    # ------------------------------------------------------------ the loop

    def watches(self, now: float) -> dict[int, object]:
        """fd -> identity: the listener, and the connections unless the byte budget is spent."""
        wanted: dict[int, object] = {}
        if self.listener is not None:
            wanted[self.listener.fileno()] = "brain-socket"
        if self._connections and self._bytes.available(now) > 0:
            for fd, connection in self._connections.items():
                wanted[fd] = ("brain-connection", connection.serial)
        return wanted

    def owns(self, fd: int) -> bool:
        """Whether `fd` is the listener's or a connection's."""
        listener = self.listener
        return fd in self._connections or (listener is not None and fd == listener.fileno())

    def due(self, now: float) -> float | None:
        """When the connections are read again after the byte budget ran out."""
        if self._connections and self._bytes.available(now) <= 0:
            return self._bytes.ready_at(now)
        return None

    def service(self, ready: set[int], now: float) -> Taken:
        """One pass over what the selector found ready."""
        taken = Taken()
        if self.listener is not None and self.listener.fileno() in ready:
            self._accept(taken)
        for fd in [fd for fd in self._connections if fd in ready]:
            self._read(self._connections[fd], taken, now)
        return taken

    def _accept(self, taken: Taken) -> None:
        assert self.listener is not None
        for _ in range(ACCEPTS_PER_PASS):
            try:
                sock, _ = self.listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # EMFILE and the like: the loop goes on, the brain retries
                log.warning("cannot accept the brain's connection: %s", exc.strerror or exc)
                return
            if not self.accepting or len(self._connections) >= self.max_connections:
                sock.close()
                taken.refused += 1
                continue
            sock.setblocking(False)
            self._serial += 1
            self._connections[sock.fileno()] = _Connection(sock, self._serial)

    def _read(self, connection: _Connection, taken: Taken, now: float) -> None:
        budget = min(READ_CHUNK, self._bytes.available(now))
        if budget <= 0:
            return
        try:
            data = connection.sock.recv(budget)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._connections.pop(connection.sock.fileno(), None)
            connection.sock.close()
            return
        self._bytes.take(now, len(data))
        taken.refused += split_lines(connection, data, taken.lines)

    @property
    def connections(self) -> int:
        return len(self._connections)


def split_lines(connection: _Connection, data: bytes, out: list[bytes]) -> int:
    """Appends the whole lines `data` completes to `out`; returns how many were too long."""
    refused = 0
    parts = data.split(b"\n")
    buffer = connection.buffer
    for part in parts[:-1]:
        if connection.skipping:
            connection.skipping = False  # the end of the over-long line
        elif len(buffer) + len(part) > MAX_LINE_BYTES:
            refused += 1
        else:
            line = bytes(buffer + part) if buffer else part
            line = line.rstrip(b"\r")
            if line.strip():
                out.append(line)
        buffer.clear()
    tail = parts[-1]
    if connection.skipping:
        return refused
    if len(buffer) + len(tail) > MAX_LINE_BYTES:
        refused += 1
        connection.skipping = True
        buffer.clear()
    else:
        buffer += tail
    return refused
