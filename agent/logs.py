"""The brain's log for the desk (`robotconf logs`): tails and a followed stream, redacted, cut to
the message bound, paced at about RATE lines a second and shared fairly between who asks.

No MQTT here: `DeskRequests` (agent/desk_requests.py) asks `LogStream` for the chunks due and
publishes them.
"""

from __future__ import annotations

import json
import os
from collections import OrderedDict, deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from robotconf.agent.redact import (
    MIN_SECRET_CHARS,
    REDACTED,
    Pem,
    Redactor,
    key_fragment,
    pem_state_after,
)
from robotconf.contract.wire import (
    LOG_FOLLOW_TTL,
    MAX_LOG_MESSAGE_BYTES,
    LogsChunk,
    LogsRequest,
)

__all__ = ["MIN_SECRET_CHARS", "REDACTED", "LogStream", "Redactor", "fit_line", "read_tail"]

RATE = 100.0  # lines a second, sustained, for all who ask together
BURST = 200.0  # lines at once, after a quiet while
POLL_INTERVAL = 0.25  # seconds between looks at the log file while followed
READ_LIMIT = 256 * 1024  # bytes read from the file per look; the rest is skipped, counted
TAIL_WINDOW = 1024 * 1024  # bytes read back from the end of a file for a tail
# Bytes read back before a tail (or the stream's start) for an open PEM block: a private key,
# RSA 16384 included, is far shorter, so a look back that finds no marker is outside one.
LOOKBACK = 64 * 1024
# Lines waiting to go out: the tails together, and the followed stream on its own. Beyond,
# the tail with the most lines waiting loses its oldest (counted, said as `dropped`), and new
# followed lines are dropped (counted).
QUEUE_LIMIT = 2 * 1000
QUEUE_BYTES = 4 * 1024 * 1024  # the tails' lines waiting, in bytes of JSON
QUANTUM = 10  # lines one waiting answer sends before the next one's turn
# Asks served (each reads the log): per session, and for everyone together; more are refused.
SESSION_ASKS_PER_SECOND = 5.0
ASKS_PER_SECOND = 20.0
MAX_SESSIONS = 256  # sessions whose ask budget is remembered (an idle one's is full anyway)
# What a chunk's JSON holds besides its lines; a line gets the rest of the message bound.
_CHUNK_OVERHEAD = 512
MAX_LINE_BYTES = MAX_LOG_MESSAGE_BYTES - _CHUNK_OVERHEAD
_BLOCK = 64 * 1024  # a tail reads back this much at a time, until it has its lines


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


def _decode(raw: bytes) -> str:
    return raw.decode("utf-8", errors="replace").rstrip("\r")


def _older(path: Path) -> Path:
    """The rotated copy before `path`: brain.log -> brain.log.1 -> brain.log.2."""
    stem, _, suffix = path.name.rpartition(".")
    if stem and suffix.isdigit():
        return path.with_name(f"{stem}.{int(suffix) + 1}")
    return path.with_name(path.name + ".1")


def pem_state_before(path: Path, offset: int, backups: int = 3, budget: int = LOOKBACK) -> Pem:
    """Whether the byte at `offset` of the log file `path` is inside a private-key PEM block,
    by looking back (at most `budget` bytes, into the rotated copy before it if need be);
    rotation keeps `backups` copies."""
    start = max(0, offset - budget)
    try:
        with open(path, "rb") as log:
            log.seek(start)
            data = log.read(offset - start)
    except OSError:
        data = b""
    text = data.decode("utf-8", errors="replace")
    found = pem_state_after(text)
    if found is not None:
        return found
    if start > 0:
        return Pem.OUTSIDE  # no key is that long: not inside one
    at_start = _state_at_start(path, backups, budget - offset)
    if at_start is not Pem.UNKNOWN:
        return at_start
    # Unknown at the file's start: what its lines up to `offset` say (see Redactor).
    tracker = Redactor((), (), Pem.UNKNOWN)
    for line in text.split("\n")[:-1]:
        tracker.track(line.rstrip("\r"))
    return tracker.state


