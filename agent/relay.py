"""The relay's rules: a brain's JSON lines in, its goals summary and outcome records out.

Pure: no socket, no broker, no clock of its own. The agent's loop feeds it the lines its brain
wrote (agent/brain_socket.py reads them) with the time (`Now`: monotonic for deadlines, wall for
what is published), and asks it what to publish (agent/goals_report.py sends it).

What a brain cannot do here, however it writes: take more than `lines_per_second` (a token
bucket; the rest is refused and counted in the summary's `dropped`), make more than
`records_per_second` records, get the summary published more than once a `summary_interval`
(progress is coalesced), keep more than `MAX_OPEN_GOALS` goals open, or put a control character
or more than `MAX_TEXT` characters of text into what leaves the robot. Every record carries the
request the agent started the brain with, never what the brain says it runs.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from enum import Enum

from pydantic import TypeAdapter, ValidationError

from robotconf.contract.goals import (
    MAX_EVENTS_KEPT,
    MAX_LINE_BYTES,
    MAX_RECENT_KEPT,
    MAX_TASKS_KEPT,
    MAX_TEXT,
    MAX_VITALS,
    OTHER_TASK,
    BrainEvent,
    BrainMessage,
    CurrentGoal,
    EventLine,
    GoalLine,
    GoalsSummary,
    Hello,
    LastOutcome,
    OutcomeRecord,
    OutcomeState,
    Ready,
    Severity,
    TaskCounts,
    VitalsLine,
    VitalValue,
)
from robotconf.contract.safejson import PayloadError, parse_object
from robotconf.contract.textsafe import printable, shorten

MAX_OPEN_GOALS = 32  # goals underway at once; a start beyond is refused (and counted)
MAX_PENDING_RECORDS = 1000  # records kept while the broker is away; the oldest go first
MAX_LINE_DEPTH = 4  # a line's JSON nesting: {"values": {...}} is 2

_LINE: TypeAdapter[Hello | Ready | GoalLine | VitalsLine | EventLine] = TypeAdapter(BrainMessage)


def safe_text(text: str, limit: int = MAX_TEXT) -> str:
    """Printable (every control, line break and bidi character escaped), cut to `limit`."""
    return shorten(printable(text), limit)


def _short(digest: str) -> str:
    """A digest as a message names it: `sha256:` and 12 hex digits."""
    return shorten(digest, 20)


@dataclass(frozen=True)
class Now:
    """One moment: `mono` for deadlines and rates, `wall` (unix time) for what is published."""

    mono: float
    wall: float


@dataclass(frozen=True)
class Limits:
    stale_after: float = 300.0  # seconds without progress before an open goal is stale
    lines_per_second: float = 50.0
    line_burst: float = 100.0
    records_per_second: float = 10.0
    record_burst: float = 20.0
    summary_interval: float = 1.0  # seconds between two summaries, at least


@dataclass
class TokenBucket:
    """`rate` tokens a second, at most `burst` saved up."""

    rate: float
    burst: float
    tokens: float = -1.0  # full at the first look
    at: float = 0.0

    def _refill(self, now: float) -> None:
        if self.tokens < 0:
            self.tokens, self.at = self.burst, now
            return
        elapsed = max(0.0, now - self.at)
        self.tokens = min(self.burst, self.tokens + elapsed * self.rate)
        self.at = now

    def take(self, now: float, wanted: int = 1) -> int:
        """Takes up to `wanted` whole tokens; how many it got."""
        self._refill(now)
        got = max(0, min(wanted, int(self.tokens)))
        self.tokens -= got
        return got

    def available(self, now: float) -> int:
        self._refill(now)
        return int(self.tokens)

    def ready_at(self, now: float) -> float:
        """When at least one token will be there."""
        self._refill(now)
        return now if self.tokens >= 1 else now + (1 - self.tokens) / self.rate


class Signal(Enum):
    """What the supervisor hears from the relay: the brain's readiness (agent/supervisor.py)."""

    HELLO = "hello"
    READY = "ready"


@dataclass
class _Counts:
    completed: int = 0
    failed: int = 0
    canceled: int = 0
    stale_ended: int = 0  # open when their run ended: stale for good


