"""`robotconf draft`: a robot template and mapping scheme written from a robot's interfaces, read
from a file or from the robot's retained message on a real Mosquitto, validated first."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from robotconf.configurator.workspace import check, check_with
from robotconf.contract.wire import Topics
from robotconf.contract.yamlio import parse_document
from robotconf.workstation.cli.draft import write_validated
from tests.support.agents import publish
from tests.support.lab import ROOT, Lab
from tests.support.mosquitto import Mosquitto, free_port

TEMPLATE = "models/platforms/ROS2/robot-templates/{}.yaml"
SCHEME = "models/platforms/ROS2/mapping-schemes/{}.yaml"


def message(
    topics: list[tuple[str, str]],
    services: Sequence[tuple[str, str]] = (),
    **extra: Any,
) -> bytes:
    def entries(pairs: Sequence[tuple[str, str]]) -> list[dict[str, str]]:
        return [{"name": n, "type": t} for n, t in pairs]

    body = {"topics": entries(topics), "services": entries(services), "actions": [], **extra}
    return json.dumps({"source": "ros2", "at": 1764100000.0, "truncated": 0, **body}).encode()


# tb3-01 runs in namespace tb3_01 (configs/fleet.yaml).
TB3_01 = message(
    [
        ("/tb3_01/scan", "sensor_msgs/msg/LaserScan"),
        ("/tb3_01/cmd_vel", "geometry_msgs/msg/Twist"),
        ("/tb3_01/odom", "nav_msgs/msg/Odometry"),
        ("/tb3_01/front/scan", "sensor_msgs/msg/LaserScan"),
        ("/rosout", "rcl_interfaces/msg/Log"),
    ],
    [("/tb3_01/turtlebot3_node/get_parameters", "rcl_interfaces/srv/GetParameters")],
)


def data(lab: Lab, rel: str) -> Any:
    return parse_document(rel, lab.path(rel).read_bytes()).data


def from_file(lab: Lab, payload: bytes, *args: str) -> Any:
    path = lab.root / "report.json"
    path.write_bytes(payload)
    return lab.run("draft", *args, "--platform", "ROS2", "--from", str(path))


def test_draft_from_a_file_writes_files_that_validate(lab: Lab) -> None:
    done = from_file(lab, TB3_01, "tb3-01", "--template", "tb3-sim")
    assert done.returncode == 0, done.stderr
    template, scheme = data(lab, TEMPLATE.format("tb3-sim")), data(lab, SCHEME.format("tb3-sim"))
    assert template["mappings"] == ["cmd_vel", "front_scan", "odometry", "scan"]
    assert scheme["mappings"]["scan"] == {
        "kind": "topic",
        "name": "scan",
        "type": "sensor_msgs/msg/LaserScan",
    }
    assert scheme["mappings"]["front_scan"]["name"] == "front/scan"
    assert lab.read(SCHEME.format("tb3-sim")).startswith(
        "# yaml-language-server: $schema=../../../../schemas/mapping-scheme.schema.json\n"
    )
    assert lab.read(TEMPLATE.format("tb3-sim")).startswith(
        "# yaml-language-server: $schema=../../../../schemas/robot-template.schema.json\n"
    )
    assert "namespace tb3_01 (configs/fleet.yaml)" in done.stdout
    assert "front_scan" in done.stdout and "did you mean 'scan'" in done.stdout
    assert "left out 2 interface(s) of the ROS graph itself" in done.stdout
    checked = lab.check()
    assert checked.ok, checked.errors
    assert "tb3-sim" in checked.repo.platforms["ROS2"].templates


def test_the_scheme_is_named_after_the_template_unless_given(lab: Lab) -> None:
    done = from_file(lab, TB3_01, "tb3-01", "--template", "t1", "--scheme", "s1")
    assert done.returncode == 0, done.stderr
    assert lab.path(SCHEME.format("s1")).is_file() and not lab.path(SCHEME.format("t1")).exists()


def test_nothing_is_overwritten_without_force(lab: Lab) -> None:
    before = lab.read(SCHEME.format("gazebo"))
    done = from_file(lab, TB3_01, "tb3-01", "--template", "fresh", "--scheme", "gazebo")
    assert done.returncode == 1
    assert "mapping-schemes/gazebo.yaml exists" in done.stderr and "--force" in done.stderr
    assert lab.read(SCHEME.format("gazebo")) == before
    assert not lab.path(TEMPLATE.format("fresh")).exists()  # neither file is written

    assert from_file(lab, TB3_01, "tb3-01", "--template", "mine").returncode == 0
    other = message([("/tb3_01/imu", "sensor_msgs/msg/Imu")])
    again = from_file(lab, other, "tb3-01", "--template", "mine")
    assert again.returncode == 1 and "robot-templates/mine.yaml exists" in again.stderr
    forced = from_file(lab, other, "tb3-01", "--template", "mine", "--force")
    assert forced.returncode == 0, forced.stderr
    assert data(lab, TEMPLATE.format("mine"))["mappings"] == ["imu"]


def test_a_draft_that_does_not_validate_is_refused(lab: Lab) -> None:
    """Settings copied from a template whose default breaks its own bound: the new template
    would carry a new RC601, so nothing is written."""
    lab.replace(TEMPLATE.format("turtlebot3-burger"), "default: 0.22", "default: 0.5")
    done = from_file(
        lab, TB3_01, "tb3-01", "--template", "copy", "--settings-from", "turtlebot3-burger"
    )
    assert done.returncode == 1
    assert "RC601" in done.stderr and "robot-templates/copy.yaml" in done.stderr
    assert "nothing written" in done.stderr
    assert not lab.path(TEMPLATE.format("copy")).exists()
    assert not lab.path(SCHEME.format("copy")).exists()


def test_settings_are_copied_from_a_template_when_asked(lab: Lab) -> None:
    done = from_file(
        lab, TB3_01, "tb3-01", "--template", "copy", "--settings-from", "turtlebot3-burger"
    )
    assert done.returncode == 0, done.stderr
    settings = data(lab, TEMPLATE.format("copy"))["settings"]
    assert settings["max_linear_speed"]["maximum"] == 0.22
    assert lab.check().ok


def test_the_files_are_validated_before_they_are_written(lab: Lab) -> None:
    template = lab.path(TEMPLATE.format("bad"))
    scheme = lab.path(SCHEME.format("bad"))
    texts = {
        template: "mappings: [x, x]\n",  # RC607
        scheme: "mappings:\n  x: {kind: topic, name: 'a b', type: std_msgs/msg/String}\n",  # RC609
    }
    before = check(lab.root).diagnostics
    found = write_validated(lab.root, texts, before)
    assert {d.code for d in found} == {"RC607", "RC609"}
    assert not template.exists() and not scheme.exists()


def test_bad_arguments_and_reports_are_one_line_errors(lab: Lab) -> None:
    cases = [
        (b"{not json", ["tb3-01", "--template", "t"], 1, "is not an interfaces message"),
        (message([], error="ros2 not found"), ["tb3-01", "--template", "t"], 1, "source failed"),
        (TB3_01, ["tb3-01", "--template", "../x"], 2, "cannot name a file"),
        (TB3_01, ["tb3-01", "--template", "t", "--namespace", "1bad"], 1, "starting with a digit"),
        (
            message([("/rosout", "rcl_interfaces/msg/Log")]),
            ["tb3-01", "--template", "t"],
            1,
            "no interface a draft could bind",
        ),
    ]
    for payload, args, code, words in cases:
        done = from_file(lab, payload, *args)
        assert done.returncode == code, (args, done.stderr)
        assert words in done.stderr and "Traceback" not in done.stderr
    wrong = lab.run("draft", "tb3-01", "--platform", "ROS3", "--template", "t", "--from", "x")
    assert wrong.returncode == 1 and "did you mean 'ROS2'" in wrong.stderr
    missing = lab.run(
        "draft",
        "tb3-01",
        "--platform",
        "ROS2",
        "--template",
        "t",
        "--from",
        str(lab.root / "none.json"),
    )
    assert missing.returncode == 2 and "cannot read --from" in missing.stderr
    lab.replace("configs/fleet.yaml", "namespace: tb3_01", "namespace: 1tb3")
    bad_fleet = from_file(lab, TB3_01, "tb3-01", "--template", "t")
    assert bad_fleet.returncode == 1 and "gives tb3-01 namespace '1tb3'" in bad_fleet.stderr
    assert not lab.path(TEMPLATE.format("t")).exists()


def test_draft_reads_the_robot_s_retained_interfaces(lab: Lab, mosquitto: Mosquitto) -> None:
    """As a robot would: retained messages on <prefix>/robots/<id>/interfaces."""
    topics = Topics("robotconf")
    # tb3-04 is the lab's physical robot, without a namespace: names stay absolute.
    lab_robot = message(
        [
            ("/scan", "sensor_msgs/msg/LaserScan"),
            ("/image_raw/compressed", "sensor_msgs/msg/CompressedImage"),
        ],
        [("/door_bridge/open", "std_srvs/srv/Trigger")],
    )
    publish(mosquitto.url, topics.interfaces("tb3-04"), lab_robot)
    publish(mosquitto.url, topics.interfaces("tb3-02"), message([], error="ros2 timed out"))
    publish(mosquitto.url, topics.interfaces("tb3-03"), b"\xff garbage")
    publish(mosquitto.url, topics.interfaces("tb3-05"), b" " * (600 * 1024))

    def draft(robot: str, template: str) -> Any:
        args = ("--platform", "ROS2", "--template", template, "--broker", mosquitto.url)
        return lab.run("draft", robot, *args)

    done = draft("tb3-04", "lab-tb3")
    assert done.returncode == 0, done.stderr
    scheme = data(lab, SCHEME.format("lab-tb3"))["mappings"]
    assert scheme["scan"]["name"] == "/scan" and scheme["camera"]["name"] == "/image_raw/compressed"
    assert scheme["door_opener"]["kind"] == "service"
    assert lab.check().ok
    nothing = draft("tb3-01", "t1")
    assert nothing.returncode == 1 and "tb3-01 has reported no interfaces" in nothing.stderr
    failed = draft("tb3-02", "t2")
    assert failed.returncode == 1 and "source failed (ros2 timed out)" in failed.stderr
    garbage = draft("tb3-03", "t3")
    assert garbage.returncode == 1 and "is not an interfaces message" in garbage.stderr
    huge = draft("tb3-05", "t5")
    assert huge.returncode == 1 and "over the limit" in huge.stderr
    for name in ("t1", "t2", "t3", "t5"):
        assert not lab.path(TEMPLATE.format(name)).exists()


def test_draft_without_a_broker_says_so(lab: Lab, tmp_path: Path) -> None:
    url = f"mqtt://127.0.0.1:{free_port()}"
    args = ("--platform", "ROS2", "--template", "t", "--broker", url, "--wait", "0.5")
    done = lab.run("draft", "tb3-04", *args)
    assert done.returncode == 2 and "is the broker running?" in done.stderr


def test_the_documented_example_drafts_the_lab_robot(lab: Lab) -> None:
    """docs/how-to/real-robots.md's example: tb3-04's report in examples/, drafted and then
    autofilled."""
    report = ROOT / "examples" / "interfaces" / "tb3-04.json"
    done = lab.run(
        "draft",
        "tb3-04",
        "--platform",
        "ROS2",
        "--template",
        "turtlebot3-waffle-pi-lab",
        "--settings-from",
        "turtlebot3-waffle-pi",
        "--from",
        str(report),
    )
    assert done.returncode == 0, done.stderr
    page = (ROOT / "docs" / "how-to" / "real-robots.md").read_text(encoding="utf-8")
    shown = [
        line
        for line in done.stdout.splitlines()
        if not line.startswith(("  imu", "  odometry", "  scan", "  sensor_state", "  navigate"))
    ]
    for line in shown[:7]:
        assert f"\n{line}\n" in page, line
    # This lab has no .robotconf.yaml, so RC608 warns; the page shows the example repository,
    # whose .robotconf.yaml turns RC608 off, and says so.
    warning = "models/platforms/ROS2/mapping-schemes/gazebo.yaml:8:3: warning RC608 "
    assert warning in done.stdout + done.stderr
    assert "`.robotconf.yaml` turns RC608 off" in page
    filled = lab.run(
        "autofill",
        "--platform",
        "ROS2",
        "--scheme",
        "turtlebot3-waffle-pi-lab",
        "--template",
        "turtlebot3-waffle-pi-lab",
    )
    assert filled.returncode == 0, filled.stderr
    assert "Follow: follow_with_poses" in filled.stdout


def test_a_file_that_cannot_be_written_takes_the_other_back(lab: Lab) -> None:
    """The scheme's path is a folder: the template written before it is removed again."""
    lab.path(SCHEME.format("blocked")).mkdir(parents=True)
    done = from_file(lab, TB3_01, "tb3-01", "--template", "blocked", "--force")
    assert (
        done.returncode == 2 and "cannot write" in done.stderr and "nothing written" in done.stderr
    )
    assert not lab.path(TEMPLATE.format("blocked")).exists()
    # Overwriting: the template's old text is put back.
    lab.write(TEMPLATE.format("blocked"), "mappings: [scan]\n")
    again = from_file(lab, TB3_01, "tb3-01", "--template", "blocked", "--force")
    assert again.returncode == 2
    assert lab.read(TEMPLATE.format("blocked")) == "mappings: [scan]\n"