def _state_at_start(path: Path, backups: int, budget: int) -> Pem:
    """The PEM state at the start of a log file. Lines may have been lost between the copy and
    the truncation of the rotation that began it: only a block open at the end of the copy
    before it says INSIDE, anything else UNKNOWN. Without a copy before it, the file is the
    log's own start (OUTSIDE) when rotation would have kept that copy, else UNKNOWN (a copy
    was deleted, or rotation only truncates: `backups` 0)."""
    older = _older(path)
    try:
        size = older.stat().st_size
    except OSError:
        number = int(older.name.rpartition(".")[2])
        return Pem.OUTSIDE if number <= backups else Pem.UNKNOWN
    before = pem_state_before(older, size, backups, budget)
    return Pem.INSIDE if before is Pem.INSIDE else Pem.UNKNOWN


@dataclass
class _Line:
    path: Path  # the file it was read from
    offset: int  # where it begins there
    raw: bytes
    seam: int | None = None  # where the rest of it begins, in the file after (see _tail_lines)

    @property
    def text(self) -> str:
        return _decode(self.raw)


def _file_tail(
    path: Path, count: int, window: int, end: int | None = None
) -> tuple[list[_Line], bool] | None:
    """The last `count` lines of one file (as of `end` bytes, else its size), read back at most
    `window` bytes, a block at a time, and whether the file ends with a line break; None when
    it cannot be read."""
    try:
        with open(path, "rb") as log:
            size = os.fstat(log.fileno()).st_size if end is None else end
            floor = max(0, size - window)
            start, data = size, b""
            # One more line break than lines asked for: the one before the first line.
            while start > floor and data.count(b"\n") <= count:
                step = min(_BLOCK, start - floor)
                start -= step
                log.seek(start)
                data = log.read(step) + data
    except OSError:
        return None
    data = data[: size - start]  # the file may have grown since `end`
    if not data:
        return [], True  # an empty file has no line, not an empty one
    ends_in_break = data.endswith(b"\n")
    pieces = data.split(b"\n")
    if ends_in_break:
        pieces.pop()  # the line break that ends the file
    lines: list[_Line] = []
    at = start
    for piece in pieces:
        lines.append(_Line(path, at, piece))
        at += len(piece) + 1
    if start > 0 and lines:
        lines.pop(0)  # begun before what was read
    return (lines[-count:] if count > 0 else []), ends_in_break


def _tail_lines(
    path: Path, count: int, window: int = TAIL_WINDOW, end: int | None = None
) -> list[_Line]:
    """The last `count` lines of the log, from the rotated copy before it when the current
    file holds fewer. Rotation copies, then truncates: a line the brain was writing then has
    its beginning at the copy's end and its rest at the file's start; it is joined again."""
    if count <= 0:
        return []
    current = _file_tail(path, count, window, end)
    newest = [] if current is None else current[0]
    if newest and newest[0].offset > 0:
        return newest
    # One more line of the copy: it may be the beginning of the current file's first line.
    older = _file_tail(_older(path), count - len(newest) + 1, window)
    if older is None:
        return newest
    lines, ends_in_break = older
    if lines and newest and not ends_in_break:
        lines[-1].seam = len(lines[-1].raw)
        lines[-1].raw += newest.pop(0).raw  # as bytes: the cut may split a character
    return (lines + newest)[-count:]


def read_tail(path: Path, count: int, window: int = TAIL_WINDOW) -> list[str]:
    """The last `count` lines of the log, as written (not redacted)."""
    return [line.text for line in _tail_lines(path, count, window)]


def redacted_tail(
    path: Path,
    count: int,
    redactor: Redactor,
    backups: int = 3,
    end: int | None = None,
    window: int = TAIL_WINDOW,
) -> list[str]:
    """The last `count` lines of the log as they may leave the robot: redacted from the PEM
    state found by looking back before the first of them, each cut to fit a message."""
    lines = _tail_lines(path, count, window, end)
    if not lines:
        return []
    reader = redactor.fresh(pem_state_before(lines[0].path, lines[0].offset, backups))
    shown: list[str] = []
    for n, line in enumerate(lines):
        before = lines[n - 1] if n > 0 else None
        # A rotation lies between: lines may have been lost at it (see pem_state_before; a
        # line it cut says what the ground is itself, see _across_seam).
        seam = before is not None and line.path != before.path and before.seam is None
        if seam and reader.state is not Pem.INSIDE:
            reader.state = Pem.UNKNOWN
        if line.seam is None:
            shown.append(fit_line(reader.line(line.text)))
        else:
            shown.append(fit_line(_across_seam(reader, line.raw, line.seam)))
    return shown


