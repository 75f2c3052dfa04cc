"""`robotconf status` shows each robot's labels from fleet.yaml: in JSON always, in the table
when some robot has any; as text, never as markup."""

from __future__ import annotations

from robotconf.configurator.render import render_fleet
from robotconf.contract.wire import AgentState, AgentStatus
from robotconf.readmodel.observed import Retained, RobotSeen
from robotconf.readmodel.verdicts import DesiredRobot, FleetStatus, build_rows, desired_from_fleet
from robotconf.workstation.cli.fleet_view import COLUMNS, fleet_status_text
from tests.support.lab import Lab

D1 = "sha256:" + "1" * 64


def running(robot_id: str) -> RobotSeen:
    status = AgentStatus(robot_id=robot_id, state=AgentState.RUNNING, digest=D1)
    return RobotSeen(launch_digest=D1, status=status)


def test_the_rendered_fleet_carries_every_robot_s_labels(lab: Lab) -> None:
    checked = lab.check()
    desired = desired_from_fleet(render_fleet(checked.repo))
    assert dict(desired["tb3-01"].labels) == {"ring": "canary", "site": "sim"}
    assert dict(desired["tb3-04"].labels) == {"site": "robotics-lab"}
    assert dict(desired["tb3-02"].labels) == {}


def test_rows_carry_the_labels_and_json_always_has_them(lab: Lab) -> None:
    desired = desired_from_fleet(render_fleet(lab.check().repo))
    retained = Retained(robots={"stray": running("stray")})
    rows = {r.robot_id: r for r in build_rows(desired, retained)}
    assert rows["tb3-03"].as_json()["labels"] == {"ring": "canary", "site": "sim"}
    assert rows["tb3-02"].as_json()["labels"] == {}
    assert rows["stray"].as_json()["labels"] == {}  # not in fleet.yaml: no labels known


def test_the_table_has_a_labels_column_when_some_robot_has_labels() -> None:
    desired = {
        "r1": DesiredRobot("r1", "s", D1, labels={"site": "sim", "ring": "canary"}),
        "r2": DesiredRobot("r2", "s", D1),
    }
    retained = Retained(robots={"r1": running("r1"), "r2": running("r2")})
    text = fleet_status_text(FleetStatus(build_rows(desired, retained), None, "t"))
    header = next(line for line in text.splitlines() if line.startswith("ROBOT"))
    assert header.split() == ["ROBOT", "VERDICT", "ONLINE", "SCENARIO", "LABELS", *COLUMNS[4:]]
    r1 = next(line for line in text.splitlines() if line.startswith("r1 "))
    r2 = next(line for line in text.splitlines() if line.startswith("r2 "))
    assert r1.split()[3:5] == ["s", "ring=canary,site=sim"]  # in key order
    assert r2.split()[3:5] == ["s", "-"]


def test_a_fleet_without_labels_keeps_its_table() -> None:
    desired = {"r1": DesiredRobot("r1", "s", D1)}
    text = fleet_status_text(
        FleetStatus(build_rows(desired, Retained(robots={"r1": running("r1")})), None, "t")
    )
    header = next(line for line in text.splitlines() if line.startswith("ROBOT"))
    assert header.split() == list(COLUMNS)


def test_labels_are_text_never_markup_or_control_codes() -> None:
    labels = {"[bold]ring": "[link=http://x]canary[/link]", "site": "a\x1b[2J\u202eb"}
    desired = {"r1": DesiredRobot("r1", "s", D1, labels=labels)}
    rows = build_rows(desired, Retained(robots={"r1": running("r1")}))
    text = fleet_status_text(FleetStatus(rows, None, "t"))
    row = next(line for line in text.splitlines() if line.startswith("r1 "))
    assert "[bold]ring=[link=http://x]canary[/link],site=a\\x1b[2J\\u202eb" in row
    assert "\x1b" not in text and "\u202e" not in text