def test_check_with_sees_the_files_as_if_written(lab: Lab) -> None:
    broken = "mappings:\n  scan: {kind: topic, name: 'a b', type: sensor_msgs/msg/LaserScan}\n"
    before = lab.read(SCHEME.format("gazebo"))
    found = check_with(lab.root, {SCHEME.format("gazebo"): broken.encode()})
    assert [d.code for d in found.errors if d.path == SCHEME.format("gazebo")] == ["RC609"]
    assert lab.read(SCHEME.format("gazebo")) == before and lab.check().ok
    added = check_with(lab.root, {TEMPLATE.format("new"): b"mappings: [scan]\n"})
    assert "new" in added.repo.platforms["ROS2"].templates


def test_a_hostile_report_is_listed_within_bounds(lab: Lab) -> None:
    odd = [(f"/bad name {i}\x1b[31m", "std_msgs/msg/String") for i in range(30)]
    done = from_file(
        lab, message([*odd, ("/fine", "std_msgs/msg/String")]), "tb3-04", "--template", "t"
    )
    assert done.returncode == 0, done.stderr
    left = [line for line in done.stdout.splitlines() if line.startswith("left out topic")]
    assert len(left) == 20 and "left out 10 more interface(s) the same way" in done.stdout
    assert "\x1b" not in done.stdout and "\\x1b" in done.stdout
    assert data(lab, TEMPLATE.format("t"))["mappings"] == ["fine"]


def test_drafting_again_keeps_a_renamed_mapping(lab: Lab) -> None:
    assert from_file(lab, TB3_01, "tb3-01", "--template", "again").returncode == 0
    for rel in (TEMPLATE.format("again"), SCHEME.format("again")):
        lab.write(rel, lab.read(rel).replace("front_scan", "rear_lidar"))
    done = from_file(lab, TB3_01, "tb3-01", "--template", "again", "--force")
    assert done.returncode == 0, done.stderr
    assert "rear_lidar" in data(lab, TEMPLATE.format("again"))["mappings"]
    assert "front_scan" not in lab.read(SCHEME.format("again"))