def _across_seam(reader: Redactor, raw: bytes, seam: int) -> str:
    """A line that a rotation cut in two at `seam`, joined again (a secret it cut is whole
    again). Bytes may have been lost at the cut (see pem_state_before), and with them a key's
    END or BEGIN: inside a key, or when what follows the cut may be part of one, the whole
    line is redacted, and the ground is what the part after the cut says, else unknown."""
    rest = _decode(raw[seam:])
    if reader.state is Pem.INSIDE or key_fragment(rest):
        reader.state = pem_state_after(rest) or Pem.UNKNOWN
        return REDACTED
    shown = reader.line(_decode(raw))
    if not rest.strip() and not reader.inside:
        reader.state = Pem.UNKNOWN  # nothing after the cut: the next line is the first one
    return shown


class _Budget:
    """A token bucket of asks."""

    def __init__(self, rate: float, now: float) -> None:
        self.rate = rate
        self.tokens = rate  # a second's worth at once
        self.at = now

    def refill(self, now: float) -> float:
        self.tokens = min(self.rate, self.tokens + max(0.0, now - self.at) * self.rate)
        self.at = now
        return self.tokens


@dataclass
class _Tail:
    """One answer's lines still to send; its end follows the last of them."""

    lines: deque[str]
    dropped: int = 0  # its lines left out before the next ones sent: the tails outgrew the queue


@dataclass
class _Waiting:
    """One session's answers still to send, in the order asked."""

    tails: deque[_Tail] = field(default_factory=deque)
    lines: int = 0
    size: int = 0


