"""`robotconf status` judges drift: robots' retained interfaces against their desired requests."""

from __future__ import annotations

import json
import subprocess
from typing import Any

from robotconf.contract.interfaces import MAX_INTERFACES_BYTES, RobotInterfaces
from tests.support.fleet import GitLab, robotconf_argv
from tests.support.interfaces import PATROL_ON_A_PATH_DRIFT, publish_interfaces, report
from tests.support.mosquitto import Mosquitto, free_port

# tb3-04 runs patrol-real: navigate_with_nav2 needs /navigate_to_pose and /odom.
PATROL_ACTION = ("/navigate_to_pose", "nav2_msgs/action/NavigateToPose")


def status(lab: GitLab, url: str, *extra: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        robotconf_argv("status", "--repo", str(lab.root), "--broker", url, *extra),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "Traceback" not in done.stdout + done.stderr, done.stderr
    return done


def rows(lab: GitLab, url: str) -> dict[str, dict[str, Any]]:
    found = json.loads(status(lab, url, "--json").stdout)
    return {r["robot_id"]: r for r in found["robots"]}


def test_status_shows_each_robot_s_drift_and_whether_it_reports(
    lab: GitLab, mosquitto: Mosquitto
) -> None:
    url = mosquitto.url
    # tb3-04 has no Nav2 action and publishes /odom with another type.
    publish_interfaces(url, "tb3-04", report(("/odom", "nav_msgs/msg/Path")))
    # tb3-01 (namespace tb3_01) has all it needs, under its namespace.
    publish_interfaces(
        url,
        "tb3-01",
        report(
            ("/tb3_01/odom", "nav_msgs/msg/Odometry"),
            ("/tb3_01/cmd_vel", "geometry_msgs/msg/Twist"),
            ("/tb3_01/camera/image_raw", "sensor_msgs/msg/Image"),
        ),
    )
    publish_interfaces(url, "tb3-02", b"{not json")
    publish_interfaces(url, "tb3-03", RobotInterfaces(source="ros2", error="ros2 timed out"))
    publish_interfaces(url, "tb3-05", b'{"topics": []}' + b" " * MAX_INTERFACES_BYTES)

    found = rows(lab, url)
    assert found["tb3-04"]["interfaces"] == "reported"
    assert found["tb3-04"]["drift"] == PATROL_ON_A_PATH_DRIFT
    assert (found["tb3-01"]["interfaces"], found["tb3-01"]["drift"]) == ("reported", [])
    # Unreadable (garbage, or over the bound) and a failed source: `error`, never drift.
    for robot_id in ("tb3-02", "tb3-03", "tb3-05"):
        assert (found[robot_id]["interfaces"], found[robot_id]["drift"]) == ("error", [])
    assert "ros2 timed out" in found["tb3-03"]["drift_note"]
    assert f"{MAX_INTERFACES_BYTES:,}" in found["tb3-05"]["drift_note"]

    text = status(lab, url).stdout
    assert "DRIFT" in text
    assert (
        "drift: tb3-04 lacks /navigate_to_pose (nav2_msgs/action/NavigateToPose), needed by "
        "navigate_with_nav2 via action client mapping navigate_to_pose"
    ) in text
    # Worst first: every robot is Offline here; the drifted one leads its verdict's rows.
    assert text.index("tb3-04") < min(text.index(f"tb3-0{i}") for i in (1, 2, 3, 5))

    # The robot's interfaces change: the drift follows.
    publish_interfaces(
        url, "tb3-04", report(("/odom", "nav_msgs/msg/Odometry"), actions=(PATROL_ACTION,))
    )
    publish_interfaces(url, "tb3-02", b"")  # reporting nothing: unknown
    found = rows(lab, url)
    assert (found["tb3-04"]["interfaces"], found["tb3-04"]["drift"]) == ("reported", [])
    assert (found["tb3-02"]["interfaces"], found["tb3-02"]["drift"]) == ("unknown", [])


def test_plan_shows_the_drift_of_the_robots_a_change_would_affect(
    lab: GitLab, mosquitto: Mosquitto
) -> None:
    url = mosquitto.url
    publish_interfaces(url, "tb3-04", report(("/odom", "nav_msgs/msg/Odometry")))  # no Nav2
    publish_interfaces(url, "tb3-05", report(("/odom", "nav_msgs/msg/Odometry")))  # unchanged
    lab.replace("configs/fleet.yaml", "name: Lab patrol,", "name: Lab patrol 2,")
    lab.replace("configs/fleet.yaml", "name: Guide bot,", "name: Guide bot 2,")

    offline = lab.run("plan", "--base", "HEAD")
    assert offline.returncode == 1 and "drift" not in offline.stdout  # nothing said without

    text = lab.run("plan", "--base", "HEAD", "--broker", url)
    assert text.returncode == 1, text.stderr
    assert (
        "drift: tb3-04 lacks /navigate_to_pose (nav2_msgs/action/NavigateToPose), needed by "
        "navigate_with_nav2 via action client mapping navigate_to_pose"
    ) in text.stdout
    assert "drift not judged (no interfaces reported): tb3-02" in text.stdout
    assert "tb3-05" not in text.stdout  # not affected: not judged

    found = json.loads(
        lab.run("plan", "--base", "HEAD", "--broker", url, "--format", "json").stdout
    )
    changes = {c["robot_id"]: c for c in found["changes"]}
    assert changes["tb3-04"]["interfaces"] == "reported"
    assert [d["mapping"] for d in changes["tb3-04"]["drift"]] == ["navigate_to_pose"]
    assert (changes["tb3-02"]["interfaces"], changes["tb3-02"]["drift"]) == ("unknown", [])

    markdown = lab.run("plan", "--base", "HEAD", "--broker", url, "--format", "markdown")
    assert "- drift: tb3-04 lacks" in markdown.stdout.replace("\\", "")


def test_plan_without_an_answer_from_the_broker_stands_without_drift(lab: GitLab) -> None:
    lab.replace("configs/fleet.yaml", "name: Lab patrol,", "name: Lab patrol 2,")
    url = f"mqtt://127.0.0.1:{free_port()}"
    done = lab.run("plan", "--base", "HEAD", "--broker", url, "--wait", "1")
    assert done.returncode == 1 and "tb3-04" in done.stdout and "drift" not in done.stdout
    assert "Traceback" not in done.stderr
    assert f"no answer from {url} within 1 s: drift is not judged" in done.stderr
