"""Goal outcomes, pure: a record checked before it is trusted, the ledger's rows tallied into
what a revision achieved (revision → scenario → task → counts, rates, durations), the
comparison with the revision before, and the streaks that make a robot's goals failing.

No SQLite and no MQTT here: `readmodel/ledger.py` is the edge that feeds these functions.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from pydantic import ValidationError

from robotconf.contract.goals import (
    CODE_PATTERN,
    GOAL_ID_PATTERN,
    MAX_TEXT,
    TASK_PATTERN,
    OutcomeRecord,
    OutcomeState,
    success_rate,
)
from robotconf.contract.safejson import PayloadError, parse_object
from robotconf.contract.textsafe import printable, shorten
from robotconf.readmodel.events import Event, Kind

MAX_RECORD_BYTES = 8 * 1024  # one OutcomeRecord: its texts are cut at MAX_TEXT by the agent
MAX_ID = 80  # characters of a run, a revision or a digest
MAX_SCENARIO = 128
NO_REVISION = "(none)"  # records of a brain that ran under no known revision
NO_SCENARIO = "(none)"
MAX_SEQ = 2**63 - 1  # SQLite's largest integer
_CODE = re.compile(CODE_PATTERN)
_GOAL = re.compile(GOAL_ID_PATTERN)
_TASK = re.compile(TASK_PATTERN)
_ID = re.compile(r"^[A-Za-z0-9_.:+=/-]{1,80}$")
_SCENARIO = re.compile(r"^[A-Za-z0-9_.-]{1,128}$")
# What counts toward a robot's failing streak, and what ends one.
FAILING = frozenset({OutcomeState.FAILED})  # stale may still end: never failing
DEFAULT_STREAK = 3  # failed goals in a row before a robot's goals are failing


class Row(NamedTuple):
    """One outcome as the ledger keeps it, the columns evidence needs."""

    id: int
    robot_id: str
    digest: str | None
    scenario: str
    outcome: str
    code: str | None
    received_at: float


class RecordRefused(ValueError):
    """An outcome record that is not trusted: its reason, in one line."""


def check_record(topic_robot: str, payload: bytes) -> OutcomeRecord:
    """The record a robot published on its outcomes topic, checked: its size, its model, its
    robot id equal to the topic's (a robot writes only its own topics, so a record naming
    another robot is a lie), its names of the shapes they have; its texts escaped and cut.
    RecordRefused says why not."""
    if len(payload) > MAX_RECORD_BYTES:
        raise RecordRefused(f"{len(payload):,} bytes, over the limit of {MAX_RECORD_BYTES:,}")
    try:
        record = OutcomeRecord.model_validate(parse_object(payload, max_bytes=MAX_RECORD_BYTES))
    except PayloadError as exc:
        raise RecordRefused(str(exc)) from None
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(part) for part in first["loc"]) or "record"
        raise RecordRefused(f"not an OutcomeRecord: {where}: {first['msg']}") from None
    if record.robot_id != topic_robot:
        raise RecordRefused(
            f"its robot_id {printable(record.robot_id[:MAX_ID])!r} is not its topic's robot"
        )
    _shaped(record.run, _ID, "run")
    _shaped(record.goal, _GOAL, "goal")
    _shaped(record.task, _TASK, "task")
    for name in ("revision", "digest"):
        value = getattr(record, name)
        if value is not None:
            _shaped(value, _ID, name)
    if record.scenario is not None:
        _shaped(record.scenario, _SCENARIO, "scenario")
    if record.code is not None:
        _shaped(record.code, _CODE, "code")
    if record.seq > MAX_SEQ:
        raise RecordRefused("seq is too large")
    times = (record.ended_at, record.started_at, record.duration)
    if any(t is not None and (not math.isfinite(t) or t < 0) for t in times):
        raise RecordRefused("a time or duration is not a finite, positive number")
    if record.message is not None:
        record = record.model_copy(update={"message": shorten(printable(record.message), MAX_TEXT)})
    return record


def _shaped(value: str, pattern: re.Pattern[str], name: str) -> None:
    if not pattern.match(value):
        raise RecordRefused(f"its {name} is not of the shape {pattern.pattern}")


# ---------------------------------------------------------------- what a revision achieved


@dataclass(frozen=True)
class Group:
    """One row of the ledger's aggregate queries: outcomes of one revision and outcome, of
    one scenario and task (`robot_id` empty) or of one robot (`scenario`, `task` empty), with
    the sum and count of their known durations."""

    revision: str
    outcome: OutcomeState
    count: int
    duration_sum: float = 0.0
    durations: int = 0  # how many of `count` had a duration
    scenario: str = ""
    task: str = ""
    robot_id: str = ""


@dataclass(frozen=True)
class Tally:
    """Ended goals counted by outcome, with the success rate (`contract.goals.success_rate`)
    and the mean duration of the succeeded ones."""

    succeeded: int = 0
    failed: int = 0
    canceled: int = 0
    stale: int = 0
    duration_sum: float = 0.0  # of succeeded goals with a known duration
    durations: int = 0

    @property
    def total(self) -> int:
        return self.succeeded + self.failed + self.canceled + self.stale

    @property
    def success_rate(self) -> float | None:
        return success_rate(self.succeeded, self.failed)

    @property
    def mean_duration(self) -> float | None:
        return self.duration_sum / self.durations if self.durations else None

    def add(self, group: Group) -> Tally:
        outcome, n = group.outcome, group.count
        succeeded = outcome is OutcomeState.SUCCEEDED
        return Tally(
            succeeded=self.succeeded + (n if succeeded else 0),
            failed=self.failed + (n if outcome is OutcomeState.FAILED else 0),
            canceled=self.canceled + (n if outcome is OutcomeState.CANCELED else 0),
            stale=self.stale + (n if outcome is OutcomeState.STALE else 0),
            duration_sum=self.duration_sum + (group.duration_sum if succeeded else 0.0),
            durations=self.durations + (group.durations if succeeded else 0),
        )

    def as_json(self) -> dict[str, Any]:
        rate, mean = self.success_rate, self.mean_duration
        return {
            "succeeded": self.succeeded,
            "failed": self.failed,
            "canceled": self.canceled,
            "stale": self.stale,
            "total": self.total,
            "success_rate": None if rate is None else round(rate, 4),
            "mean_duration": None if mean is None else round(mean, 3),
        }


@dataclass(frozen=True)
class ScenarioReport:
    tally: Tally
    tasks: dict[str, Tally]  # task -> its tally, by name


@dataclass(frozen=True)
class RevisionReport:
    """What one revision achieved: in all, per scenario and task, per robot; and the failure
    codes seen most (code -> count, most first)."""

    revision: str
    tally: Tally
    scenarios: dict[str, ScenarioReport]
    robots: dict[str, Tally]
    codes: dict[str, int] = field(default_factory=dict)
    first_seen: float | None = None
    last_seen: float | None = None

    def worst_robots(self, limit: int | None = None) -> list[tuple[str, Tally]]:
        """Robots by their success rate, lowest first (then most failures, then id)."""
        ranked = sorted(
            self.robots.items(),
            key=lambda item: (
                _rate_key(item[1].success_rate),
                -item[1].failed,
                item[0],
            ),
        )
        return ranked if limit is None else ranked[:limit]

    def as_json(self) -> dict[str, Any]:
        return {
            "revision": self.revision,
            "first_seen": self.first_seen,
            "last_seen": self.last_seen,
            **self.tally.as_json(),
            "codes": self.codes,
            "scenarios": {
                name: {
                    **scenario.tally.as_json(),
                    "tasks": {task: t.as_json() for task, t in scenario.tasks.items()},
                }
                for name, scenario in self.scenarios.items()
            },
            "robots": {robot: t.as_json() for robot, t in self.worst_robots()},
        }


def _rate_key(rate: float | None) -> float:
    return 2.0 if rate is None else rate


def aggregate(
    revision: str,
    tasks: Iterable[Group],
    robots: Iterable[Group] = (),
    codes: Mapping[str, int] | None = None,
    *,
    first_seen: float | None = None,
    last_seen: float | None = None,
) -> RevisionReport:
    """The ledger's rows of one revision, tallied: revision → scenario → task (from `tasks`,
    grouped by scenario and task) and per robot (from `robots`, grouped by robot)."""
    total = Tally()
    scenarios: dict[str, tuple[Tally, dict[str, Tally]]] = {}
    for group in tasks:
        total = total.add(group)
        scenario, by_task = scenarios.get(group.scenario, (Tally(), {}))
        by_task[group.task] = by_task.get(group.task, Tally()).add(group)
        scenarios[group.scenario] = (scenario.add(group), by_task)
    per_robot: dict[str, Tally] = {}
    for group in robots:
        per_robot[group.robot_id] = per_robot.get(group.robot_id, Tally()).add(group)
    return RevisionReport(
        revision=revision,
        tally=total,
        scenarios={
            name: ScenarioReport(tally, dict(sorted(by_task.items())))
            for name, (tally, by_task) in sorted(scenarios.items())
        },
        robots=per_robot,
        codes=dict(sorted((codes or {}).items(), key=lambda item: (-item[1], item[0]))),
        first_seen=first_seen,
        last_seen=last_seen,
    )


@dataclass(frozen=True)
class Change:
    """One scenario's or task's success rate now and in the revision before."""

    scenario: str
    task: str | None  # None: the scenario as a whole
    rate: float | None
    before: float | None

    @property
    def delta(self) -> float | None:
        if self.rate is None or self.before is None:
            return None
        return self.rate - self.before

    def as_json(self) -> dict[str, Any]:
        delta = self.delta
        return {
            "scenario": self.scenario,
            "task": self.task,
            "success_rate": None if self.rate is None else round(self.rate, 4),
            "before": None if self.before is None else round(self.before, 4),
            "delta": None if delta is None else round(delta, 4),
        }


@dataclass(frozen=True)
class History:
    """What a revision achieved, beside the revision before it (None: the first one seen).
    `robot` and `since` say how both were narrowed."""

    report: RevisionReport
    before: RevisionReport | None
    robot: str | None = None
    since: float | None = None

    @property
    def changes(self) -> list[Change]:
        return compare(self.report, self.before)

    def as_json(self) -> dict[str, Any]:
        return {
            "robot": self.robot,
            "since": self.since,
            "revision": self.report.as_json(),
            "before": None if self.before is None else self.before.as_json(),
            "changes": [change.as_json() for change in self.changes],
        }


def compare(report: RevisionReport, before: RevisionReport | None) -> list[Change]:
    """Each scenario's and task's success rate beside the revision before's, scenario first
    then its tasks; those of either revision."""
    old = before.scenarios if before is not None else {}
    changes: list[Change] = []
    for name in sorted(set(report.scenarios) | set(old)):
        now_s, then_s = report.scenarios.get(name), old.get(name)
        changes.append(Change(name, None, _rate(now_s), _rate(then_s)))
        tasks_now = now_s.tasks if now_s else {}
        tasks_then = then_s.tasks if then_s else {}
        for task in sorted(set(tasks_now) | set(tasks_then)):
            now_t, then_t = tasks_now.get(task), tasks_then.get(task)
            changes.append(
                Change(
                    name,
                    task,
                    now_t.success_rate if now_t else None,
                    then_t.success_rate if then_t else None,
                )
            )
    return changes


def _rate(scenario: ScenarioReport | None) -> float | None:
    return scenario.tally.success_rate if scenario is not None else None


# ---------------------------------------------------------------- failing streaks


@dataclass(frozen=True)
class Streak:
    """A robot's failed goals in a row, and whether it was told failing."""

    count: int = 0
    failing: bool = False


