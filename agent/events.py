"""What arrives in the agent's inbox: the only way other threads and signal handlers reach it.

All work happens on the agent's own thread; the brain's exit watcher, a connection attempt and
signal handlers only put one of these into the `Inbox`, which wakes the agent's loop.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class Connected:
    seq: int  # the seq of this connection, the one its Last Will carries


@dataclass(frozen=True)
class ConnectFailed:
    reason: str


@dataclass(frozen=True)
class Disconnected:
    reason: str


@dataclass(frozen=True)
class LaunchMessage:
    payload: bytes


@dataclass(frozen=True)
class StatusMessage:
    payload: bytes


@dataclass(frozen=True)
class RestartMessage:
    payload: bytes
    retained: bool  # delivered from the broker's retained store: never carried out


@dataclass(frozen=True)
class LogsMessage:
    payload: bytes


@dataclass(frozen=True)
class BrainExited:
    pid: int
    code: int


@dataclass(frozen=True)
class Shutdown:
    signal_name: str


Event = (
    Connected
    | ConnectFailed
    | Disconnected
    | LaunchMessage
    | StatusMessage
    | RestartMessage
    | LogsMessage
    | BrainExited
    | Shutdown
)


class Inbox:
    """Events for the agent's thread, plus a pipe its loop waits on (with the MQTT socket).

    `put` may be called from any thread and from a signal handler: a deque append and a
    one-byte write, both atomic. The agent's own thread uses `put_local`, which needs no wake-up.
    """

    def __init__(self) -> None:
        self._events: deque[Event] = deque()
        self._read_fd, self._write_fd = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        # Once closed, a late wake-up (a connection attempt ending after the agent) must not
        # write to a descriptor number that may belong to something else by then. Reentrant:
        # a signal handler may run while this thread holds it.
        self._closing = threading.RLock()
        self._closed = False

    def put(self, event: Event) -> None:
        self._events.append(event)
        self.wake()

    def put_local(self, event: Event) -> None:
        self._events.append(event)

    def wake(self) -> None:
        # A full pipe already wakes the loop: a lost byte loses nothing.
        with self._closing, contextlib.suppress(BlockingIOError, OSError):
            if not self._closed:
                os.write(self._write_fd, b"!")

    def fileno(self) -> int:
        return self._read_fd

    def clear_wakeups(self) -> None:
        with contextlib.suppress(BlockingIOError, OSError):
            while os.read(self._read_fd, 4096):
                pass

    def pop(self) -> Event | None:
        try:
            return self._events.popleft()
        except IndexError:
            return None

    def __bool__(self) -> bool:
        return bool(self._events)

    def close(self) -> None:
        with self._closing:
            if self._closed:
                return
            self._closed = True
            for fd in (self._read_fd, self._write_fd):
                with contextlib.suppress(OSError):
                    os.close(fd)
