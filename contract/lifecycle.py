"""Long-running commands' process setup: stop signals, where the logs go, addresses to listen at."""

from __future__ import annotations

import logging
import re
import signal
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from types import FrameType

from robotconf.contract.logsafe import SafeFormatter

_PORT = re.compile(r"[0-9]{1,5}")


def on_stop_signals(
    stop: threading.Event | None = None,
    callback: Callable[[], None] | None = None,
    again: Callable[[], None] | None = None,
) -> None:
    """SIGINT, SIGTERM and SIGHUP (the terminal was closed) end the command cleanly instead
    of raising in a random place or, for SIGHUP, killing it without its cleanup; a second one
    calls `again` (for those who will not wait) when given."""

    def handler(signum: int, frame: FrameType | None) -> None:
        if stop is not None and stop.is_set():
            # A closed terminal may send SIGHUP twice (the kernel, then the shell): not a hurry.
            if again is not None and signum != signal.SIGHUP:
                again()
            return
        if stop is not None:
            stop.set()
        if callback is not None:
            callback()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGHUP, handler)


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
