"""The brain's log for the desk (`robotconf logs`): a tail and a followed stream, with secrets
redacted, lines cut to the message bound, and everything paced at about RATE lines a second.

No MQTT here: the runtime asks `LogStream` for the chunks due and publishes them.
"""

from __future__ import annotations

import copy
import json
import os
import re
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from configurator.wire import (
    LOG_FOLLOW_TTL,
    MAX_LOG_MESSAGE_BYTES,
    LogsChunk,
    LogsRequest,
)

RATE = 100.0  # lines a second, sustained
BURST = 200.0  # lines at once, after a quiet while
POLL_INTERVAL = 0.25  # seconds between looks at the log file while followed
READ_LIMIT = 256 * 1024  # bytes read from the file per look; the rest is skipped, counted
TAIL_WINDOW = 1024 * 1024  # bytes read back from the end of a file for a tail
QUEUE_LIMIT = 2 * 1000  # lines waiting to go out; beyond, followed lines are dropped, counted
ASKS_PER_SECOND = 5  # requests served in a second; more are ignored (each reads the file)
# What a chunk's JSON holds besides its lines; a line gets the rest of the message bound.
_CHUNK_OVERHEAD = 512
MAX_LINE_BYTES = MAX_LOG_MESSAGE_BYTES - _CHUNK_OVERHEAD
MIN_SECRET_CHARS = 3  # shorter values (ROS_DOMAIN_ID: 7) are redacted only as NAME=value
REDACTED = "[redacted]"

_PEM_BEGIN = re.compile(r"-----BEGIN [A-Z0-9 ]*PRIVATE KEY-----")
_PEM_END = re.compile(r"-----END [A-Z0-9 ]*PRIVATE KEY-----")
_URL_PASSWORD = re.compile(r"(?i)\b([a-z][a-z0-9+.-]*://[^\s/:@]*):[^\s/@]+@")


class Redactor:
    """Takes secrets out of log lines: the values of agent.yaml's `env:` and the broker
    password anywhere they appear (each at least MIN_SECRET_CHARS long), `NAME=value` for
    every `env:` name whatever its value, passwords in URLs, and private-key PEM blocks.
    Stateful: a PEM block spans lines, so one Redactor reads one stream in order."""

    def __init__(self, secrets: Iterable[str], names: Iterable[str]) -> None:
        values = sorted(
            {s for s in secrets if len(s) >= MIN_SECRET_CHARS and "\n" not in s},
            key=len,
            reverse=True,
        )
        self._values = re.compile("|".join(re.escape(v) for v in values)) if values else None
        named = sorted(set(names), key=len, reverse=True)
        self._assignments = (
            re.compile(r"\b(" + "|".join(re.escape(n) for n in named) + r")(\s*[=:]\s*)(\S+)")
            if named
            else None
        )
        self._in_key = False

    def fresh(self) -> Redactor:
        """The same rules for another read of the log, with no PEM block open."""
        other = copy.copy(self)
        other._in_key = False
        return other

    def line(self, text: str) -> str:
        if self._in_key:
            if _PEM_END.search(text):
                self._in_key = False
            return REDACTED
        begin = _PEM_BEGIN.search(text)
        if begin is not None:
            self._in_key = _PEM_END.search(text, begin.end()) is None
            return text[: begin.start()] + REDACTED
        if self._values is not None:
            text = self._values.sub(REDACTED, text)
        if self._assignments is not None:
            text = self._assignments.sub(lambda m: m.group(1) + m.group(2) + REDACTED, text)
        return _URL_PASSWORD.sub(lambda m: m.group(1) + ":" + REDACTED + "@", text)


def _encoded_size(line: str) -> int:
    return len(json.dumps(line, ensure_ascii=False).encode("utf-8"))


