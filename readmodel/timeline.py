"""The fleet's timeline, pure: the events kept in the ledger beside the alerts, and how they are
asked for.

The alerts (`readmodel/events.py`) are the transitions worth telling a person; the timeline
keeps them all, and three more that would be noise in a chat but are the fleet's history: a
commit applied, a rollout's wave started, a robot restarted from the desk (and by whom). Those
three are judged here (`timeline_transitions`), with their own memory (`Noted`).

What is asked of the kept events (`EventQuery`: a robot, a kind, a time since; newest first;
at most `limit`) is checked here from what a person typed (`event_query`), each refusal one
line naming what would be right; what is kept is bounded here (`stored`), every field cut to
a length, so that no robot's message makes the ledger or a page grow without end.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from robotconf.contract.durations import MAX_SECONDS, parse_duration
from robotconf.contract.models import is_robot_id
from robotconf.contract.textsafe import printable
from robotconf.contract.wire import (
    AgentState,
    AgentStatus,
    ReconcilerReason,
    ReconcilerStatus,
    RolloutStatus,
    short_rev,
)
from robotconf.readmodel.events import REMEMBERED, Event, Kind, with_subject

KINDS = tuple(kind.value for kind in Kind)  # what --kind and the page's filter accept
DEFAULT_LIMIT = 200  # events listed unless asked for more
MAX_LIMIT = 5000
MAX_SINCE_TEXT = 32  # characters of a --since (a duration is `30m`, `7d`)
MAX_SINCE = MAX_SECONDS  # ten years: further back is everything the ledger keeps
MAX_MESSAGE = 2000  # characters of an event's message kept
MAX_FIELD = 200  # characters of every other text field kept
_WAVE_GOING = {"Progressing", "Paused"}


class QueryRefused(ValueError):
    """A filter that cannot be asked, in one line naming what would be right."""


@dataclass(frozen=True)
class EventQuery:
    """The kept events asked for: of `robot`, of `kind`, at or after `since` (unix time);
    newest first, at most `limit`."""

    robot: str | None = None
    kind: str | None = None
    since: float | None = None
    limit: int = DEFAULT_LIMIT


def event_query(
    robot: str | None = None,
    kind: str | None = None,
    since: str | None = None,
    *,
    now: float,
    limit: int = DEFAULT_LIMIT,
) -> EventQuery:
    """The query of what a person typed (a blank field: no filter); QueryRefused when a
    field is not a robot id, an event kind, a duration, or a limit from 1 to MAX_LIMIT."""
    robot = (robot or "").strip() or None
    if robot is not None and (len(robot) > MAX_FIELD or not is_robot_id(robot)):
        raise QueryRefused(
            f"robot {printable(robot[:64])!r} is not a robot id (letters, digits, '-', '_', '.')"
        )
    kind = (kind or "").strip() or None
    if kind is not None and kind not in KINDS:
        raise QueryRefused(
            f"kind {printable(kind[:64])!r} is not an event kind: one of {', '.join(KINDS)}"
        )
    after = None
    since = (since or "").strip() or None
    if since is not None:
        if len(since) > MAX_SINCE_TEXT:
            raise QueryRefused(f"since: {len(since)} characters is not a duration (e.g. 2h, 7d)")
        try:
            after = now - parse_duration(since, clamp=True)
        except ValueError as exc:
            raise QueryRefused(f"since: {exc}") from None
    if not 1 <= limit <= MAX_LIMIT:
        raise QueryRefused(f"limit {limit}: give 1 to {MAX_LIMIT} events")
    return EventQuery(robot, kind, after, limit)


@dataclass(frozen=True)
class KeptEvent:
    """An event as the ledger keeps it. `kind` is text: a ledger written by a newer robotconf
    may hold kinds this one does not know, and they are shown as they are."""

    at: float
    kind: str
    message: str
    robot: str | None = None
    branch: str | None = None
    revision: str | None = None
    reason: str | None = None
    refused_revision: str | None = None
    by: str | None = None
    subject: str | None = None  # the subject of `revision`'s commit, when it was known

    def as_json(self) -> dict[str, Any]:
        return {
            "at": self.at,
            "event": self.kind,
            "robot": self.robot,
            "branch": self.branch,
            "revision": self.revision,
            "reason": self.reason,
            "by": self.by,
            "refused_revision": self.refused_revision,
            "subject": self.subject,
            "message": self.message,
        }

    def line(self) -> str:
        """`2026-11-24 12:00:03 UTC  commit_refused  -  0a1b2c3d4e5f on main refused ...`:
        the robot's words made inert (no terminal escape reaches the screen)."""
        when = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(self.at))
        robot = printable(self.robot) if self.robot else "-"
        subject = f' ("{printable(self.subject)}")' if self.subject else ""
        return f"{when}  {printable(self.kind)}  {robot}  {printable(self.message)}{subject}"


def _cut(text: str | None, limit: int = MAX_FIELD) -> str | None:
    return None if text is None else text[:limit]


def stored(event: Event) -> KeptEvent:
    """What the ledger keeps of `event`: every field bounded."""
    message = event.message
    if len(message) > MAX_MESSAGE:
        message = message[: MAX_MESSAGE - 1] + "…"
    return KeptEvent(
        at=event.at,
        kind=event.kind.value,
        message=message,
        robot=_cut(event.robot),
        branch=_cut(event.branch),
        revision=_cut(event.revision),
        reason=_cut(event.reason),
        refused_revision=_cut(event.refused_revision),
        by=_cut(event.by),
        subject=_cut(event.subject),
    )


