"""Drift, pure: a request's needs against a robot's reported interfaces (configurator/drift.py)."""

from __future__ import annotations

from robotconf.configurator.drift import (
    DriftMemo,
    Need,
    drift_of,
    logics_needing,
    needs_of,
    needs_of_rendered,
)
from robotconf.configurator.render import render_fleet
from robotconf.contract.interfaces import Interface, RobotInterfaces
from robotconf.contract.launch import LaunchRequest
from tests.support.interfaces import PATROL_ON_A_PATH_DRIFT
from tests.support.lab import Lab

# What the example lab's tb3-04 (patrol-real: navigate_with_nav2 on the real-world scheme)
# needs: /navigate_to_pose (an action client) and /odom.
FITTING = RobotInterfaces(
    topics=[
        Interface(name="/odom", type="nav_msgs/msg/Odometry"),
        Interface(name="/scan", type="sensor_msgs/msg/LaserScan"),
    ],
    actions=[Interface(name="/navigate_to_pose", type="nav2_msgs/action/NavigateToPose")],
    source="ros2",
)


def patrol(lab: Lab) -> tuple[LaunchRequest, dict[str, tuple[str, ...]]]:
    checked = lab.check()
    assert checked.ok, checked.errors
    fleet = render_fleet(checked.repo)
    return fleet.requests["tb3-04"].model(), fleet.needed_by["turtlebot3-real-patrol"]


def test_interfaces_that_fit_are_no_drift(lab: Lab) -> None:
    request, needed_by = patrol(lab)
    drift = drift_of("tb3-04", needs_of(request, needed_by), FITTING)
    assert drift.interfaces == "reported" and drift.items == () and not drift.drifted
    # Older tools name types without the middle part: the same type.
    short = FITTING.model_copy(
        update={"topics": [Interface(name="/odom", type="nav_msgs/Odometry")]}
    )
    assert drift_of("tb3-04", needs_of(request, needed_by), short).items == ()


def test_a_missing_interface_and_a_wrong_type_are_named_with_the_logic_needing_them(
    lab: Lab,
) -> None:
    request, needed_by = patrol(lab)
    found = RobotInterfaces(
        topics=[Interface(name="/odom", type="nav_msgs/msg/Path")], source="ros2"
    )
    drift = drift_of("tb3-04", needs_of(request, needed_by), found)
    assert [item.as_json() for item in drift.items] == PATROL_ON_A_PATH_DRIFT
    assert [item.text() for item in drift.items] == [
        "tb3-04 lacks /navigate_to_pose (nav2_msgs/action/NavigateToPose), needed by "
        "navigate_with_nav2 via action client mapping navigate_to_pose",
        "tb3-04 has /odom as nav_msgs/msg/Path, not nav_msgs/msg/Odometry, needed by "
        "navigate_with_nav2 via mapping odometry",
    ]
    assert drift.summary() == "1 missing, 1 type"


def test_an_interface_of_another_kind_is_missing() -> None:
    needs = [Need("scan", "/scan", "topic", "sensor_msgs/msg/LaserScan", ("patrol_with_lidar",))]
    found = RobotInterfaces(services=[Interface(name="/scan", type="sensor_msgs/msg/LaserScan")])
    (item,) = drift_of("tb3-04", needs, found).items
    assert item.text() == (
        "tb3-04 lacks /scan (sensor_msgs/msg/LaserScan), needed by patrol_with_lidar via "
        "mapping scan"
    )


def test_nothing_reported_is_unknown_and_never_lacks_anything(lab: Lab) -> None:
    request, needed_by = patrol(lab)
    drift = drift_of("tb3-04", needs_of(request, needed_by), None)
    assert drift.interfaces == "unknown" and drift.items == () and drift.note is None


def test_a_failed_source_or_an_unreadable_payload_is_an_error_not_drift(lab: Lab) -> None:
    request, needed_by = patrol(lab)
    needs = needs_of(request, needed_by)
    failed = RobotInterfaces(error="ros2 timed out after 10 s")
    drift = drift_of("tb3-04", needs, failed)
    assert drift.interfaces == "error" and drift.items == ()
    assert drift.note is not None and "ros2 timed out" in drift.note
    unreadable = drift_of("tb3-04", needs, None, "payload is 600,000 bytes, over the limit")
    assert unreadable.interfaces == "error" and unreadable.items == ()
    assert unreadable.note is not None and "600,000 bytes" in unreadable.note


def test_interfaces_cut_by_the_bounds_do_not_claim_a_missing_one(lab: Lab) -> None:
    request, needed_by = patrol(lab)
    cut = FITTING.model_copy(
        update={
            "actions": [],
            "topics": [Interface(name="/odom", type="nav_msgs/msg/Path")],
            "truncated": 12,
        }
    )
    drift = drift_of("tb3-04", needs_of(request, needed_by), cut)
    # The wrong type is reported as seen; the missing action may only have been cut.
    assert [item.need.mapping for item in drift.items] == ["odometry"]
    assert [need.mapping for need in drift.unsure] == ["navigate_to_pose"]
    assert drift.note is not None and "12 entries left out" in drift.note


def test_names_are_the_robot_s_resolved_ones(lab: Lab) -> None:
    checked = lab.check()
    assert checked.ok
    fleet = render_fleet(checked.repo)
    rendered = fleet.requests["tb3-01"]  # namespace tb3_01
    needs = needs_of_rendered(rendered, fleet.needed_by["turtlebot3-camera"])
    assert needs == needs_of(rendered.model(), fleet.needed_by["turtlebot3-camera"])
    assert "/tb3_01/odom" in [n.name for n in needs]
    assert {n.logics for n in needs} == {("follow_with_poses",)}


def test_a_multi_logic_selection_is_read_defensively(lab: Lab) -> None:
    request, _ = patrol(lab)
    checked = lab.check()
    actions = {name: entry.model for name, entry in checked.repo.actions.items()}
    capability = request.scenario.capability.model_copy(
        update={"logics": {"NavigateToLocation": ["navigate_with_nav2", "navigate_with_move_base"]}}
    )
    needed = logics_needing(capability, actions)
    assert needed["odometry"] == ("navigate_with_move_base", "navigate_with_nav2")
    assert needed["navigate_to_pose"] == ("navigate_with_nav2",)


def test_the_memo_works_out_only_the_robot_whose_interfaces_or_request_changed(lab: Lab) -> None:
    request, needed_by = patrol(lab)
    needs = needs_of(request, needed_by)
    memo = DriftMemo()
    first = memo.get("tb3-04", request.digest, needs, FITTING)
    assert memo.get("tb3-04", request.digest, needs, FITTING) is first
    assert memo.computed == 1
    lacking = FITTING.model_copy(update={"actions": []})
    assert memo.get("tb3-04", request.digest, needs, lacking).drifted
    assert memo.computed == 2
    assert memo.get("tb3-04", "sha256:other", needs, lacking).drifted
    assert memo.computed == 3
