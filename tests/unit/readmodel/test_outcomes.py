"""Goal outcomes, pure: records checked before they are trusted, tallies, the comparison with
the revision before, failing streaks and their events, bounded metric labels, durations."""

from __future__ import annotations

import json
from typing import Any

import pytest

from robotconf.contract.durations import parse_duration
from robotconf.contract.goals import OutcomeRecord, OutcomeState
from robotconf.readmodel.events import Kind
from robotconf.readmodel.outcomes import (
    MAX_RECORD_BYTES,
    OTHER,
    BoundedLabels,
    Group,
    RecordRefused,
    Streak,
    Tally,
    advance,
    aggregate,
    check_record,
    compare,
    streak_event,
)

S, F, C, ST = (
    OutcomeState.SUCCEEDED,
    OutcomeState.FAILED,
    OutcomeState.CANCELED,
    OutcomeState.STALE,
)


def fields(**changes: Any) -> dict[str, Any]:
    found: dict[str, Any] = {
        "kind": "OutcomeRecord",
        "robot_id": "tb3-01",
        "revision": "ab" * 20,
        "digest": "sha256:" + "0" * 64,
        "scenario": "delivery-gazebo",
        "run": "run-1",
        "seq": 3,
        "goal": "g3",
        "task": "Delivery",
        "outcome": "failed",
        "code": "NAV2_TIMEOUT",
        "message": "blocked",
        "started_at": 100.0,
        "ended_at": 110.0,
        "duration": 10.0,
    }
    found.update(changes)
    return found


def payload(**changes: Any) -> bytes:
    return json.dumps(fields(**changes)).encode()


def test_a_good_record_is_trusted_and_its_message_escaped_and_cut() -> None:
    record = check_record("tb3-01", payload(message="\x1b[2J" + "x" * 500))
    assert record.outcome is F and record.code == "NAV2_TIMEOUT"
    assert record.message is not None and "\x1b" not in record.message
    assert len(record.message) <= 200 and record.message.endswith("…")


@pytest.mark.parametrize(
    ("raw", "why"),
    [
        (payload(robot_id="tb3-02"), "not its topic's robot"),
        (b"{not json", ""),
        (b"[1, 2]", ""),
        (payload(outcome="exploded"), "not an OutcomeRecord: outcome"),
        (payload(seq=-1), "not an OutcomeRecord: seq"),
        (payload(task="two words"), "its task"),
        (payload(goal="g" * 65), "its goal"),
        (payload(code="bad code!"), "its code"),
        (payload(run="r\n1"), "its run"),
        (payload(revision="x" * 81), "its revision"),
        (payload(scenario="../etc"), "its scenario"),
        (payload(seq=2**63), "seq is too large"),
        (payload(duration=-1.0), "finite, positive"),
        (b'{"ended_at": 1e999}', ""),
        (payload(message="x" * MAX_RECORD_BYTES), "over the limit"),
    ],
)
def test_records_that_cannot_be_trusted_are_refused(raw: bytes, why: str) -> None:
    with pytest.raises(RecordRefused) as refused:
        check_record("tb3-01", raw)
    assert why in str(refused.value)
    assert "\n" not in str(refused.value)


def group(outcome: OutcomeState, count: int, **where: Any) -> Group:
    return Group("rev", outcome, count, duration_sum=count * 2.0, durations=count, **where)


def test_a_revision_is_tallied_per_scenario_task_and_robot() -> None:
    tasks = [
        group(S, 6, scenario="delivery", task="Deliver"),
        group(F, 2, scenario="delivery", task="Deliver"),
        group(C, 5, scenario="delivery", task="Deliver"),
        group(ST, 1, scenario="delivery", task="Dock"),
        group(S, 3, scenario="guide", task="Guide"),
    ]
    robots = [group(S, 9, robot_id="r1"), group(F, 2, robot_id="r2"), group(C, 5, robot_id="r3")]
    report = aggregate("rev", tasks, robots, {"E1": 1, "E2": 4})
    assert report.tally.total == 17 and report.tally.succeeded == 9
    delivery = report.scenarios["delivery"]
    # Succeeded of succeeded and failed: neither canceled nor stale is judged.
    assert delivery.tally.success_rate == pytest.approx(6 / 8)
    assert delivery.tasks["Dock"].success_rate is None
    assert delivery.tasks["Deliver"].mean_duration == 2.0  # of the succeeded ones
    assert list(report.codes) == ["E2", "E1"]  # most first
    assert [robot for robot, _ in report.worst_robots()] == ["r2", "r1", "r3"]
    assert report.robots["r3"].success_rate is None  # nothing judged: not 0
    shown = report.as_json()
    assert shown["scenarios"]["delivery"]["tasks"]["Deliver"]["success_rate"] == 0.75
    assert list(shown["robots"]) == ["r2", "r1", "r3"]