@dataclass
class _Open:
    """A goal underway."""

    goal: str
    task: str
    key: str  # the task it is counted under (OTHER_TASK past MAX_TASKS_KEPT)
    counted: bool  # started under the current request (its end counts in the summary)
    digest: str | None
    revision: str | None
    scenario: str | None
    started_wall: float | None  # None: its start was never seen (a progress came first)
    first_wall: float
    updated_mono: float
    updated_wall: float
    fraction: float | None = None
    eta: float | None = None
    note: str | None = None
    stale: bool = False


@dataclass
class Publish:
    """What to send now: the retained summary (if one is due) and the records, oldest first."""

    summary: GoalsSummary | None = None
    records: list[OutcomeRecord] = field(default_factory=list)


class GoalsRelay:
    """One robot's brain reports: its counts since the current request, its goals underway,
    vitals and events, and the records still to send."""

    def __init__(self, robot_id: str, limits: Limits) -> None:
        self.robot_id = robot_id
        self.limits = limits
        self.digest: str | None = None
        self.revision: str | None = None
        self.scenario: str | None = None
        self.since: float | None = None
        self.run: str | None = None
        self.reporting = False
        self.ready: bool | None = None
        self.dropped = 0
        self._seq = 0
        self._counts: dict[str, _Counts] = {}
        self._open: dict[str, _Open] = {}
        self._last: LastOutcome | None = None
        self._recent: deque[LastOutcome] = deque(maxlen=MAX_RECENT_KEPT)
        self._vitals: dict[str, VitalValue] = {}
        self._vitals_at: float | None = None
        self._events: deque[BrainEvent] = deque(maxlen=MAX_EVENTS_KEPT)
        self._records: deque[OutcomeRecord] = deque()
        self._lines = TokenBucket(limits.lines_per_second, limits.line_burst)
        self._record_tokens = TokenBucket(limits.records_per_second, limits.record_burst)
        self._dirty = True
        self._next_summary = 0.0

    # ------------------------------------------------------------ what the agent tells it

    def request(
        self, digest: str | None, revision: str | None, scenario: str | None, now: Now
    ) -> None:
        """The request the brain runs (after a start or a reload). A new digest starts new
        counts; the same one (a restart of the brain) keeps them."""
        if digest == self.digest:
            self.revision, self.scenario = revision, scenario
            return
        self.digest, self.revision, self.scenario = digest, revision, scenario
        self.since = round(now.wall, 3)
        self.dropped = 0
        self._counts = {}
        for goal in self._open.values():
            goal.counted = False  # it ends under the request it started with, uncounted here
        self._changed()

    def brain_started(self, run: str, now: Now) -> None:
        """A new run of the brain: not reporting until its hello."""
        self._close_run(now)
        self.run = run
        self._seq = 0
        self._changed()

    def brain_exited(self, now: Now) -> None:
        """The run is over: what it left open is stale, and nothing reports any more."""
        self._close_run(now)
        self._changed()

    def refused(self, count: int) -> None:
        """Lines or connections the socket refused (too long, too many)."""
        if count > 0:
            self.dropped += count
            self._changed()

    def connected(self) -> None:
        """A new broker connection: the summary goes out at once."""
        self._dirty = True
        self._next_summary = 0.0

    # ------------------------------------------------------------ what the brain says

    def lines(self, raw: list[bytes], now: Now) -> list[Signal]:
        """Lines from the brain of the current run, in order; what the supervisor must hear.
        Beyond the line bucket they are refused unread (counted)."""
        if not raw:
            return []
        taken = self._lines.take(now.mono, len(raw))
        if taken < len(raw):
            self.dropped += len(raw) - taken
            self._changed()
        signals: list[Signal] = []
        for line in raw[:taken]:
            signal = self._line(line, now)
            if signal is not None:
                signals.append(signal)
        return signals

    def _line(self, raw: bytes, now: Now) -> Signal | None:
        if self.run is None:
            return None  # no brain runs: nobody to attribute it to
        try:
            message = _LINE.validate_python(
                parse_object(raw, max_bytes=MAX_LINE_BYTES, max_depth=MAX_LINE_DEPTH)
            )
        except (PayloadError, ValidationError, RecursionError):
            self.dropped += 1
            self._changed()
            return None
        self._changed()
        if isinstance(message, Hello):
            return self._hello(message, now)
        if isinstance(message, Ready):
            self.reporting = True
            self.ready = True
            return Signal.READY
        if isinstance(message, GoalLine):
            self._goal(message, now)
        elif isinstance(message, VitalsLine):
            self._vitals_line(message, now)
        else:
            self._event(message.severity, message.message, now)
        return None

    def _hello(self, hello: Hello, now: Now) -> Signal:
        self.reporting = True
        if self.ready is not True:
            self.ready = False
        if hello.digest is not None and hello.digest != self.digest:
            self._event(
                Severity.WARNING,
                f"the brain says it runs {_short(hello.digest)}, the agent started it with "
                f"{_short(self.digest or 'no request')}: its records carry the agent's",
                now,
            )
        return Signal.HELLO

    def _goal(self, line: GoalLine, now: Now) -> None:
        goal = self._open.get(line.id)
        if line.state in ("started", "progress"):
            if goal is None:
                goal = self._start(line, now)
                if goal is None:
                    return
            elif line.state == "started":
                goal.started_wall = goal.started_wall or now.wall
            goal.updated_mono, goal.updated_wall = now.mono, now.wall
            goal.stale = False
            if line.fraction is not None:
                goal.fraction = line.fraction
            if line.eta is not None:
                goal.eta = line.eta
            if line.note is not None:
                goal.note = safe_text(line.note)
            return
        if goal is None:
            goal = self._start(line, now, opening=False)
            if goal is None:
                return
        else:
            del self._open[line.id]
        outcome = OutcomeState(line.state)
        if goal.counted:
            counts = self._counts[goal.key]
            if outcome is OutcomeState.SUCCEEDED:
                counts.completed += 1
            elif outcome is OutcomeState.FAILED:
                counts.failed += 1
            else:
                counts.canceled += 1
        message = None if line.message is None else safe_text(line.message)
        self._ended(
            goal, outcome, line.code if outcome is OutcomeState.FAILED else None, message, now
        )

    def _start(self, line: GoalLine, now: Now, opening: bool = True) -> _Open | None:
        if opening and len(self._open) >= MAX_OPEN_GOALS:
            self.dropped += 1
            return None
        key = (
            line.task
            if line.task in self._counts or len(self._counts) < MAX_TASKS_KEPT
            else OTHER_TASK
        )
        self._counts.setdefault(key, _Counts())
        goal = _Open(
            goal=line.id,
            task=line.task,
            key=key,
            counted=True,
            digest=self.digest,
            revision=self.revision,
            scenario=self.scenario,
            started_wall=now.wall if line.state == "started" else None,
            first_wall=now.wall,
            updated_mono=now.mono,
            updated_wall=now.wall,
        )
        if opening:
            self._open[line.id] = goal
        return goal

    def _vitals_line(self, line: VitalsLine, now: Now) -> None:
        refused = False
        for name, value in line.values.items():
            if name not in self._vitals and len(self._vitals) >= MAX_VITALS:
                refused = True
                continue
            self._vitals[name] = safe_text(value) if isinstance(value, str) else value
        if refused:
            self.dropped += 1
        self._vitals_at = round(now.wall, 3)

    def _event(self, severity: Severity, message: str, now: Now) -> None:
        self._events.append(
            BrainEvent(at=round(now.wall, 3), severity=severity, message=safe_text(message))
        )

    # ------------------------------------------------------------ time

    def tick(self, now: Now) -> None:
        """Goals with no progress for `stale_after` become stale: once, with a record each."""
        limit = self.limits.stale_after
        for goal in self._open.values():
            if not goal.stale and now.mono - goal.updated_mono >= limit:
                goal.stale = True
                self._record(
                    goal,
                    OutcomeState.STALE,
                    None,
                    f"no progress for {limit:g} s (stale_after)",
                    now,
                )
                self._changed()

    def due(self, connected: bool) -> float | None:
        """The monotonic time by which `tick` or `publishes` has work (while disconnected,
        only `tick`: what waits to be sent waits for the connection, not for a time)."""
        times = [
            goal.updated_mono + self.limits.stale_after
            for goal in self._open.values()
            if not goal.stale
        ]
        if connected and self._dirty:
            times.append(self._next_summary)
        if connected and self._records:
            times.append(0.0)
        return min(times) if times else None

    def publishes(self, now: Now, connected: bool, final: bool = False) -> Publish:
        """What to send now, if connected: the records waiting, and the summary once its
        interval has passed since the last (what changed meanwhile goes in one); `final`: the
        agent stops, the summary goes at once."""
        if not connected:
            return Publish()
        records = list(self._records)
        self._records.clear()
        summary = None
        if self._dirty and (final or now.mono >= self._next_summary):
            summary = self.summary(now)
            self._dirty = False
            self._next_summary = now.mono + self.limits.summary_interval
        return Publish(summary, records)

    # ------------------------------------------------------------ the summary

    def summary(self, now: Now) -> GoalsSummary:
        tasks: dict[str, TaskCounts] = {
            key: TaskCounts(
                completed=c.completed, failed=c.failed, canceled=c.canceled, stale=c.stale_ended
            )
            for key, c in self._counts.items()
        }
        for goal in self._open.values():
            if goal.counted:
                counts = tasks[goal.key]
                if goal.stale:
                    counts.stale += 1
                else:
                    counts.underway += 1
        current = None
        if self._open:
            goal = next(reversed(self._open.values()))
            current = CurrentGoal(
                goal=goal.goal,
                task=goal.task,
                started_at=goal.started_wall or goal.first_wall,
                updated_at=goal.updated_wall,
                fraction=goal.fraction,
                eta=goal.eta,
                note=goal.note,
                stale=goal.stale,
            )
        return GoalsSummary(
            robot_id=self.robot_id,
            revision=self.revision,
            digest=self.digest,
            scenario=self.scenario,
            run=self.run,
            since=self.since,
            reporting=self.reporting,
            ready=self.ready,
            completed=sum(t.completed for t in tasks.values()),
            failed=sum(t.failed for t in tasks.values()),
            canceled=sum(t.canceled for t in tasks.values()),
            underway=sum(t.underway for t in tasks.values()),
            stale=sum(t.stale for t in tasks.values()),
            tasks=tasks,
            current=current,
            last=self._last,
            recent=list(self._recent),
            vitals=dict(self._vitals),
            vitals_at=self._vitals_at,
            events=list(self._events),
            dropped=self.dropped,
            updated=round(now.wall, 3),
        )

    # ------------------------------------------------------------ internals

    def _close_run(self, now: Now) -> None:
        for goal in list(self._open.values()):
            if goal.counted:
                self._counts[goal.key].stale_ended += 1
            if not goal.stale:
                self._record(
                    goal, OutcomeState.STALE, None, "the brain's run ended with it underway", now
                )
        self._open.clear()
        self.reporting = False
        self.ready = None

    def _ended(
        self,
        goal: _Open,
        outcome: OutcomeState,
        code: str | None,
        message: str | None,
        now: Now,
    ) -> None:
        last = LastOutcome(
            goal=goal.goal,
            task=goal.task,
            outcome=outcome,
            code=code,
            message=message,
            ended_at=round(now.wall, 3),
            duration=_duration(goal, now),
        )
        self._last = last
        self._recent.append(last)
        self._record(goal, outcome, code, message, now)

    def _record(
        self,
        goal: _Open,
        outcome: OutcomeState,
        code: str | None,
        message: str | None,
        now: Now,
    ) -> None:
        if self.run is None:
            return
        if self._record_tokens.take(now.mono) == 0:
            self.dropped += 1
            return
        if len(self._records) >= MAX_PENDING_RECORDS:
            self._records.popleft()
            self.dropped += 1
        started = goal.started_wall
        self._records.append(
            OutcomeRecord(
                robot_id=self.robot_id,
                revision=goal.revision,
                digest=goal.digest,
                scenario=goal.scenario,
                run=self.run,
                seq=self._seq,
                goal=goal.goal,
                task=goal.task,
                outcome=outcome,
                code=code,
                message=message,
                started_at=None if started is None else round(started, 3),
                ended_at=round(now.wall, 3),
                duration=_duration(goal, now),
            )
        )
        self._seq += 1

    def _changed(self) -> None:
        self._dirty = True


def _duration(goal: _Open, now: Now) -> float | None:
    """Seconds from the goal's start (when it was seen) to now, never negative."""
    started = goal.started_wall
    return None if started is None else round(max(0.0, now.wall - started), 3)