class LogStream:
    """One robot's log answers: tails for who asked, and the followed stream while anyone
    asks for it (until LOG_FOLLOW_TTL after the newest request).

    Fair to every asker: asks are budgeted per session as well as in all, and the lines go
    out in turns of QUANTUM between the answers waiting (each session's, and the stream), so a
    short tail goes out promptly however much another asker has waiting."""

    def __init__(self, path: Path, robot_id: str, redactor: Redactor, backups: int = 3) -> None:
        self.path = path
        self.robot_id = robot_id
        self._rules = redactor
        self._backups = backups  # rotated copies kept (agent.yaml's log.backups)
        self._redactor = redactor.fresh()  # the followed stream's
        self._waiting: dict[str, _Waiting] = {}
        self._waiting_lines = 0
        self._waiting_size = 0
        self._stream: deque[str] = deque()
        self._turns: deque[str | None] = deque()  # sessions with lines waiting; None: the stream
        self._turn_left = QUANTUM
        self._tokens = BURST
        self._refilled_at: float | None = None
        self._follow_until: float | None = None
        self._offset = 0
        self._inode: int | None = None
        self._partial = b""
        self._discarding = False  # the rest of a line that was cut or skipped is not shown
        self._copy_seen: tuple[int, int, int] | None = None  # the rotated copy, as last seen
        self._seam: int | None = None  # where a rotation cut the line in `_partial`
        self._next_poll = 0.0
        self._dropped = 0  # followed lines not sent, told in the next stream chunk
        self._budgets: OrderedDict[str, _Budget] = OrderedDict()
        self._all: _Budget | None = None

    @property
    def following(self) -> bool:
        return self._follow_until is not None

    # ------------------------------------------------------------ asks

    def ask(self, request: LogsRequest, now: float) -> str | None:
        """Queues the tail for `request` (and starts or extends following); None when served,
        else why it is refused (asked too often)."""
        refusal = self._admit(request.session, now)
        if refusal is not None:
            return refusal
        end: int | None = None
        if request.follow and self._follow_until is None:
            # The stream starts where the tail ends: nothing twice, nothing missed.
            end = self._start_following()
        lines = redacted_tail(self.path, request.lines, self._rules, self._backups, end)
        self._enqueue(request.session, lines)
        if request.follow:
            self._follow_until = now + LOG_FOLLOW_TTL
        return None

    def _admit(self, session: str, now: float) -> str | None:
        """Takes an ask from the session's budget and from everyone's; neither is touched when
        either is spent, so a refused ask costs nobody anything."""
        if self._all is None:
            self._all = _Budget(ASKS_PER_SECOND, now)
        budget = self._budgets.get(session)
        own = SESSION_ASKS_PER_SECOND if budget is None else budget.refill(now)
        if own < 1:
            return f"session {session} asks more than {SESSION_ASKS_PER_SECOND:g} times a second"
        if self._all.refill(now) < 1:
            return f"more than {ASKS_PER_SECOND:g} asks a second from all desks together"
        if budget is None:
            budget = self._budgets[session] = _Budget(SESSION_ASKS_PER_SECOND, now)
        budget.tokens -= 1
        self._all.tokens -= 1
        self._budgets.move_to_end(session)
        # Forget budgets that are full again (oldest first): a new session starts full.
        while self._budgets:
            oldest = next(iter(self._budgets.values()))
            if len(self._budgets) <= MAX_SESSIONS and oldest.refill(now) < oldest.rate:
                break
            self._budgets.popitem(last=False)
        return None

    def _enqueue(self, session: str, lines: list[str]) -> None:
        waiting = self._waiting.get(session)
        if waiting is None:
            waiting = self._waiting[session] = _Waiting()
            self._turns.append(session)
        size = sum(_encoded_size(line) + 1 for line in lines)
        waiting.tails.append(_Tail(deque(lines)))
        waiting.lines += len(lines)
        waiting.size += size
        self._waiting_lines += len(lines)
        self._waiting_size += size
        self._fit_waiting()

    def _fit_waiting(self) -> None:
        """Over the queue's bounds, the session with the most lines waiting loses its oldest
        unsent one, until the tails fit: whoever asks beyond a fair share pays for it alone."""
        while self._waiting_lines > QUEUE_LIMIT or self._waiting_size > QUEUE_BYTES:
            waiting = max(self._waiting.values(), key=lambda w: w.lines)
            tail = next(t for t in waiting.tails if t.lines)
            size = _encoded_size(tail.lines.popleft()) + 1
            tail.dropped += 1
            waiting.lines -= 1
            waiting.size -= size
            self._waiting_lines -= 1
            self._waiting_size -= size

    # ------------------------------------------------------------ following

    def _start_following(self) -> int:
        """Follows from the log's current end (returned), in the PEM state found there."""
        self._partial = b""
        self._discarding = False
        try:
            stat = self.path.stat()
        except OSError:
            self._offset, self._inode = 0, None
        else:
            self._offset, self._inode = stat.st_size, stat.st_ino
        self._next_poll = 0.0
        self._copy_seen = self._copy_signature()
        self._redactor = self._rules.fresh(pem_state_before(self.path, self._offset, self._backups))
        return self._offset

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
                copy = self._copy_signature()
                if stat.st_ino != self._inode:
                    # Replaced by another file: read it from its start.
                    self._restart_at_rotation(stat.st_ino, copied=False)
                elif copy != self._copy_seen or stat.st_size < self._offset:
                    # Rotated by someone else than this agent (which says so: `rotated`): a
                    # new copy, or a shorter file. The size alone may not tell: by now the
                    # brain may have written more than the stream had read.
                    self._restart_at_rotation(stat.st_ino, copied=True)
                self._copy_seen = copy
                found = self._read(log, stat.st_size)
        except OSError:
            return
        self._take_in(self.path, *found)

    def rotated(self) -> None:
        """The agent has just rotated the log (copied, then truncated it): the stream goes on
        at the file's start. Said rather than guessed from the size: by the next look, the
        brain may have written more than the stream had read."""
        if self._follow_until is not None:
            self._restart_at_rotation(self._inode, copied=True)
            self._copy_seen = self._copy_signature()

    def _copy_signature(self) -> tuple[int, int, int] | None:
        """What changes when a rotation writes the copy before the log."""
        try:
            stat = _older(self.path).stat()
        except OSError:
            return None
        return stat.st_ino, stat.st_size, stat.st_mtime_ns

    def _restart_at_rotation(self, inode: int | None, copied: bool) -> None:
        # What the brain wrote since the last look is at the copy's end, and a line it was
        # writing goes on at the file's start: both are read, in order.
        copy = self._read_copy() if copied else None
        if copy is None:
            self._partial, self._discarding = b"", False
        else:
            self._take_in(_older(self.path), *copy)
        self._seam = len(self._partial) if self._partial else None
        # Lines may have been lost between the copy and the truncation.
        if self._redactor.state is not Pem.INSIDE:
            self._redactor.state = Pem.UNKNOWN
        self._offset, self._inode = 0, inode

    def _read(self, log: BinaryIO, size: int) -> tuple[bytes, int, int]:
        """What follows `_offset` in `log` (at most READ_LIMIT bytes, the newest: the rest is
        skipped), where it begins, and how many bytes were skipped."""
        skipped = max(0, size - self._offset - READ_LIMIT)
        self._offset += skipped
        at = self._offset
        log.seek(at)
        raw = log.read(READ_LIMIT)
        self._offset += len(raw)
        return raw, at, skipped

    def _read_copy(self) -> tuple[bytes, int, int] | None:
        """The rest of the rotated copy after `_offset`; None without a copy of what was read."""
        try:
            with open(_older(self.path), "rb") as copy:
                size = os.fstat(copy.fileno()).st_size
                return None if size < self._offset else self._read(copy, size)
        except OSError:
            return None

    def _take_in(self, path: Path, raw: bytes, at: int, skipped: int) -> None:
        """Queues the complete lines of what was read (`raw`, from `at` in `path`)."""
        notices: list[str] = []
        if skipped:
            notices.append(
                f"[robotconf: skipped {skipped:,} bytes: the brain writes faster than "
                "the log stream carries]"
            )
            self._partial = b""
            self._discarding = True  # begun mid-line
        if self._discarding:
            self._seam = None
            newline = raw.find(b"\n")
            if newline < 0:
                self._queue_stream(notices)
                return
            self._discarding = False
            raw, at = raw[newline + 1 :], at + newline + 1
            # What was left out may have opened or closed a key: look back from here.
            self._redactor.state = pem_state_before(path, at, self._backups)
            data = raw
        else:
            data = self._partial + raw
        pieces = data.split(b"\n")
        self._partial = pieces.pop()
        if len(self._partial) > MAX_LINE_BYTES:
            # Shown cut, as a tail shows it; the rest of it, whenever it comes, is not shown.
            pieces.append(self._partial)
            self._partial = b""
            self._discarding = True
        seam = None
        if pieces:
            seam, self._seam = self._seam, None  # the first line is the one a rotation cut
        self._queue_stream(notices, pieces, seam)

    def _queue_stream(
        self, notices: list[str], pieces: Sequence[bytes] = (), seam: int | None = None
    ) -> None:
        """Queues notices, then lines (redacted; the first cut by a rotation at `seam`)."""
        was_empty = not self._stream
        for notice in notices:
            self._stream.append(notice)
        for n, piece in enumerate(pieces):
            shown: str | None = None
            if n == 0 and seam is not None:
                shown = _across_seam(self._redactor, piece, seam)
            elif len(self._stream) >= QUEUE_LIMIT:
                self._redactor.track(_decode(piece))  # not sent, but it may open or close a key
            else:
                shown = self._redactor.line(_decode(piece))
            if shown is None or len(self._stream) >= QUEUE_LIMIT:
                self._dropped += 1
                continue
            self._stream.append(fit_line(shown))
        if was_empty and self._stream:
            self._turns.append(None)

    # ------------------------------------------------------------ sending

    def due(self, now: float) -> float | None:
        """When `poll`/`take` next have work; None when nobody asks for anything."""
        when: list[float] = []
        if any(not w.tails[0].lines for w in self._waiting.values()):
            when.append(now)  # an end to send: it costs no line
        if self._turns:
            wait = 0.0 if self._tokens >= 1 else (1 - self._tokens) / RATE
            when.append(now + wait)
        if self._follow_until is not None:
            when.append(min(self._next_poll, self._follow_until))
        return min(when) if when else None

    def take(self, now: float) -> list[LogsChunk]:
        """The chunks to publish now: as many lines as the rate allows, in turns between the
        answers waiting, each chunk at most MAX_LOG_MESSAGE_BYTES, a tail's end marked."""
        self._refill(now)
        out = _Chunks(self)
        for session in list(self._waiting):
            self._send_ends(session, out)
        while self._turns and self._tokens >= 1:
            key = self._turns[0]
            if key is None:
                out.line(None, self._stream.popleft())
                more = bool(self._stream)
                if not more:
                    self._turns.popleft()
            else:
                waiting = self._waiting[key]
                tail = waiting.tails[0]
                line = tail.lines.popleft()
                size = _encoded_size(line) + 1
                waiting.lines -= 1
                waiting.size -= size
                self._waiting_lines -= 1
                self._waiting_size -= size
                out.line(key, line, tail.dropped)
                tail.dropped = 0
                more = self._send_ends(key, out)  # out of the turns once it has nothing left
            self._tokens -= 1
            self._turn_left -= 1
            if not more:
                self._turn_left = QUANTUM
            elif self._turn_left <= 0:
                self._turns.rotate(-1)
                self._turn_left = QUANTUM
        if self._dropped and not any(c.session is None for c in out.chunks):
            out.chunks.append(self._chunk(None))  # say what was dropped, even with nothing new
        for chunk in out.chunks:
            chunk.following = self._follow_until is not None
        return out.chunks

    def _send_ends(self, session: str, out: _Chunks) -> bool:
        """Ends the session's tails that have no line left; True while it has lines waiting."""
        waiting = self._waiting[session]
        while waiting.tails and not waiting.tails[0].lines:
            out.end(session, waiting.tails.popleft().dropped)
        if waiting.tails:
            return True
        del self._waiting[session]
        if self._turns[0] == session:
            self._turns.popleft()
            self._turn_left = QUANTUM
        else:
            self._turns.remove(session)  # ended before its turn came (it had no lines)
        return False

    def _chunk(self, session: str | None, dropped: int = 0) -> LogsChunk:
        if session is None:
            dropped, self._dropped = self._dropped, 0
        return LogsChunk(robot_id=self.robot_id, session=session, dropped=dropped)

    def _refill(self, now: float) -> None:
        if self._refilled_at is not None:
            self._tokens = min(BURST, self._tokens + (now - self._refilled_at) * RATE)
        self._refilled_at = now

    def stop(self) -> None:
        """Nobody reads any more (the broker connection is lost): drop what waits."""
        self._waiting.clear()
        self._waiting_lines = self._waiting_size = 0
        self._stream.clear()
        self._turns.clear()
        self._turn_left = QUANTUM
        self._follow_until = None
        self._partial = b""
        self._discarding = False
        self._seam = None


class _Chunks:
    """The chunks of one `take`: each session's (and the stream's) lines in order, a chunk
    closed by its tail's end or when the next line would not fit."""

    def __init__(self, stream: LogStream) -> None:
        self._stream = stream
        self.chunks: list[LogsChunk] = []
        self._open: dict[str | None, tuple[LogsChunk, int]] = {}

    def line(self, session: str | None, line: str, dropped: int = 0) -> None:
        size = _encoded_size(line) + 1
        current = self._open.get(session)
        if current is None or dropped or current[1] + size > MAX_LOG_MESSAGE_BYTES:
            # `dropped` counts lines left out before a chunk's own: it starts one.
            chunk = self._stream._chunk(session, dropped)
            self.chunks.append(chunk)
            current = (chunk, _CHUNK_OVERHEAD)
        current[0].lines.append(line)
        self._open[session] = (current[0], current[1] + size)

    def end(self, session: str, dropped: int) -> None:
        current = self._open.pop(session, None)
        if current is None or dropped:
            chunk = self._stream._chunk(session, dropped)
            self.chunks.append(chunk)
        else:
            chunk = current[0]
        chunk.end = True  # a tail's end closes its chunk
