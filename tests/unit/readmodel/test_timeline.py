"""The timeline, pure: its own events (a commit applied, a wave started, a restart from the desk
and by whom) once each, not again after a restart; the filter as a person types it, every
refusal one line naming what would be right; every kept field bounded."""

from __future__ import annotations

import pytest

from robotconf.contract.wire import (
    AgentState,
    AgentStatus,
    CommitLine,
    ReconcilerStatus,
    RolloutStatus,
)
from robotconf.readmodel.events import Event, Kind
from robotconf.readmodel.timeline import (
    KINDS,
    MAX_FIELD,
    MAX_LIMIT,
    MAX_MESSAGE,
    MAX_SINCE,
    EventQuery,
    KeptEvent,
    Noted,
    QueryRefused,
    event_query,
    noted_at_start,
    stored,
    timeline_transitions,
)

A, B = "a" * 40, "b" * 40
NOW = 1_000_000.0


def applied(revision: str, reason: str = "Applied") -> ReconcilerStatus:
    return ReconcilerStatus(
        state="Ready",
        ready=True,
        reason=reason,
        branch="main",
        last_applied_revision=revision,
        message="3 robots",
    )


def rolling(revision: str, wave: int, state: str = "Progressing") -> ReconcilerStatus:
    rollout = RolloutStatus(revision=revision, state=state, wave=wave, waves=3, wave_name="canary")
    return ReconcilerStatus(
        state="Progressing",
        ready=False,
        reason="Progressing",
        branch="main",
        last_applied_revision=A,
        rollout=rollout,
    )


def robot(by: str | None, at: float | None, state: AgentState = AgentState.RUNNING) -> AgentStatus:
    return AgentStatus(
        robot_id="tb3-02", state=state, restart_requested_by=by, restart_requested_at=at
    )


def kinds_of(events: list[Event]) -> list[Kind]:
    return [event.kind for event in events]


def test_a_head_applied_is_noted_once_per_revision() -> None:
    noted, first = timeline_transitions(Noted(), applied(A), None, NOW)
    assert kinds_of(first) == [Kind.COMMIT_APPLIED]
    assert first[0].revision == A and "applied: 3 robots" in first[0].message
    noted, again = timeline_transitions(noted, applied(A), None, NOW + 30)
    assert again == []
    noted, refused = timeline_transitions(noted, applied(A, "BuildFailed"), None, NOW + 60)
    assert refused == []  # a refusal is the alerts' to tell
    _, second = timeline_transitions(noted, applied(B), None, NOW + 90)
    assert kinds_of(second) == [Kind.COMMIT_APPLIED] and second[0].revision == B


def test_a_restarted_reconciler_does_not_note_again_what_it_found() -> None:
    noted = noted_at_start(Noted(), rolling(B, 1))
    _, events = timeline_transitions(noted, applied(A), None, NOW)
    assert events == []  # A was applied under the one before
    _, events = timeline_transitions(noted, rolling(B, 1), None, NOW)
    assert events == []  # and B's wave 2 started under it
    _, events = timeline_transitions(noted, rolling(B, 2), None, NOW)
    assert kinds_of(events) == [Kind.WAVE_STARTED]
    assert "wave 'canary' (3 of 3) started" in events[0].message


def test_a_wave_is_noted_once_and_not_while_the_rollout_stopped() -> None:
    noted, events = timeline_transitions(Noted(), rolling(B, 0), None, NOW)
    assert kinds_of(events) == [Kind.WAVE_STARTED]
    noted, events = timeline_transitions(noted, rolling(B, 0, "Paused"), None, NOW)
    assert events == []
    _, events = timeline_transitions(noted, rolling(B, 1, "RolledBack"), None, NOW)
    assert events == []


def test_a_restart_from_the_desk_is_noted_once_with_who_asked() -> None:
    noted, events = timeline_transitions(Noted(), None, {"tb3-02": robot(None, None)}, NOW, NOW)
    assert events == []
    asked = {"tb3-02": robot("alice", NOW + 5)}
    noted, events = timeline_transitions(noted, None, asked, NOW + 6, NOW)
    assert kinds_of(events) == [Kind.ROBOT_RESTARTED]
    event = events[0]
    assert (event.robot, event.by) == ("tb3-02", "alice")
    assert event.message == "tb3-02 restarted from the desk by alice"
    assert event.as_json()["by"] == "alice"
    noted, events = timeline_transitions(noted, None, asked, NOW + 7, NOW)
    assert events == []  # the status keeps naming it: once
    again = {"tb3-02": robot("bob", NOW + 20, AgentState.DEFERRED)}
    _, events = timeline_transitions(noted, None, again, NOW + 21, NOW)
    assert [e.by for e in events] == ["bob"] and "deferred" in events[0].message


