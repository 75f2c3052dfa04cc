"""`robotconf autofill --robot`: logics selected by what a live robot reports (its retained
interfaces, or a file of them), alone or together with a robot template."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from robotconf.contract.wire import Topics
from robotconf.contract.yamlio import parse_document
from tests.support.agents import publish
from tests.support.lab import ROOT, Lab
from tests.support.mosquitto import Mosquitto

ARGS = ("--platform", "ROS2", "--scheme", "real-world", "--robot", "tb3-04")
WRITTEN = "configs/capabilities/{}.yaml"


def report(**change: Any) -> dict[str, Any]:
    """The example lab's physical robot as it reports itself (examples/interfaces)."""
    found: dict[str, Any] = json.loads((ROOT / "examples/interfaces/tb3-04.json").read_text())
    found.update(change)
    return found


def with_topic(name: str, type_name: str) -> dict[str, Any]:
    found = report()
    found["topics"] = [*found["topics"], {"name": name, "type": type_name}]
    return found


def autofill(lab: Lab, found: dict[str, Any], *args: str) -> Any:
    path = lab.root / "tb3-04.json"
    path.write_text(json.dumps(found))
    return lab.run("autofill", *ARGS, "--from", str(path), *args)


def actions(lab: Lab, name: str) -> Any:
    rel = WRITTEN.format(name)
    return parse_document(rel, lab.path(rel).read_bytes()).data["actions"]


def test_only_logics_the_robot_serves_are_selected(lab: Lab) -> None:
    done = autofill(lab, report(), "--all", "--name", "live")
    assert done.returncode == 0, done.stderr
    # The robot has a camera but no /bluetooth/rssi: following by poses only.
    assert actions(lab, "live")["Follow"] == "follow_with_poses"
    assert lab.check().ok
    # Without /odom, no logic of NavigateToLocation fits: it is left out, and why is said.
    found = report()
    found["topics"] = [t for t in found["topics"] if t["name"] != "/odom"]
    done = autofill(lab, found, "--all", "--name", "no-odom")
    assert done.returncode == 0, done.stderr
    assert "NavigateToLocation" not in actions(lab, "no-odom")
    assert "robot lacks topic /odom (nav_msgs/msg/Odometry), mapping odometry" in done.stdout


def test_every_fitting_logic_once_the_robot_reports_its_mapping(lab: Lab) -> None:
    done = autofill(lab, with_topic("/bluetooth/rssi", "std_msgs/msg/Float32"), "--all")
    assert done.returncode == 0, done.stderr
    assert actions(lab, "tb3-04-real-world")["Follow"] == [
        "follow_with_poses",
        "follow_with_bluetooth",
    ]


def test_a_type_that_differs_does_not_fit(lab: Lab) -> None:
    done = autofill(lab, with_topic("/bluetooth/rssi", "std_msgs/msg/String"), "--all")
    assert done.returncode == 0, done.stderr
    assert actions(lab, "tb3-04-real-world")["Follow"] == "follow_with_poses"
    found = report()
    for topic in found["topics"]:
        if topic["name"] == "/odom":
            topic["type"] = "geometry_msgs/msg/PoseStamped"
    done = autofill(lab, found, "--name", "odd-odom")
    assert "NavigateToLocation" not in actions(lab, "odd-odom")
    assert "/odom is geometry_msgs/msg/PoseStamped, not nav_msgs/msg/Odometry" in done.stdout


def test_a_template_and_the_robot_must_both_serve_a_logic(lab: Lab) -> None:
    # The burger template has no camera, although the robot reports one.
    done = autofill(lab, report(), "--template", "turtlebot3-burger", "--name", "both")
    assert done.returncode == 0, done.stderr
    assert "Follow" not in actions(lab, "both")
    assert "robot template lacks camera" in done.stdout


def test_a_failed_or_missing_report_selects_nothing(lab: Lab) -> None:
    failed = autofill(lab, report(error="ros2 timed out"))
    assert failed.returncode == 1 and "source failed (ros2 timed out)" in failed.stderr
    neither = lab.run("autofill", "--platform", "ROS2", "--scheme", "real-world")
    assert neither.returncode == 2 and "give --template, --robot, or both" in neither.stderr
    assert not lab.path(WRITTEN.format("tb3-04-real-world")).exists()


