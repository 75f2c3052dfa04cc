"""What one revision achieved, as the revision page reads it: the small interface the page asks
of the reconciler's outcome ledger (`RevisionHistory`), the answer's shape, and the page's own
live part worked out from the robots' retained goals summaries. Pure but for whatever implements
`RevisionHistory` (the ledger's SQLite edge)."""

from __future__ import annotations

import re
import time
from collections import OrderedDict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Protocol

from reconciler.robot_goals import GoalRate, goal_rates
from reconciler.verdicts import RobotRow

REVISION = re.compile(r"[0-9a-f]{4,64}")  # a commit id or a prefix of one, as links carry it


@dataclass(frozen=True)
class Tally:
    """Ended goals of one (scenario, task) or one robot under one revision."""

    succeeded: int = 0
    failed: int = 0
    canceled: int = 0
    stale: int = 0
    mean_duration: float | None = None  # seconds, of the goals whose start was seen
    codes: tuple[tuple[str, int], ...] = ()  # the most frequent failure codes, most first

    @property
    def ended(self) -> int:
        return self.succeeded + self.failed

    @property
    def rate(self) -> float | None:
        """Succeeded of succeeded and failed, as the fleet page's rate; None before any."""
        return self.succeeded / self.ended if self.ended else None


@dataclass(frozen=True)
class RevisionResult:
    """What the ledger kept of one revision: per (scenario, task) and per robot."""

    revision: str
    tasks: dict[tuple[str | None, str], Tally] = field(default_factory=dict)
    robots: dict[str, Tally] = field(default_factory=dict)
    first_at: float | None = None  # its first and last recorded outcome
    last_at: float | None = None

    @property
    def total(self) -> Tally:
        found = list(self.tasks.values())
        return Tally(
            sum(t.succeeded for t in found),
            sum(t.failed for t in found),
            sum(t.canceled for t in found),
            sum(t.stale for t in found),
        )


@dataclass(frozen=True)
class Comparison:
    """A revision beside the one before it (None: the ledger holds nothing before it)."""

    revision: RevisionResult
    before: RevisionResult | None = None


class HistoryError(Exception):
    """The ledger cannot answer (missing, unreadable): its words are the page's."""


class RevisionHistory(Protocol):
    """What the revision page asks of the outcome ledger."""

    def compare(self, revision: str) -> Comparison | None:
        """`revision` (a full id or a prefix) beside the revision before it; None when the
        ledger holds no outcome of it. HistoryError when the ledger cannot be read."""
        ...


class CachedHistory:
    """A RevisionHistory whose answers are kept `ttl` seconds (at most `size` revisions): the
    page is answered on the UI's one HTTP thread, and a reload or many viewers of one revision
    ask the ledger once. A refusal (HistoryError) is kept as long."""

    def __init__(
        self,
        history: RevisionHistory,
        ttl: float = 10.0,
        size: int = 32,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.history = history
        self.ttl = ttl
        self.size = size
        self.clock = clock
        self._kept: OrderedDict[str, tuple[float, Comparison | HistoryError | None]] = OrderedDict()

    def compare(self, revision: str) -> Comparison | None:
        now = self.clock()
        kept = self._kept.get(revision)
        if kept is None or now - kept[0] > self.ttl:
            answer: Comparison | HistoryError | None
            try:
                answer = self.history.compare(revision)
            except HistoryError as exc:
                answer = exc
            kept = (now, answer)
            self._kept[revision] = kept
            while len(self._kept) > self.size:
                self._kept.popitem(last=False)
        self._kept.move_to_end(revision)
        if isinstance(kept[1], HistoryError):
            raise kept[1]
        return kept[1]


def live_rates(rows: Iterable[RobotRow], revision: str) -> list[GoalRate]:
    """The success rate per scenario of the robots whose goals summaries count goals under
    `revision` now (their current request's), from the retained topics alone."""
    return goal_rates(
        (row.scenario, row.goals)
        for row in rows
        if row.goals.summary is not None and (row.goals.summary.revision or "").startswith(revision)
    )[0]


def rate_change(now: float | None, before: float | None) -> str:
    """`+12 pts`, `-3 pts`, `±0 pts`; `-` when either is unknown."""
    if now is None or before is None:
        return "-"
    points = round(100 * (now - before))
    return "±0 pts" if points == 0 else f"{points:+d} pts"
