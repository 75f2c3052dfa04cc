"""The interfaces source's output: ros2cli's `list -t` lines and a command's JSON, parsed
strictly and bounded (agent/interfaces.py), and the stand-in `ros2` printing that format."""

from __future__ import annotations

import json
import re

import pytest

from robotconf.agent.interfaces import (
    SourceError,
    bound,
    check_names,
    exit_reason,
    parse_cli_list,
    parse_command_json,
)
from robotconf.agent.standin_ros2 import lines_of
from robotconf.contract.interfaces import MAX_INTERFACE_NAME, MAX_INTERFACES, MAX_INTERFACES_BYTES
from robotconf.contract.wire import AgentState, AgentStatus

# What `ros2 topic list -t` prints on a TurtleBot3 (ros2topic/verb/list.py: name, a space,
# the types in brackets joined by ', ').
TOPICS = """\
/cmd_vel [geometry_msgs/msg/Twist]
/odom [nav_msgs/msg/Odometry]
/parameter_events [rcl_interfaces/msg/ParameterEvent]
/rosout [rcl_interfaces/msg/Log]
/scan [sensor_msgs/msg/LaserScan]
"""


def test_one_line_per_name_with_its_type() -> None:
    found = parse_cli_list(TOPICS, "ros2 topic list -t")
    assert ("/scan", "sensor_msgs/msg/LaserScan") in found
    assert len(found) == 5


def test_several_types_of_one_name_are_one_entry_each() -> None:
    found = parse_cli_list("/chatter [std_msgs/msg/String, example/msg/Other]\n", "t")
    assert found == [("/chatter", "std_msgs/msg/String"), ("/chatter", "example/msg/Other")]


def test_services_and_actions_have_the_same_format() -> None:
    services = "/add_two_ints [example_interfaces/srv/AddTwoInts]\n"
    actions = "/fibonacci [action_tutorials_interfaces/action/Fibonacci]\n"
    assert parse_cli_list(services, "s") == [("/add_two_ints", "example_interfaces/srv/AddTwoInts")]
    assert parse_cli_list(actions, "a")[0][1] == "action_tutorials_interfaces/action/Fibonacci"


def test_no_output_is_no_interface_and_blank_lines_are_skipped() -> None:
    assert parse_cli_list("", "t") == []
    assert len(parse_cli_list("\n" + TOPICS + "\n\n", "t")) == 5


@pytest.mark.parametrize(
    "line",
    [
        "/odom geometry_msgs/msg/Twist",  # no brackets: `ros2 topic list` without -t, or noise
        "/odom [geometry_msgs/msg/Twist",
        "Traceback (most recent call last):",
        "/a [b] [c]",
    ],
)
def test_any_other_line_refuses_the_whole_output(line: str) -> None:
    with pytest.raises(SourceError, match=re.escape("on line 2, not NAME [TYPE, ...]")):
        parse_cli_list("/ok [std_msgs/msg/Empty]\n" + line + "\n", "ros2 topic list -t")


def test_names_and_types_that_are_no_ros_names_are_garbage() -> None:
    with pytest.raises(SourceError, match="not a ROS name"):
        check_names({"topics": [("scan", "sensor_msgs/msg/LaserScan")]}, "t")
    with pytest.raises(SourceError, match="not pkg/msg/Type"):
        check_names({"topics": [("/scan", "LaserScan")]}, "t")


def test_over_long_names_are_left_out_and_counted() -> None:
    long = "/" + "a" * MAX_INTERFACE_NAME
    kept, cut = check_names(
        {"topics": [(long, "std_msgs/msg/Empty"), ("/ok", "std_msgs/msg/Empty")]}, "t"
    )
    assert kept["topics"] == [("/ok", "std_msgs/msg/Empty")] and cut == 1


def test_the_command_json() -> None:
    raw = json.dumps(
        {
            "topics": [{"name": "/scan", "type": "sensor_msgs/LaserScan"}],
            "actions": [{"name": "/move_base", "type": "move_base_msgs/MoveBaseAction"}],
            "note": "other keys are ignored",
        }
    ).encode()
    entries = parse_command_json(raw, "cmd")
    assert entries["topics"] == [("/scan", "sensor_msgs/LaserScan")]
    assert entries["services"] == []  # a missing kind is empty


@pytest.mark.parametrize(
    ("raw", "reason"),
    [
        (b"not json", "no usable JSON object: malformed JSON"),
        (b"[1, 2]", "expected a JSON object"),
        (b'{"topics": {"/a": "b"}}', "topics that is not a list"),
        (b'{"topics": [{"name": "/a"}]}', 'topics[0], which is not {"name": TEXT, "type": TEXT}'),
        (b'{"services": ["/a"]}', "services[0], which is not"),
        (b'{"topics": [], "topics": []}', "duplicate key"),
    ],
)
def test_a_command_printing_anything_else_is_refused(raw: bytes, reason: str) -> None:
    with pytest.raises(SourceError, match=re.escape(reason)):
        parse_command_json(raw, "cmd")


def test_bounds_sort_deduplicate_and_count_what_is_cut() -> None:
    many = [(f"/t{i:05d}", "std_msgs/msg/Empty") for i in range(MAX_INTERFACES + 10)]
    kept, cut = bound({"topics": list(reversed(many)), "services": [("/s", "a/srv/B")] * 2})
    assert len(kept["topics"]) == MAX_INTERFACES and kept["topics"][0] == many[0]
    assert kept["services"] == []  # topics come first; what does not fit is counted
    assert cut == 10 + 1


def test_bounds_keep_the_payload_under_its_limit() -> None:
    name = "/" + "n" * (MAX_INTERFACE_NAME - 1)
    big = [(f"{name[:-5]}{i:05d}", "x" * 200 + "/msg/T") for i in range(3000)]
    kept, cut = bound({"topics": big})
    size = sum(len(n) + len(t) + 23 for n, t in kept["topics"])
    assert size <= MAX_INTERFACES_BYTES and cut == 3000 - len(kept["topics"]) > 0


def test_a_failure_is_one_line_with_the_last_line_of_stderr() -> None:
    reason = exit_reason("ros2 topic list -t", 1, b"Traceback...\n  x\nRuntimeError: !rclpy.ok()\n")
    assert reason == "`ros2 topic list -t` exited with code 1: RuntimeError: !rclpy.ok()"
    assert "killed by SIGKILL" in exit_reason("c", -9, b"")
    assert "\\x1b" in exit_reason("c", 2, b"\x1b[31mred\n")  # escaped, never raw


def test_the_standin_prints_what_the_parser_reads() -> None:
    graph = {
        "topics": [
            {"name": "/chatter", "type": "std_msgs/msg/String"},
            {"name": "/chatter", "type": "example/msg/Other"},
            {"name": "/a", "type": "std_msgs/msg/Empty"},
        ]
    }
    lines = lines_of(graph, "topic", show_types=True)
    assert lines == ["/a [std_msgs/msg/Empty]", "/chatter [std_msgs/msg/String, example/msg/Other]"]
    assert lines_of(graph, "topic", show_types=False) == ["/a", "/chatter"]
    assert len(parse_cli_list("\n".join(lines), "t")) == 3


def test_the_status_says_why_interfaces_cannot_be_read_and_older_statuses_still_read() -> None:
    older = AgentStatus.model_validate_json(b'{"robot_id": "tb3-01", "state": "running"}')
    assert older.interfaces_error is None
    newer = AgentStatus(robot_id="tb3-01", state=AgentState.IDLE, interfaces_error="no `ros2`")
    assert AgentStatus.model_validate_json(newer.model_dump_json()) == newer