def test_autofill_reads_the_robot_s_retained_interfaces(lab: Lab, mosquitto: Mosquitto) -> None:
    topic = Topics("robotconf").interfaces("tb3-04")
    publish(mosquitto.url, topic, json.dumps(report()).encode())
    done = lab.run("autofill", *ARGS, "--broker", mosquitto.url, "--name", "from-broker")
    assert done.returncode == 0, done.stderr
    assert actions(lab, "from-broker")["NavigateToLocation"] == "navigate_with_nav2"
    unknown = lab.run(
        "autofill", *ARGS[:4], "--robot", "tb3-09", "--broker", mosquitto.url, "--wait", "2"
    )
    assert unknown.returncode == 1 and "tb3-09 has reported no interfaces" in unknown.stderr


def test_the_namespace_comes_from_the_fleet(lab: Lab, tmp_path: Path) -> None:
    # tb3-01 runs in namespace tb3_01 (configs/fleet.yaml), and the gazebo scheme's names
    # are relative: the robot's /tb3_01/odom is the scheme's odom.
    found = report()
    found["topics"] = [
        {"name": "/tb3_01/odom", "type": "nav_msgs/msg/Odometry"},
        {"name": "/tb3_01/cmd_vel", "type": "geometry_msgs/msg/Twist"},
        {"name": "/odom", "type": "nav_msgs/msg/Odometry"},
    ]
    found["actions"] = [
        {"name": "/tb3_01/navigate_to_pose", "type": "nav2_msgs/action/NavigateToPose"}
    ]
    path = tmp_path / "ns.json"
    path.write_text(json.dumps(found))
    args = ("autofill", "--platform", "ROS2", "--scheme", "gazebo", "--from", str(path))
    done = lab.run(*args, "--robot", "tb3-01", "--name", "ns")
    assert done.returncode == 0, done.stderr
    assert actions(lab, "ns")["NavigateToLocation"] == "navigate_with_nav2"
    # In another namespace the same report serves nothing of it.
    other = lab.run(*args, "--robot", "tb3-01", "--namespace", "tb3_09", "--name", "ns9")
    assert "robot lacks topic /tb3_09/odom" in other.stdout
    assert "NavigateToLocation" not in actions(lab, "ns9")


def test_a_name_that_cannot_be_a_file_is_refused_before_anything_is_read_or_written(
    lab: Lab, tmp_path: Path
) -> None:
    """The robot id (the file's default name), --name, --template and --scheme are checked by
    the one rule of file names (contract.models.file_name): nothing lands outside the folder,
    nor in a file named with a line break or a terminal escape."""
    path = lab.root / "tb3-04.json"
    path.write_text(json.dumps(report()))
    outside = tmp_path / "outside"
    before = sorted(p.name for p in lab.path("configs/capabilities").iterdir())
    cases = [
        ("--robot", "../../x"),
        ("--robot", str(outside)),
        ("--robot", "tb3\nplatform: evil"),
        ("--robot", "\x1b]0;owned\x07tb3"),
        ("--name", "../escape"),
        ("--template", "../../t"),
        ("--scheme", ".hidden"),
    ]
    for option, bad in cases:
        args = ["--platform", "ROS2", "--scheme", "real-world", "--from", str(path)]
        args += ["--robot", "tb3-04"] if option != "--robot" else []
        done = lab.run("autofill", *args, option, bad)
        assert done.returncode == 2, (bad, done.stdout, done.stderr)
        [line] = done.stderr.splitlines()
        assert line.startswith(f"robotconf: {option} '") and "cannot name a file" in line
        assert "\x1b" not in line and "\x07" not in line
    assert sorted(p.name for p in lab.path("configs/capabilities").iterdir()) == before
    assert not outside.exists() and not (lab.root.parent / "x.yaml").exists()
    # Each part may be a file name and the made name (ROBOT-SCHEME) still too long for one.
    long_robot = ("--robot", "t" * 60, "--platform", "ROS2", "--scheme", "real-world")
    done = lab.run("autofill", *long_robot, "--from", str(path))
    assert done.returncode == 2 and "give --name" in done.stderr
