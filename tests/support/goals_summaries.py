"""Goals summaries as an agent publishes them (contract/goals.py), made directly for the tests of
what `status`, `up` and the browser view show of them; and published retained to a real broker."""

from __future__ import annotations

from robotconf.contract.goals import (
    BrainEvent,
    CurrentGoal,
    GoalsSummary,
    LastOutcome,
    OutcomeState,
    Severity,
    TaskCounts,
)
from robotconf.contract.wire import Topics
from tests.support.agents import Broker, publish

REV1 = "1" * 40
REV2 = "2" * 40
AT = 1_790_000_000.0


def ended(
    goal: str,
    outcome: OutcomeState = OutcomeState.SUCCEEDED,
    code: str | None = None,
    message: str | None = None,
    task: str = "Delivery",
    at: float = AT,
) -> LastOutcome:
    return LastOutcome(
        goal=goal,
        task=task,
        outcome=outcome,
        code=code,
        message=message,
        ended_at=at,
        duration=12.5,
    )


def summary(robot_id: str, **fields: object) -> GoalsSummary:
    """A reporting robot on REV1 with 3 goals succeeded, 1 failed (NAV2_TIMEOUT), one underway at
    40 %, a battery and a pose, and a warning; `fields` replace any of it."""
    made = GoalsSummary(
        robot_id=robot_id,
        revision=REV1,
        digest="sha256:" + "a" * 64,
        scenario="delivery-gazebo",
        run="run-1",
        since=AT - 600,
        reporting=True,
        ready=True,
        completed=3,
        failed=1,
        underway=1,
        tasks={"Delivery": TaskCounts(completed=3, failed=1, underway=1)},
        current=CurrentGoal(
            goal="g-5",
            task="Delivery",
            started_at=AT - 20,
            updated_at=AT - 1,
            fraction=0.4,
            eta=30.0,
            note="past the door",
        ),
        last=ended("g-4", OutcomeState.FAILED, "NAV2_TIMEOUT", "no path to the ball"),
        recent=[
            ended("g-1", at=AT - 400),
            ended("g-2", at=AT - 300),
            ended("g-3", at=AT - 200),
            ended("g-4", OutcomeState.FAILED, "NAV2_TIMEOUT", "no path to the ball", at=AT - 100),
        ],
        vitals={"battery": 0.82, "pose": "x=1.0 y=2.0", "docked": False},
        vitals_at=AT - 5,
        events=[BrainEvent(at=AT - 50, severity=Severity.WARNING, message="battery below 85 %")],
        updated=AT,
    )
    return made.model_copy(update=fields)


def publish_summary(broker: Broker, robot_id: str, found: GoalsSummary | bytes) -> None:
    """Retained, as its agent publishes it (`b""` clears the topic)."""
    payload = found if isinstance(found, bytes) else found.model_dump_json().encode()
    publish(broker, Topics().goals(robot_id), payload)
