"""What arrives in the agent's inbox: the only way other threads and signal handlers reach it.

All work happens on the agent's own thread; the network thread and the brain's waiter
thread only put one of these into a `queue.SimpleQueue` (safe even from a signal handler).
"""

from __future__ import annotations

import queue
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
    | BrainExited
    | Shutdown
)
Inbox = queue.SimpleQueue[Event]
