"""What robots achieve on the UI's pages, pure: a robot's goals box (a progress bar, outcomes with
codes, vitals, events), the fleet's Goals cells and its success rates per scenario and revision,
every robot-supplied string as text, and no inline style (the CSP forbids it)."""

from __future__ import annotations

import re

from robotconf.contract.goals import BrainEvent, CurrentGoal, OutcomeState, Severity
from robotconf.readmodel.robot_goals import RobotGoals, bounded
from robotconf.workstation.ui.auth import ANONYMOUS
from robotconf.workstation.ui.changes import Shown, change, first
from robotconf.workstation.ui.goals_html import duration, goals_box, rates_box
from robotconf.workstation.ui.model import FleetQuery
from robotconf.workstation.ui.pages import fleet_page
from robotconf.workstation.ui.robot_page import robot_page
from tests.support.goals_summaries import AT, REV1, REV2, ended, summary
from tests.unit.ui.fleets import fleet, row, snapshot
from tests.unit.ui.test_pages import assert_no_inline_code, tags

HOSTILE = '<script>alert(1)</script>"\x1b[31m'


def goals(robot_id: str, **fields: object) -> RobotGoals:
    return RobotGoals.of(bounded(summary(robot_id, **fields)))


def test_the_goals_box_shows_the_goal_underway_as_a_progress_bar() -> None:
    snap = snapshot(fleet([row("r1", goals=goals("r1"))]))
    box = goals_box(snap, "r1")
    bars = [a for tag, a in tags(box) if tag == "progress"]
    assert bars == [{"max": "1", "value": "0.4000", "aria-label": "progress of Delivery"}]
    assert "40%" in box and "about 30 s left" in box and "past the door" in box
    assert 'data-goal-counts="3/1"' in box and 'data-current-goal="g-5"' in box
    assert_no_inline_code(box)
    # Without a fraction: an indeterminate bar (no value), and no percentage made up.
    unsure = CurrentGoal(goal="g-6", task="Patrol", started_at=AT, updated_at=AT)
    box = goals_box(snapshot(fleet([row("r1", goals=goals("r1", current=unsure))])), "r1")
    assert [a for tag, a in tags(box) if tag == "progress"] == [
        {"max": "1", "aria-label": "progress of Patrol"}
    ]


def test_recent_outcomes_newest_first_with_codes_and_vitals_and_events() -> None:
    box = goals_box(snapshot(fleet([row("r1", goals=goals("r1"))])), "r1")
    outcomes = re.findall(r'<tr data-outcome="(\w+)">.*?<code>([^<]*)</code>.*?</tr>', box)
    assert [o for o, _ in outcomes] == ["failed", "succeeded", "succeeded", "succeeded"]
    assert "NAV2_TIMEOUT" in box and "no path to the ball" in box
    assert '<dd data-vital="battery">0.82</dd>' in box and '<dd data-vital="docked">no</dd>' in box
    assert '<li data-severity="warning">' in box and "battery below 85 %" in box


def test_a_stale_goal_is_said_so() -> None:
    stuck = CurrentGoal(goal="g-6", task="Patrol", started_at=AT, updated_at=AT, stale=True)
    box = goals_box(snapshot(fleet([row("r1", goals=goals("r1", current=stuck, stale=1))])), "r1")
    assert "data-stale" in box and "stale: no progress" in box


def test_every_robot_supplied_string_in_the_goals_box_is_text() -> None:
    hostile = goals(
        "r1",
        current=CurrentGoal(
            goal="g", task="T", started_at=AT, updated_at=AT, fraction=0.5, note=HOSTILE
        ),
        recent=[ended("g", OutcomeState.FAILED, "E1", HOSTILE, task="T")],
        vitals={"pose": HOSTILE},
        events=[BrainEvent(at=AT, severity=Severity.ERROR, message=HOSTILE)],
        scenario=HOSTILE,
        run=HOSTILE,
    )
    page = robot_page(snapshot(fleet([row("r1", goals=hostile)])), "r1", ANONYMOUS, None, None)
    assert "<script>alert" not in page and "\x1b" not in page
    assert page.count("&lt;script&gt;alert(1)&lt;/script&gt;&quot;\\x1b[31m") >= 5
    assert_no_inline_code(page)


def test_a_robot_that_does_not_report_has_goals_unknown() -> None:
    quiet = row("r1")  # no summary at all
    box = goals_box(snapshot(fleet([quiet])), "r1")
    assert 'data-goals="unknown"' in box and "publishes no goals summary" in box
    silent = row("r2", goals=goals("r2", reporting=False))
    box = goals_box(snapshot(fleet([silent])), "r2")
    assert 'data-goals="unknown"' in box and "progress" not in box


def test_the_fleet_table_has_a_goals_cell_and_the_page_the_success_rates() -> None:
    rows = [
        row("r1", goals=goals("r1", completed=9, failed=1)),
        row("r2", goals=goals("r2", completed=1, failed=1, revision=REV2, since=AT)),
        row("r3"),
    ]
    page = fleet_page(snapshot(fleet(rows)), FleetQuery(), ANONYMOUS)
    cells = re.findall(r'<td class="goals[^"]*" data-goals="(\w+)">([^<]*)</td>', page)
    assert sorted(cells) == [("reporting", "1/1"), ("reporting", "9/1"), ("unknown", "unknown")]
    rates = dict(re.findall(r'<tr data-scenario="delivery-gazebo" data-revision="(\w+)" '
                            r'data-rate="([^"]+)">', page))  # fmt: skip
    assert rates == {REV1: "90%", REV2: "50%"}
    assert f'href="/revisions/{REV2}"' in page
    assert "1 robots do not report their goals" in page
    assert_no_inline_code(page)
    # The query narrows the rates as it narrows the rows.
    narrowed = rates_box(snapshot(fleet(rows)), FleetQuery(search="r2"))
    assert REV2 in narrowed and REV1 not in narrowed


def test_a_fleet_without_goals_hides_the_rates_box() -> None:
    page = fleet_page(snapshot(fleet([row("r1")])), FleetQuery(), ANONYMOUS)
    assert '<section data-box="rates" hidden></section>' in page


def test_an_open_robot_page_gets_its_goals_box_when_progress_moves() -> None:
    before = snapshot(fleet([row("r1", goals=goals("r1"))]), version=1)
    shown = Shown(FleetQuery(), "r1")
    assert first(before, shown, 1) is None  # the page was made from this very state
    moved = CurrentGoal(goal="g-5", task="Delivery", started_at=AT, updated_at=AT, fraction=0.7)
    after = snapshot(fleet([row("r1", goals=goals("r1", current=moved))]), version=2)
    event = change(after, shown, {"r1"})
    assert event is not None
    assert b'"goals"' in event and b'value=\\"0.7000\\"' in event and b'"robot"' not in event


def test_durations_read_as_people_say_them() -> None:
    assert [duration(s) for s in (None, -1, 4.25, 42, 185, 7500)] == [
        "-",
        "-",
        "4.2 s",
        "42 s",
        "3 min 5 s",
        "2 h 5 min",
    ]