def test_a_restart_asked_before_this_process_watched_is_not_noted_again() -> None:
    old = {"tb3-02": robot("alice", NOW - 100)}
    _, events = timeline_transitions(Noted(), None, old, NOW, NOW)
    assert events == []
    new = {"tb3-02": robot("alice", NOW + 1)}
    _, events = timeline_transitions(Noted(), None, new, NOW + 2, NOW)
    assert [e.by for e in events] == ["alice"]


def test_the_alerts_payload_has_no_by_unless_there_is_a_who() -> None:
    event = Event(Kind.COMMIT_REFUSED, "refused", NOW, "main", A)
    assert "by" not in event.as_json()


def test_a_query_as_typed() -> None:
    assert event_query(now=NOW) == EventQuery()
    assert event_query(" ", "", "", now=NOW) == EventQuery()
    asked = event_query("tb3-02", "commit_refused", "2h", now=NOW, limit=10)
    assert asked == EventQuery("tb3-02", "commit_refused", NOW - 7200, 10)
    far = event_query(since="99999999999999999999w", now=NOW)
    assert far.since == NOW - MAX_SINCE  # everything kept, not an overflow


@pytest.mark.parametrize(
    ("robot", "kind", "since", "limit", "said"),
    [
        (None, "comit_refused", None, 10, "not an event kind: one of commit_refused,"),
        (None, "x" * 10_000, None, 10, "not an event kind"),
        ("tb3 02; drop", None, None, 10, "is not a robot id"),
        ("r" * 10_000, None, None, 10, "is not a robot id"),
        (None, None, "yesterday", 10, "since: 'yesterday' is not a duration"),
        (None, None, "1" * 100, 10, "since: 100 characters is not a duration"),
        (None, None, "0s", 10, "not a positive duration"),
        (None, None, None, 0, f"give 1 to {MAX_LIMIT} events"),
        (None, None, None, MAX_LIMIT + 1, f"give 1 to {MAX_LIMIT} events"),
    ],
)
def test_a_query_refused_says_what_would_be_right(
    robot: str | None, kind: str | None, since: str | None, limit: int, said: str
) -> None:
    with pytest.raises(QueryRefused) as refused:
        event_query(robot, kind, since, now=NOW, limit=limit)
    assert said in str(refused.value)
    assert len(str(refused.value)) < 1200 and "\n" not in str(refused.value)


def test_a_wrong_kind_lists_every_kind() -> None:
    with pytest.raises(QueryRefused) as refused:
        event_query(kind="nope", now=NOW)
    for kind in KINDS:
        assert kind in str(refused.value)
    assert {"commit_applied", "wave_started", "robot_restarted", "robot_offline"} <= set(KINDS)


def test_what_is_kept_is_bounded() -> None:
    huge = Event(
        Kind.ROBOT_DEGRADED, "m" * 100_000, NOW, "b" * 5000, "r" * 5000, "x" * 5000, "y" * 5000
    )
    kept = stored(huge)
    assert len(kept.message) == MAX_MESSAGE and kept.message.endswith("…")
    assert {len(kept.branch or ""), len(kept.revision or ""), len(kept.robot or "")} == {MAX_FIELD}
    assert kept.kind == "robot_degraded"


def test_a_kept_event_as_a_line_and_as_json() -> None:
    said = "tb3-02 restarted\x1b[2J by alice"
    kept = KeptEvent(0.0, "robot_restarted", said, "tb3-02", by="alice")
    assert kept.line().startswith("1970-01-01 00:00:00 UTC  robot_restarted  tb3-02  ")
    assert "\x1b" not in kept.line()  # a robot's words made inert
    assert kept.as_json()["by"] == "alice" and kept.as_json()["event"] == "robot_restarted"


def test_each_timeline_line_names_its_commit_by_subject_and_says_applied_once() -> None:
    """The reconciler's status carries the subjects of the commits it names: the timeline's
    own events (a commit applied, a wave started) carry them as the alerts' events do."""
    line = CommitLine(revision=A, subject="delivery: a new planner", author="ada")
    status = applied(A).model_copy(update={"message": f"applied {A[:12]}", "commits": [line]})
    _, events = timeline_transitions(Noted(), status, None, NOW)
    (event,) = events
    assert event.subject == "delivery: a new planner"
    assert event.message == f"{A[:12]} on main applied"  # not "applied: applied aaaa..."
    stale = status.model_copy(update={"message": f"applied {A[:12]}, but the last fetch failed"})
    _, (event,) = timeline_transitions(Noted(), stale, None, NOW)
    assert event.message == f"{A[:12]} on main applied: but the last fetch failed"
    wave = rolling(A, 0).model_copy(update={"commits": [line]})
    _, events = timeline_transitions(Noted(), wave, None, NOW)
    assert [e.subject for e in events if e.kind is Kind.WAVE_STARTED] == [line.subject]
