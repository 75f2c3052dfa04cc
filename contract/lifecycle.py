"""Long-running commands' process setup: stop signals, where the logs go, addresses to listen at."""

from __future__ import annotations

import logging
import queue
import re
import signal
import sys
import threading
from collections.abc import Callable, Iterable
from pathlib import Path
from types import FrameType

from robotconf.contract.logsafe import SafeFormatter

_PORT = re.compile(r"[0-9]{1,5}")


def on_stop_signals(
    stop: threading.Event | None = None,
    callback: Callable[[], None] | None = None,
    again: Callable[[], None] | None = None,
    signals: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP),
) -> None:
    """SIGINT, SIGTERM and SIGHUP (the terminal was closed) end the command cleanly instead
    of raising in a random place or, for SIGHUP, killing it without its cleanup; a second one
    calls `again` (for those who will not wait) when given. `signals` narrows which (a brain
    keeps SIGHUP for reloads). Call it on the main thread.

    The handler only queues the signal (`queued_signals`); a thread of its own sets `stop`
    and calls the callbacks. Run in the handler, they would take locks on the main thread,
    interrupted wherever it was: inside an Event's wait on that same event (the lock held
    between two bytecodes), `stop.set()` waited for itself forever and a SIGTERM never
    stopped the process."""
    received = queued_signals(signals)

    def act() -> None:
        while True:
            signum = received.get()
            if stop is not None and stop.is_set():
                # A closed terminal may send SIGHUP twice (the kernel, then the shell): no hurry.
                if again is not None and signum != signal.SIGHUP:
                    again()
                continue
            if stop is not None:
                stop.set()
            if callback is not None:
                callback()

    threading.Thread(target=act, name="robotconf-stop-signals", daemon=True).start()


def queued_signals(signals: Iterable[signal.Signals]) -> queue.SimpleQueue[int]:
    """`signals` handled by putting each on the queue returned, and nothing else: whoever
    acts on them takes them from there. SimpleQueue.put is reentrant (the standard library
    says so), so the handler may land anywhere, even inside itself; an Event set or a flag
    tested in a handler may not. Call it on the main thread."""
    received: queue.SimpleQueue[int] = queue.SimpleQueue()

    def handler(signum: int, frame: FrameType | None) -> None:
        received.put(signum)

    for signum in signals:
        signal.signal(signum, handler)
    return received


def _quiet_chatty_loggers() -> None:
    logging.getLogger("watchfiles").setLevel(logging.WARNING)  # it logs every change it sees


def log_to_stderr(name: str) -> None:
    """One line per record on stderr; text from robots in it is escaped (SafeFormatter)."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(SafeFormatter(f"%(asctime)s {name} %(levelname)s %(message)s"))
    logging.basicConfig(level=logging.INFO, handlers=[handler])
    _quiet_chatty_loggers()


def log_to_file(path: Path) -> None:
    """As log_to_stderr, to a file (`robotconf up`'s log)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(path, encoding="utf-8")
    handler.setFormatter(SafeFormatter("%(asctime)s %(name)s %(levelname)s %(message)s"))
    root = logging.getLogger()
    root.addHandler(handler)
    root.setLevel(logging.INFO)
    _quiet_chatty_loggers()


def parse_address(text: str, option: str, example: str) -> tuple[str, int]:
    """`HOST:PORT` of a listening option (`[::1]:PORT` for IPv6; `:PORT` listens on every
    interface, as Prometheus exporters do). ValueError with a one-line reason."""
    host, sep, port = text.rpartition(":")
    if not sep or not _PORT.fullmatch(port) or not 0 < int(port) < 65536:
        raise ValueError(f"{option} {text!r} must be HOST:PORT, e.g. {example}")
    host = host.removeprefix("[").removesuffix("]")
    return host or "0.0.0.0", int(port)
