"""What one revision achieved, as the revision page reads it: the small interface the page asks
of the reconciler's outcome ledger (`RevisionHistory`, answered with the ledger's own `History`),
the ledger file behind it (`LedgerHistory`, the one edge here, which also answers the timeline
page's `EventLog`), and the page's live part worked out from the robots' retained goals
summaries."""

from __future__ import annotations

import re
import time
from collections import OrderedDict
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Protocol

from robotconf.readmodel.outcomes import History
from robotconf.readmodel.robot_goals import GoalRate, goal_rates
from robotconf.readmodel.timeline import EventQuery, KeptEvent
from robotconf.readmodel.verdicts import RobotRow

REVISION = re.compile(r"[0-9a-f]{4,64}")  # a commit id or a prefix of one, as links carry it


class HistoryError(Exception):
    """The ledger cannot answer (missing, unreadable): its words are the page's."""


class RevisionHistory(Protocol):
    """What the revision page asks of the outcome ledger."""

    def compare(self, revision: str) -> History | None:
        """`revision` (a full id or a prefix) beside the revision before it; None when the
        ledger holds no outcome of it. HistoryError when the ledger cannot be read."""
        ...


class EventLog(Protocol):
    """What the timeline page asks of the ledger."""

    def events(self, query: EventQuery) -> list[KeptEvent]:
        """The kept events `query` asks for, newest first. HistoryError when the ledger
        cannot be read."""
        ...


class LedgerHistory:
    """The reconciler's ledger file, opened read-only for each question (the reconciler
    writes it meanwhile; WAL lets both)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def compare(self, revision: str) -> History | None:
        from robotconf.readmodel.ledger import Ledger, LedgerError

        try:
            with Ledger.open(self.path, read_only=True, check=False) as ledger:
                if not any(seen.revision.startswith(revision) for seen in ledger.revisions()):
                    return None
                return ledger.history(revision)
        except LedgerError as exc:
            raise HistoryError(str(exc)) from None

    def events(self, query: EventQuery) -> list[KeptEvent]:
        from robotconf.readmodel.ledger import Ledger, LedgerError

        try:
            with Ledger.open(self.path, read_only=True, check=False) as ledger:
                return ledger.events(query)
        except LedgerError as exc:
            raise HistoryError(str(exc)) from None


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
        self._kept: OrderedDict[str, tuple[float, History | HistoryError | None]] = OrderedDict()

    def compare(self, revision: str) -> History | None:
        now = self.clock()
        kept = self._kept.get(revision)
        if kept is None or now - kept[0] > self.ttl:
            answer: History | HistoryError | None
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