@dataclass(frozen=True)
class StreakEvent:
    robot_id: str
    failing: bool  # True: its goals started failing; False: they recovered
    streak: int  # failures in a row (when failing), or the streak it recovered from
    record: OutcomeRecord  # the outcome that made the transition


def advance(
    streaks: Mapping[str, Streak], records: Sequence[OutcomeRecord], threshold: int
) -> tuple[dict[str, Streak], list[StreakEvent]]:
    """The robots' streaks after `records` (in arrival order), and the transitions to tell:
    once when a robot reaches `threshold` failures in a row, once at its next success.
    A canceled goal neither breaks nor lengthens a streak. Only robots in `records` are in
    the result (the caller keeps the rest)."""
    changed: dict[str, Streak] = {}
    events: list[StreakEvent] = []
    for record in records:
        robot = record.robot_id
        streak = changed.get(robot) or streaks.get(robot) or Streak()
        if record.outcome in FAILING:
            count = streak.count + 1
            if not streak.failing and count >= threshold:
                events.append(StreakEvent(robot, True, count, record))
                streak = Streak(count, True)
            else:
                streak = Streak(count, streak.failing)
        elif record.outcome is OutcomeState.SUCCEEDED:
            if streak.failing:
                events.append(StreakEvent(robot, False, streak.count, record))
            streak = Streak()
        changed[robot] = streak
    return changed, events


