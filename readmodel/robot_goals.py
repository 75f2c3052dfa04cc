"""What a robot's retained goals summary shows, pure: its goals since the current request as
`status`, `up` and the browser view show them, and the success rate per scenario and revision.

A robot whose agent publishes no summary, or whose brain does not speak the brain library's wire
(`reporting` false), has goals `unknown`, never failed. What a robot wrote is bounded here once
(lists cut to the contract's sizes, texts to `MAX_TEXT`) so that no reader carries more.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from robotconf.contract.goals import (
    MAX_EVENTS_KEPT,
    MAX_RECENT_KEPT,
    MAX_TASKS_KEPT,
    MAX_TEXT,
    MAX_VITALS,
    BrainEvent,
    CurrentGoal,
    GoalsSummary,
    LastOutcome,
    TaskCounts,
    VitalValue,
    success_rate,
)
from robotconf.contract.textsafe import shorten

MAX_ID = 128  # characters of a goal id or a task name kept (the contract's own bound)
UNKNOWN = "unknown"  # the goals cell and state of a robot that does not report its goals
ERROR = "error"  # ... whose summary cannot be read
REPORTING = "reporting"
COUNTS = ("completed", "failed", "canceled", "underway", "stale")


def cut(text: str | None, limit: int = MAX_TEXT) -> str | None:
    """`text` cut to `limit` characters (ended by …); None stays None."""
    return None if text is None else shorten(text, limit)


def _vital(value: VitalValue) -> VitalValue:
    return cut(value) or "" if isinstance(value, str) else value


def _outcome(found: LastOutcome) -> LastOutcome:
    return found.model_copy(
        update={
            "goal": cut(found.goal, MAX_ID),
            "task": cut(found.task, MAX_ID),
            "code": cut(found.code),
            "message": cut(found.message),
        }
    )


def _current(found: CurrentGoal) -> CurrentGoal:
    fraction = found.fraction
    if fraction is not None and not 0.0 <= fraction <= 1.0:
        fraction = min(max(fraction, 0.0), 1.0) if fraction == fraction else None  # NaN: none
    return found.model_copy(
        update={
            "goal": cut(found.goal, MAX_ID),
            "task": cut(found.task, MAX_ID),
            "note": cut(found.note),
            "fraction": fraction,
        }
    )


def _natural(counts: TaskCounts) -> dict[str, int]:
    """The counts as numbers of goals: none below zero."""
    return {name: max(0, getattr(counts, name)) for name in COUNTS}


def _short(text: str | None, limit: int = MAX_TEXT) -> bool:
    return text is None or len(text) <= limit


def _fits(summary: GoalsSummary) -> bool:
    """True when `bounded` would change nothing: a well-behaved agent's summary, checked
    without the copy (10,000 of them are read at once by `status`)."""
    s = summary
    if (
        len(s.recent) > MAX_RECENT_KEPT
        or len(s.events) > MAX_EVENTS_KEPT
        or len(s.tasks) > MAX_TASKS_KEPT
        or len(s.vitals) > MAX_VITALS
        or min(s.completed, s.failed, s.canceled, s.underway, s.stale) < 0
        or not all(_short(t, 80) for t in (s.revision, s.digest, s.run))
        or not _short(s.scenario, MAX_ID)
    ):
        return False
    if any(
        len(name) > MAX_ID or min(c.completed, c.failed, c.canceled, c.underway, c.stale) < 0
        for name, c in s.tasks.items()
    ):
        return False
    if any(len(n) > 32 or (isinstance(v, str) and len(v) > MAX_TEXT) for n, v in s.vitals.items()):
        return False
    c = s.current
    if c is not None and not (
        _short(c.goal, MAX_ID)
        and _short(c.task, MAX_ID)
        and _short(c.note)
        and (c.fraction is None or 0.0 <= c.fraction <= 1.0)
    ):
        return False
    ended = [*s.recent, *([s.last] if s.last is not None else [])]
    return all(
        _short(o.goal, MAX_ID) and _short(o.task, MAX_ID) and _short(o.code) and _short(o.message)
        for o in ended
    ) and all(_short(e.message) for e in s.events)


def bounded(summary: GoalsSummary) -> GoalsSummary:
    """The summary with what a reader keeps of it: the newest recent outcomes and events, the
    first tasks and vitals by name, every text cut, no count below zero. A well-behaved agent's
    is returned as it is."""
    if _fits(summary):
        return summary
    tasks = {
        name: TaskCounts(**_natural(counts))
        for name, counts in sorted(summary.tasks.items())[:MAX_TASKS_KEPT]
    }
    vitals = {
        cut(name, 32) or "": _vital(value)
        for name, value in sorted(summary.vitals.items())[:MAX_VITALS]
    }
    return summary.model_copy(
        update={
            **_natural(summary),
            "tasks": {cut(name, MAX_ID) or "": counts for name, counts in tasks.items()},
            "current": _current(summary.current) if summary.current is not None else None,
            "last": _outcome(summary.last) if summary.last is not None else None,
            "recent": [_outcome(o) for o in summary.recent[-MAX_RECENT_KEPT:]],
            "events": [
                e.model_copy(update={"message": cut(e.message)})
                for e in summary.events[-MAX_EVENTS_KEPT:]
            ],
            "vitals": vitals,
            "revision": cut(summary.revision, 80),
            "digest": cut(summary.digest, 80),
            "scenario": cut(summary.scenario, MAX_ID),
            "run": cut(summary.run, 80),
        }
    )


@dataclass(frozen=True)
class RobotGoals:
    """One robot's goals as its retained summary says them (`summary` bounded), or why they are
    unknown (`note`)."""

    summary: GoalsSummary | None = None
    note: str | None = None
    unreadable: bool = False  # it published a summary that cannot be read

    @classmethod
    def of(cls, summary: GoalsSummary | None, error: str | None = None) -> RobotGoals:
        """`summary` as `bounded` keeps it (readmodel.observed reads it so, once per payload)."""
        if error is not None:
            return cls(note=f"its goals summary cannot be read: {cut(error, 300)}", unreadable=True)
        if summary is None:
            return NO_GOALS
        if not summary.reporting:
            return cls(summary, "its brain does not report goals (it does not use the library)")
        return cls(summary)

    @property
    def state(self) -> str:
        """`reporting`, `unknown` or `error`."""
        if self.unreadable:
            return ERROR
        return REPORTING if self.known else UNKNOWN

    @property
    def known(self) -> bool:
        return self.summary is not None and self.summary.reporting

    @property
    def published(self) -> bool:
        """Its agent publishes a summary (readable or not): the goals column is worth showing."""
        return self.summary is not None or self.unreadable

    def cell(self) -> str:
        """The goals column: `done/failed` since the current request, then what else is worth a
        glance (`1 stale`); `unknown` or `error` when it cannot say."""
        if not self.known or self.summary is None:
            return self.state
        s = self.summary
        text = f"{s.completed}/{s.failed}"
        if s.stale:
            text += f" {s.stale} stale"
        return text

    @property
    def failing(self) -> bool:
        """Its last goal failed or went stale: the column says it in colour."""
        s = self.summary
        if not self.known or s is None:
            return False
        return (s.current is not None and s.current.stale) or (
            s.last is not None and s.last.outcome.value in ("failed", "stale")
        )

    def as_json(self) -> dict[str, Any] | None:
        """`status --json`'s `goals`: None when unknown (no summary, or a brain that does not
        report); the counts since the current request, the goal underway, the last outcome, and
        what they are counted of."""
        s = self.summary
        if not self.known or s is None:
            return None
        return {
            **{name: getattr(s, name) for name in COUNTS},
            "current": s.current.model_dump(mode="json") if s.current is not None else None,
            "last": s.last.model_dump(mode="json") if s.last is not None else None,
            "tasks": {name: _counts(c) for name, c in s.tasks.items()},
            "recent": [o.model_dump(mode="json") for o in s.recent],
            "events": [e.model_dump(mode="json") for e in s.events],
            "revision": s.revision,
            "digest": s.digest,
            "scenario": s.scenario,
            "run": s.run,
            "since": s.since,
            "ready": s.ready,
            "dropped": s.dropped,
            "updated": s.updated,
        }

    def vitals_json(self) -> dict[str, VitalValue]:
        """`status --json`'s `vitals`: empty when none are known."""
        return dict(self.summary.vitals) if self.known and self.summary is not None else {}

    @property
    def events(self) -> list[BrainEvent]:
        return list(self.summary.events) if self.known and self.summary is not None else []