def fit_line(line: str, limit: int = MAX_LINE_BYTES) -> str:
    """`line`, cut with a marker when its JSON form would not fit in one message."""
    size = _encoded_size(line)
    if size <= limit:
        return line
    marker = f" [robotconf: line cut, {len(line.encode('utf-8', 'replace')):,} bytes]"
    keep = len(line)
    while keep > 0 and _encoded_size(line[:keep]) + _encoded_size(marker) > limit:
        # Shrink by the excess, scaled: escapes make a character up to 6 bytes of JSON.
        excess = _encoded_size(line[:keep]) + _encoded_size(marker) - limit
        keep = max(0, keep - max(1, excess // 2))
    return line[:keep] + marker


def _lines_of(raw: bytes) -> list[str]:
    text = raw.decode("utf-8", errors="replace")
    return [line.rstrip("\r") for line in text.split("\n")]


def read_tail(path: Path, count: int, window: int = TAIL_WINDOW) -> list[str]:
    """The last `count` lines of the log, from the rotated file before it when the current one
    holds fewer; each file read back at most `window` bytes from its end."""
    if count <= 0:
        return []
    lines: list[str] = []
    for candidate in (path, path.with_name(path.name + ".1")):
        try:
            with open(candidate, "rb") as log:
                size = os.fstat(log.fileno()).st_size
                start = max(0, size - window)
                log.seek(start)
                raw = log.read(window)
        except OSError:
            continue
        found = _lines_of(raw)
        if found and found[-1] == "":
            found.pop()  # the newline that ends the file
        if start > 0 and found:
            found.pop(0)  # begun mid-line
        lines = found + lines
        if len(lines) >= count:
            break
    return lines[-count:]


@dataclass
class _Queued:
    session: str | None  # None: a followed line
    line: str | None  # None: the end of the tail for `session`


class LogStream:
    """One robot's log answers: tails for who asked, and the followed stream while anyone
    asks for it (until LOG_FOLLOW_TTL after the newest request)."""

    def __init__(self, path: Path, robot_id: str, redactor: Redactor) -> None:
        self.path = path
        self.robot_id = robot_id
        self._redactor = redactor
        self._queue: deque[_Queued] = deque()
        self._tokens = BURST
        self._refilled_at: float | None = None
        self._follow_until: float | None = None
        self._offset = 0
        self._inode: int | None = None
        self._partial = b""
        self._next_poll = 0.0
        self._dropped = 0  # followed lines not sent, told in the next stream chunk
        self._asks: deque[float] = deque()

    @property
    def following(self) -> bool:
        return self._follow_until is not None

    def ask(self, request: LogsRequest, now: float) -> bool:
        """Queues the tail for `request` (and starts or extends following); False when asked
        too often to serve."""
        while self._asks and now - self._asks[0] >= 1.0:
            self._asks.popleft()
        if len(self._asks) >= ASKS_PER_SECOND:
            return False
        self._asks.append(now)
        if request.follow and self._follow_until is None:
            # The stream starts where the tail ends: nothing twice, nothing missed.
            self._start_following()
        tail = read_tail(self.path, min(request.lines, max(0, QUEUE_LIMIT - len(self._queue))))
        redactor = self._redactor.fresh()  # a tail is its own read of the file
        for line in tail:
            self._queue.append(_Queued(request.session, fit_line(redactor.line(line))))
        self._queue.append(_Queued(request.session, None))
        if request.follow:
            self._follow_until = now + LOG_FOLLOW_TTL
        return True

    def _start_following(self) -> None:
        self._partial = b""
        try:
            stat = self.path.stat()
        except OSError:
            self._offset, self._inode = 0, None
        else:
            self._offset, self._inode = stat.st_size, stat.st_ino
        self._next_poll = 0.0
        self._redactor = self._redactor.fresh()

    def poll(self, now: float) -> None:
        """Reads what the brain wrote since the last look, while followed."""
        if self._follow_until is not None and now >= self._follow_until:
            self._follow_until = None
            self._partial = b""
            return
        if self._follow_until is None or now < self._next_poll:
            return
        self._next_poll = now + POLL_INTERVAL
        try:
            with open(self.path, "rb") as log:
                stat = os.fstat(log.fileno())
                if stat.st_ino != self._inode or stat.st_size < self._offset:
                    # Rotated (copy-then-truncate) or replaced: read the new file from its start.
                    self._offset, self._inode, self._partial = 0, stat.st_ino, b""
                skipped = max(0, stat.st_size - self._offset - READ_LIMIT)
                if skipped:
                    self._offset += skipped
                    self._partial = b""
                log.seek(self._offset)
                raw = log.read(READ_LIMIT)
        except OSError:
            return
        self._offset += len(raw)
        data = self._partial + raw
        lines = _lines_of(data)
        self._partial = lines.pop().encode("utf-8") if lines else b""
        if len(self._partial) > MAX_LINE_BYTES:
            lines.append(self._partial.decode("utf-8", "replace"))
            self._partial = b""
        if skipped:
            if lines:
                lines.pop(0)  # begun mid-line
            lines.insert(
                0,
                f"[robotconf: skipped {skipped:,} bytes: the brain writes faster than "
                "the log stream carries]",
            )
        for line in lines:
            if len(self._queue) >= QUEUE_LIMIT:
                self._dropped += 1
                continue
            self._queue.append(_Queued(None, fit_line(self._redactor.line(line))))

    def due(self, now: float) -> float | None:
        """When `poll`/`take` next have work; None when nobody asks for anything."""
        when: list[float] = []
        if self._queue:
            wait = 0.0 if self._tokens >= 1 else (1 - self._tokens) / RATE
            when.append(now + wait)
        if self._follow_until is not None:
            when.append(min(self._next_poll, self._follow_until))
        return min(when) if when else None

    def take(self, now: float) -> list[LogsChunk]:
        """The chunks to publish now: as many lines as the rate allows, each chunk at most
        MAX_LOG_MESSAGE_BYTES, a tail's end marked."""
        self._refill(now)
        chunks: list[LogsChunk] = []
        current: LogsChunk | None = None
        size = 0
        while self._queue and (self._tokens >= 1 or self._queue[0].line is None):
            item = self._queue[0]
            line_size = 0 if item.line is None else _encoded_size(item.line) + 1
            fits = current is not None and size + line_size <= MAX_LOG_MESSAGE_BYTES
            if current is None or current.session != item.session or not fits:
                current = self._chunk(item.session)
                chunks.append(current)
                size = _CHUNK_OVERHEAD
            self._queue.popleft()
            if item.line is None:
                current.end = True
                current = None  # a tail's end closes its chunk
                continue
            current.lines.append(item.line)
            size += line_size
            self._tokens -= 1
        if self._dropped and not any(c.session is None for c in chunks):
            chunks.append(self._chunk(None))  # say what was dropped, even with nothing new
        for chunk in chunks:
            chunk.following = self._follow_until is not None
        return chunks

    def _chunk(self, session: str | None) -> LogsChunk:
        dropped = 0
        if session is None:
            dropped, self._dropped = self._dropped, 0
        return LogsChunk(robot_id=self.robot_id, session=session, dropped=dropped)

    def _refill(self, now: float) -> None:
        if self._refilled_at is not None:
            self._tokens = min(BURST, self._tokens + (now - self._refilled_at) * RATE)
        self._refilled_at = now

    def stop(self) -> None:
        """Nobody reads any more (the broker connection is lost): drop what waits."""
        self._queue.clear()
        self._follow_until = None
        self._partial = b""
