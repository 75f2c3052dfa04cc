"""What `up` gives each robot to try drift, `draft` and deferral with, pure: its stand-in
`ros2` graph (what its request needs, so no drift at first), its agent.yaml's interfaces
reporting (ROS 2 robots only) and the line that says how to make one busy."""

from __future__ import annotations

from pathlib import Path

import yaml

from robotconf.agent.config import parse_config
from robotconf.configurator.drift import drift_of, needs_of_rendered
from robotconf.configurator.render import FleetRender, render_fleet
from robotconf.contract.interfaces import Interface, RobotInterfaces
from robotconf.contract.mqtt import Connection
from robotconf.workstation.up import GRAPH_FILE, UpSetup, agent_yaml, robots_line, standin_graph
from tests.support.lab import Lab


def fleet(tmp_path: Path) -> FleetRender:
    checked = Lab(tmp_path / "lab").check()
    assert checked.ok, checked.errors
    return render_fleet(checked.repo)


def reported(graph: dict[str, list[dict[str, str]]]) -> RobotInterfaces:
    def entries(kind: str) -> list[Interface]:
        return [Interface(name=e["name"], type=e["type"]) for e in graph[kind]]

    return RobotInterfaces(
        topics=entries("topics"),
        services=entries("services"),
        actions=entries("actions"),
        source="ros2",
    )


def test_each_robot_s_graph_is_what_its_request_needs_so_it_does_not_drift(
    tmp_path: Path,
) -> None:
    render = fleet(tmp_path)
    for robot_id, request in render.requests.items():
        graph = standin_graph(render, robot_id)
        drift = drift_of(robot_id, needs_of_rendered(request), reported(graph))
        assert drift.interfaces == "reported" and not drift.items, (robot_id, drift)
    tb3_01 = standin_graph(render, "tb3-01")  # in namespace tb3_01: its names qualified
    assert {"name": "/tb3_01/odom", "type": "nav_msgs/msg/Odometry"} in tb3_01["topics"]
    tb3_04 = standin_graph(render, "tb3-04")
    assert tb3_04["actions"] == [
        {"name": "/navigate_to_pose", "type": "nav2_msgs/action/NavigateToPose"}
    ]
    assert {"name": "/rosout", "type": "rcl_interfaces/msg/Log"} in tb3_04["topics"]


def test_ros2_robots_report_through_the_stand_in_and_ros1_robots_not(tmp_path: Path) -> None:
    render = fleet(tmp_path)
    work = tmp_path / "up"
    connection = Connection("mqtt://127.0.0.1:1883")
    ros2 = agent_yaml(render, "tb3-04", work, connection, "robotconf")
    assert ros2["interfaces"] == {"interval": 10.0}
    assert ros2["env"]["PATH"].startswith(f"{work / 'bin'}:")
    assert ros2["env"]["STANDIN_ROS2_GRAPH"] == str(work / "tb3-04" / GRAPH_FILE)
    config = parse_config(yaml.safe_dump(ros2), "agent.yaml", prepare=False)
    assert config.interfaces is not None and config.interfaces.command is None  # ros2 itself
    ros1 = agent_yaml(render, "tb3-05", work, connection, "robotconf")  # noetic
    assert "interfaces" not in ros1 and "env" not in ros1


def test_up_says_how_to_make_a_robot_busy_or_drift(tmp_path: Path) -> None:
    render = fleet(tmp_path)
    setup = UpSetup(tmp_path, "main", "h" * 40, render, tmp_path / "up")
    line = robots_line(setup)
    assert f"`touch {tmp_path}/up/tb3-01/brain.hold` makes tb3-01 busy" in line
    assert f"{tmp_path}/up/tb3-01/ros2-graph.json is what its stand-in ros2 reports" in line
