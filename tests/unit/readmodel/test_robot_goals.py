"""A robot's retained goals summary as `status` reads it, pure: the goals column, `--json`'s
`goals` and `vitals`, what is unknown, what is refused, what is bounded, and the success rate per
scenario and revision."""

from __future__ import annotations

import json

from robotconf.contract.goals import (
    MAX_EVENTS_KEPT,
    MAX_RECENT_KEPT,
    MAX_TEXT,
    BrainEvent,
    OutcomeState,
    Severity,
    TaskCounts,
)
from robotconf.contract.wire import Topics
from robotconf.readmodel.observed import parse_retained
from robotconf.readmodel.robot_goals import NO_GOALS, RobotGoals, bounded, goal_rates
from robotconf.readmodel.verdicts import DesiredRobot, FleetStatus, build_rows
from robotconf.workstation.cli.fleet_view import GOALS, GOALS_LEGEND, columns, fleet_status_text
from tests.support.goals_summaries import AT, REV1, REV2, ended, summary

T = Topics()
FIXED = {"completed", "failed", "canceled", "underway", "stale", "current", "last"}


def read(payloads: dict[str, bytes]) -> FleetStatus:
    retained = parse_retained({T.goals(r): p for r, p in payloads.items()}, T)
    desired = {r: DesiredRobot(r, "delivery-gazebo", "sha256:" + "a" * 64) for r in payloads}
    return FleetStatus(build_rows(desired, retained), None, "a repo", ignored=retained.ignored)


def test_a_reporting_robot_s_goals_are_its_counts_current_goal_last_outcome_and_vitals() -> None:
    fleet = read({"r1": summary("r1").model_dump_json().encode()})
    [row] = fleet.rows
    assert row.goals.state == "reporting" and row.goals.cell() == "3/1"
    found = row.as_json()
    goals = found["goals"]
    assert set(goals) >= FIXED
    assert (goals["completed"], goals["failed"], goals["canceled"]) == (3, 1, 0)
    assert (goals["underway"], goals["stale"]) == (1, 0)
    assert goals["current"]["task"] == "Delivery" and goals["current"]["fraction"] == 0.4
    assert goals["last"]["outcome"] == "failed" and goals["last"]["code"] == "NAV2_TIMEOUT"
    assert goals["revision"] == REV1 and goals["tasks"]["Delivery"]["completed"] == 3
    assert found["vitals"] == {"battery": 0.82, "docked": False, "pose": "x=1.0 y=2.0"}
    assert found["goals_state"] == "reporting" and found["goals_note"] is None
    json.dumps(found)  # it is JSON as it is


def test_goals_are_unknown_without_a_summary_or_with_a_brain_that_does_not_report() -> None:
    fleet = read(
        {"r1": summary("r1", reporting=False, completed=0, failed=0).model_dump_json().encode()}
    )
    [quiet] = fleet.rows
    assert quiet.goals.cell() == "unknown" and quiet.as_json()["goals"] is None
    assert quiet.as_json()["vitals"] == {}
    assert "does not report goals" in (quiet.goals.note or "")
    # A robot no agent publishes a summary for: unknown, never failed.
    assert NO_GOALS.cell() == "unknown" and NO_GOALS.as_json() is None and not NO_GOALS.failing
    assert not NO_GOALS.published


def test_an_unreadable_summary_or_one_of_another_robot_is_an_error_and_counted() -> None:
    other = summary("r9").model_dump_json().encode()
    fleet = read({"r1": b"{not json", "r2": other, "r3": b'{"robot_id": "r3", "completed": "x"}'})
    for row in fleet.rows:
        assert row.goals.state == "error" and row.goals.cell() == "error", row.robot_id
        assert row.as_json()["goals"] is None
    assert "r9" in (fleet.rows[1].goals.note or "")
    assert fleet.ignored == {"goals": 3}


def test_a_summary_is_bounded_once_read() -> None:
    many = [ended(f"g-{n}", at=AT + n) for n in range(50)]
    events = [BrainEvent(at=AT + n, severity=Severity.INFO, message=f"e{n}") for n in range(40)]
    long = "x" * 5000
    wild = summary(
        "r1",
        recent=many,
        events=events,
        completed=-5,
        tasks={f"task-{n:03}": TaskCounts(completed=1, failed=-2) for n in range(200)},
        last=ended("g-49", OutcomeState.FAILED, "E", long),
        vitals={f"v{n:02}": long for n in range(40)},
    )
    kept = bounded(wild)
    assert [o.goal for o in kept.recent] == [f"g-{n}" for n in range(50 - MAX_RECENT_KEPT, 50)]
    assert [e.message for e in kept.events][-1] == "e39"
    assert len(kept.events) == MAX_EVENTS_KEPT
    assert kept.completed == 0 and all(c.failed == 0 for c in kept.tasks.values())
    assert len(kept.tasks) == 64 and len(kept.vitals) == 16
    assert kept.last is not None and len(kept.last.message or "") == MAX_TEXT
    assert all(isinstance(v, str) and len(v) == MAX_TEXT for v in kept.vitals.values())
    # A well-behaved agent's summary is kept as it is.
    assert bounded(summary("r1")) == summary("r1")


def test_the_goals_cell_says_stale_and_a_failing_robot_is_marked() -> None:
    stale = RobotGoals.of(bounded(summary("r1", stale=2)))
    assert stale.cell() == "3/1 2 stale" and stale.failing  # its last goal failed
    fine = RobotGoals.of(bounded(summary("r1", last=ended("g-9"))))
    assert not fine.failing


def test_the_status_table_gains_a_goals_column_only_when_some_agent_publishes_goals() -> None:
    with_goals = read({"r1": summary("r1").model_dump_json().encode(), "r2": b""})
    assert GOALS in columns(with_goals.rows)
    text = fleet_status_text(with_goals)
    header = next(line for line in text.splitlines() if line.startswith("ROBOT"))
    assert "GOALS" in header and GOALS_LEGEND in text
    line = next(line for line in text.splitlines() if line.startswith("r1 "))
    assert " 3/1 " in f"{line} "
    without = read({"r1": b""})
    assert GOALS not in columns(without.rows)
    assert "GOALS" not in fleet_status_text(without)


def test_success_rates_per_scenario_and_revision() -> None:
    robots = [
        ("delivery-gazebo", RobotGoals.of(summary("a", completed=8, failed=2, since=AT))),
        ("delivery-gazebo", RobotGoals.of(summary("b", completed=2, failed=0, since=AT))),
        ("delivery-gazebo", RobotGoals.of(summary("c", revision=REV2, since=AT + 60))),
        ("guide", RobotGoals.of(summary("d", scenario=None, completed=0, failed=0, canceled=4))),
        ("guide", NO_GOALS),
    ]
    rates, silent = goal_rates(robots)
    assert silent == 1
    keyed = {(r.scenario, r.revision): r for r in rates}
    rev1 = keyed[("delivery-gazebo", REV1)]
    assert (rev1.robots, rev1.completed, rev1.failed) == (2, 10, 2)
    assert rev1.rate_text() == "83%"
    # The newest revision of a scenario first; a summary without a scenario counts as desired.
    assert [(r.scenario, r.revision) for r in rates][:2] == [
        ("delivery-gazebo", REV2),
        ("delivery-gazebo", REV1),
    ]
    guide = keyed[("guide", REV1)]
    assert guide.rate is None and guide.rate_text() == "-" and guide.canceled == 4