def test_a_revision_is_compared_with_the_one_before() -> None:
    now = aggregate("b", [group(S, 1, scenario="s", task="A"), group(F, 3, scenario="s", task="A")])
    before = aggregate(
        "a", [group(S, 4, scenario="s", task="A"), group(S, 2, scenario="old", task="B")]
    )
    changes = {(c.scenario, c.task): c for c in compare(now, before)}
    assert changes[("s", None)].delta == pytest.approx(-0.75)
    assert changes[("s", "A")].before == 1.0
    assert changes[("old", "B")].rate is None and changes[("old", "B")].delta is None
    assert all(c.before is None for c in compare(now, None))


def test_an_empty_tally_has_no_rate() -> None:
    assert Tally().success_rate is None and Tally().mean_duration is None


def outcome(robot: str, state: OutcomeState, seq: int = 0) -> OutcomeRecord:
    return OutcomeRecord.model_validate(fields(robot_id=robot, outcome=state.value, seq=seq))


def test_a_streak_is_told_once_when_it_starts_and_once_when_it_ends() -> None:
    # Neither a canceled goal nor a stale one (it may still end) breaks or lengthens a streak.
    records = [outcome("r1", state) for state in (F, C, F, ST, F, F)]
    streaks, events = advance({}, records, 3)
    assert [(e.robot_id, e.failing, e.streak) for e in events] == [("r1", True, 3)]
    assert streaks["r1"] == Streak(4, True)
    streaks, events = advance(streaks, [outcome("r1", S), outcome("r1", S)], 3)
    assert [(e.failing, e.streak) for e in events] == [(False, 4)]
    assert streaks["r1"] == Streak()


def test_a_success_between_failures_breaks_the_streak() -> None:
    streaks, events = advance({}, [outcome("r1", s) for s in (F, F, S, F, F)], 3)
    assert events == [] and streaks["r1"] == Streak(2, False)
    _, events = advance({"r1": Streak(2, False)}, [outcome("r1", F), outcome("r2", F)], 3)
    assert [e.robot_id for e in events] == ["r1"]


def test_streak_events_are_alerts_receivers_understand() -> None:
    _, events = advance({}, [outcome("r1", F)], 1)
    failing = streak_event(events[0])
    assert failing.kind is Kind.ROBOT_GOALS_FAILING and failing.reason == "NAV2_TIMEOUT"
    assert "NAV2_TIMEOUT" in failing.message and failing.as_json()["robot"] == "r1"
    _, events = advance({"r1": Streak(1, True)}, [outcome("r1", S)], 1)
    recovered = streak_event(events[0])
    assert recovered.kind is Kind.ROBOT_GOALS_RECOVERED and "after 1 failed" in recovered.message


def test_metric_labels_are_bounded() -> None:
    labels = BoundedLabels(2)
    assert [labels.label(v) for v in ("a", "b", "c", "a", "d")] == ["a", "b", OTHER, "a", OTHER]


@pytest.mark.parametrize(
    ("text", "seconds"), [("90", 90), ("90s", 90), ("15m", 900), ("2h", 7200), ("1.5d", 129600)]
)
def test_durations(text: str, seconds: float) -> None:
    assert parse_duration(text) == seconds


@pytest.mark.parametrize(
    "text", ["", "soon", "-1h", "0s", "1y", "1 h 2m", "3651d", "9" * 400 + "w"]
)
def test_durations_that_are_not(text: str) -> None:
    with pytest.raises(ValueError, match="duration"):
        parse_duration(text)