# ---------------------------------------------------------------------- timeline-only events


@dataclass(frozen=True)
class Noted:
    """What the timeline noted so far (the memory of its own transitions)."""

    applied: tuple[str, ...] = ()  # revisions noted applied, oldest first
    waves: tuple[tuple[str, int], ...] = ()  # (revision, wave) noted started
    # robot -> the desk restart its status named when last seen (None: none)
    restarts: Mapping[str, float | None] = field(default_factory=dict)


def _remember(items: tuple[Any, ...], item: Any) -> tuple[Any, ...]:
    return (*items, item)[-REMEMBERED:]


def noted_at_start(noted: Noted, found: ReconcilerStatus | None) -> Noted:
    """What a restarted reconciler knows was noted, from the status it found on the broker:
    the revision applied there and the wave under way were noted by the one before."""
    if found is None:
        return noted
    if found.last_applied_revision and found.last_applied_revision not in noted.applied:
        noted = replace(noted, applied=_remember(noted.applied, found.last_applied_revision))
    rollout = found.rollout
    if rollout is not None and (rollout.revision, rollout.wave) not in noted.waves:
        noted = replace(noted, waves=_remember(noted.waves, (rollout.revision, rollout.wave)))
    return noted


def timeline_transitions(
    noted: Noted,
    status: ReconcilerStatus | None,
    robots: Mapping[str, AgentStatus] | None,
    at: float,
    watching_since: float = 0.0,
) -> tuple[Noted, list[Event]]:
    """The timeline-only events: a head applied, once per revision; a rollout's wave
    started, once per (revision, wave); a robot restarted from the desk, once per restart
    its status names. A robot seen for the first time names a restart asked before
    `watching_since` (this process began watching) that another process already noted: it
    is not noted again."""
    events: list[Event] = []
    branch = status.branch if status is not None else None
    if status is not None:
        noted, applied = _applied(noted, status, at)
        events += applied
        if status.rollout is not None:
            noted, wave = _wave(noted, status.rollout, branch, at)
            events += wave
    if robots is not None:
        noted, restarts = _restarts(noted, robots, branch, at, watching_since)
        events += restarts
    # Every line names its commit by its subject, as the alerts' events do, when the status
    # describes that commit.
    return noted, [with_subject(event, status) for event in events]


def _applied(noted: Noted, status: ReconcilerStatus, at: float) -> tuple[Noted, list[Event]]:
    revision = status.last_applied_revision
    if status.reason != ReconcilerReason.APPLIED.value or not revision:
        return noted, []
    if revision in noted.applied:
        return noted, []
    # The status's own words ("applied 9f3c2e1a7b4d, but the last fetch failed ...") after
    # the revision, without saying "applied" twice.
    said = (status.message or "").removeprefix(f"applied {short_rev(revision)}").lstrip(", ")
    message = f"{short_rev(revision)} on {status.branch} applied" + (f": {said}" if said else "")
    event = Event(Kind.COMMIT_APPLIED, message, at, status.branch, revision, reason=status.reason)
    return replace(noted, applied=_remember(noted.applied, revision)), [event]


def _wave(
    noted: Noted, rollout: RolloutStatus, branch: str | None, at: float
) -> tuple[Noted, list[Event]]:
    key = (rollout.revision, rollout.wave)
    if rollout.state not in _WAVE_GOING or rollout.waves < 1 or key in noted.waves:
        return noted, []
    name = f"'{rollout.wave_name}' " if rollout.wave_name else ""
    stage = f" (stage '{rollout.stage}')" if rollout.stage else ""
    message = (
        f"rollout of {short_rev(rollout.revision)} on {branch}: wave {name}"
        f"({rollout.wave + 1} of {rollout.waves}){stage} started"
    )
    event = Event(Kind.WAVE_STARTED, message, at, branch, rollout.revision, reason=rollout.state)
    return replace(noted, waves=_remember(noted.waves, key)), [event]


def _restarts(
    noted: Noted,
    robots: Mapping[str, AgentStatus],
    branch: str | None,
    at: float,
    watching_since: float,
) -> tuple[Noted, list[Event]]:
    """A restart from the desk stays named in the robot's status until its next request:
    told when the (who, when) it names is new. Robots whose status is gone are forgotten."""
    events: list[Event] = []
    seen: dict[str, float | None] = {}
    for robot_id, status in sorted(robots.items()):
        stamp = status.restart_requested_at
        seen[robot_id] = stamp
        if stamp is None or not status.restart_requested_by:
            continue
        if robot_id in noted.restarts:
            new = noted.restarts[robot_id] != stamp
        else:
            new = stamp >= watching_since
        if not new:
            continue
        by = status.restart_requested_by
        waits = (
            " (deferred: its brain's hold file holds it off)"
            if status.state is AgentState.DEFERRED
            else ""
        )
        events.append(
            Event(
                Kind.ROBOT_RESTARTED,
                f"{robot_id} restarted from the desk by {by}{waits}",
                at,
                branch,
                status.revision,
                robot_id,
                status.state.value,
                by=by,
            )
        )
    return replace(noted, restarts=seen), events