def streak_event(found: StreakEvent) -> Event:
    """The alert of a streak's transition, as receivers get it (`reconciler/notify.py`)."""
    record = found.record
    task = f"{record.task} (goal {record.goal})"
    if found.failing:
        why = record.outcome.value
        if record.code:
            why += f" {record.code}"
        if record.message:
            why += f": {record.message}"
        message = f"{found.robot_id}: {found.streak} goals in a row failed; the last, {task}: {why}"
        kind, reason = Kind.ROBOT_GOALS_FAILING, record.code or record.outcome.value
    else:
        message = f"{found.robot_id}: goals succeed again ({task}), after {found.streak} failed"
        kind, reason = Kind.ROBOT_GOALS_RECOVERED, record.outcome.value
    return Event(
        kind,
        message,
        record.ended_at,
        revision=record.revision,
        robot=found.robot_id,
        reason=reason,
    )


# ---------------------------------------------------------------- metrics' labels

MAX_LABEL_VALUES = 64  # scenarios (and tasks) a metric names; robots cannot grow it further
OTHER = "(other)"


class BoundedLabels:
    """A label's values as a metric shows them: the first `limit` distinct ones by name, the
    rest as OTHER. What robots report cannot make unbounded series (records are checked, so
    each value is a short name already)."""

    def __init__(self, limit: int = MAX_LABEL_VALUES) -> None:
        self.limit = limit
        self._known: set[str] = set()

    def label(self, value: str) -> str:
        if value in self._known:
            return value
        if len(self._known) >= self.limit:
            return OTHER
        self._known.add(value)
        return value
