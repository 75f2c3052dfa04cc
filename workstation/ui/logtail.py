"""A robot's brain log for the UI's operators: the desk channel read as `robotconf logs --follow`
reads it, on a thread of its own, fed to a server-sent-events stream until the client goes."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Protocol

from robotconf.contract.errors import CliError
from robotconf.contract.mqtt import Connection
from robotconf.contract.wire import LogsChunk
from robotconf.workstation.desk.logs import log_chunks, shown
from robotconf.workstation.desk.robot import RobotDesk

log = logging.getLogger("robotconf.ui")

TAIL_LINES = 200  # the tail a page starts with
MAX_LINE = 4000  # characters of one line sent to a page; the rest is cut with a marker
MAX_FOLLOWERS = 8  # log streams open at once: each is a thread and a broker client


class Feed(Protocol):
    """Where a follower's events go: the edge's FedStream has this shape."""

    @property
    def closed(self) -> bool: ...

    def put(self, chunk: bytes) -> None: ...

    def end(self) -> None: ...


def event(lines: list[str]) -> bytes:
    """One server-sent event (a `message`: the page appends its data, a line each): each line
    one `data:` field. Lines arrive made printable (no line break or control character left),
    so none can end the event or forge another."""
    data = "".join(f"data: {line}\n" for line in lines) or "data:\n"
    return f"{data}\n".encode()


def note(text: str) -> bytes:
    """A line of the UI's own among the log's, marked as such."""
    return event([f"[robotconf ui] {text}"])


def chunk_event(chunk: LogsChunk) -> bytes:
    """A chunk of the log as one `lines` event; lines left out are said first."""
    lines = [_cut(shown(line)) for line in chunk.lines]
    said = event(lines) if lines else b""
    if chunk.dropped:
        left_out = f"{chunk.dropped} line(s) left out: the robot sends about 100 lines a second"
        said = note(left_out) + said
    return said


def _cut(line: str) -> str:
    return line if len(line) <= MAX_LINE else line[:MAX_LINE] + " [cut]"


class LogTails:
    """The log streams open to operators' pages, at most `limit` at once."""

    def __init__(
        self,
        connection: Connection,
        prefix: str,
        *,
        limit: int = MAX_FOLLOWERS,
        wait: float = 10.0,
    ) -> None:
        self.connection = connection
        self.prefix = prefix
        self.limit = limit
        self.wait = wait
        self._open = 0
        self._lock = threading.Lock()

    @property
    def open(self) -> int:
        return self._open

    def reserve(self) -> bool:
        """Takes a place for one more stream; False when all are taken."""
        with self._lock:
            if self._open >= self.limit:
                return False
            self._open += 1
            return True

    def release(self) -> None:
        with self._lock:
            self._open -= 1

    def follow(self, robot_id: str, feed: Feed) -> threading.Thread:
        """Follows `robot_id`'s log into `feed` on a new thread, until the feed is closed (the
        client went, or the edge cut it); a place must have been reserved, it is released
        when the thread ends."""
        thread = threading.Thread(
            target=self._follow, args=(robot_id, feed), name=f"ui-logs-{robot_id}", daemon=True
        )
        thread.start()
        return thread

    def _follow(self, robot_id: str, feed: Feed) -> None:
        stopped: Callable[[], bool] = lambda: feed.closed  # noqa: E731
        try:
            with RobotDesk(self.connection, self.prefix, robot_id, logs=True) as desk:
                for item in log_chunks(desk, TAIL_LINES, True, self.wait, stopped):
                    if isinstance(item, LogsChunk):
                        said = chunk_event(item)
                        if said:
                            feed.put(said)
                    else:
                        feed.put(note(f"{robot_id} went offline; its log goes on when it is back"))
        except CliError as exc:
            feed.put(note(shown(exc.message)))
        except Exception as exc:  # one page's stream ends, never the UI
            log.error("ui: the log stream of %s failed: %s", robot_id, shown(repr(exc))[:300])
            feed.put(note("the log stream failed (see the UI's log)"))
        finally:
            feed.end()
            self.release()