def _counts(counts: TaskCounts) -> dict[str, int]:
    return {name: getattr(counts, name) for name in COUNTS}


NO_GOALS = RobotGoals(note="its agent publishes no goals summary")


# ------------------------------------------------------------------ the fleet's success rates


@dataclass(frozen=True)
class GoalRate:
    """The goals of one scenario at one revision, summed over the robots that report them."""

    scenario: str | None
    revision: str | None
    robots: int
    completed: int = 0
    failed: int = 0
    canceled: int = 0
    underway: int = 0
    stale: int = 0
    since: float = 0.0  # the newest request start among them: the newest revisions first

    @property
    def ended(self) -> int:
        """Goals that succeeded or failed: what a success rate is of (a canceled goal was called
        off, a stale one may still end: neither is counted against the revision)."""
        return self.completed + self.failed

    @property
    def rate(self) -> float | None:
        """Succeeded / (succeeded + failed); None before any such end."""
        return success_rate(self.completed, self.failed)

    def rate_text(self) -> str:
        rate = self.rate
        return "-" if rate is None else f"{100 * rate:.0f}%"


def goal_rates(robots: Iterable[tuple[str | None, RobotGoals]]) -> tuple[list[GoalRate], int]:
    """(scenario as desired, goals) of each robot -> one GoalRate per (scenario, revision) its
    summaries count, by scenario, newest revision first; and how many robots do not report."""
    sums: dict[tuple[str | None, str | None], list[float]] = {}
    silent = 0
    for desired_scenario, goals in robots:
        s = goals.summary
        if not goals.known or s is None:
            silent += 1
            continue
        key = (s.scenario or desired_scenario, s.revision)
        found = sums.setdefault(key, [0, 0, 0, 0, 0, 0, 0.0])
        found[0] += 1
        for index, name in enumerate(COUNTS, start=1):
            found[index] += getattr(s, name)
        found[6] = max(found[6], s.since or 0.0)
    rates = [
        GoalRate(
            scenario,
            revision,
            int(n[0]),
            int(n[1]),
            int(n[2]),
            int(n[3]),
            int(n[4]),
            int(n[5]),
            n[6],
        )
        for (scenario, revision), n in sums.items()
    ]
    rates.sort(key=lambda r: (r.scenario or "", -r.since, r.revision or ""))
    return rates, silent
