"""Whether a logic fits a live robot's reported interfaces (configurator/fitting.py)."""

from __future__ import annotations

from robotconf.configurator.fitting import logic_fits_interfaces
from robotconf.configurator.types import Logic, MappingBinding, MappingScheme
from robotconf.contract.interfaces import RobotInterfaces

SCHEME = MappingScheme(
    mappings={
        "scan": MappingBinding(kind="topic", name="scan", type="sensor_msgs/msg/LaserScan"),
        "cmd_vel": MappingBinding(kind="topic", name="/cmd_vel", type="geometry_msgs/msg/Twist"),
        "door": MappingBinding(kind="service", name="/door/open", type="std_srvs/srv/Trigger"),
        "nav": MappingBinding(
            kind="action_client", name="{namespace}/navigate", type="nav2_msgs/action/Nav"
        ),
    }
)


def robot(**kinds: list[tuple[str, str]]) -> RobotInterfaces:
    data = {kind: [{"name": n, "type": t} for n, t in pairs] for kind, pairs in kinds.items()}
    return RobotInterfaces.model_validate(data)


def test_a_logic_fits_when_every_mapping_is_there_with_its_type() -> None:
    live = robot(
        topics=[("/tb3_04/scan", "sensor_msgs/LaserScan"), ("/cmd_vel", "geometry_msgs/msg/Twist")],
        services=[("/door/open", "std_srvs/srv/Trigger")],
        actions=[("/tb3_04/navigate", "nav2_msgs/action/Nav")],
    )
    logic = Logic(mappings=["scan", "cmd_vel", "door", "nav"])
    assert logic_fits_interfaces(logic, SCHEME, "tb3_04", live) == []
    assert logic_fits_interfaces(Logic(), SCHEME, None, robot()) == []


def test_each_reason_a_logic_does_not_fit() -> None:
    live = robot(
        topics=[("/scan", "sensor_msgs/msg/PointCloud2"), ("/door/open", "std_srvs/srv/Trigger")]
    )
    logic = Logic(mappings=["scan", "cmd_vel", "door", "nav", "arm"])
    assert logic_fits_interfaces(logic, SCHEME, None, live) == [
        "robot's topic /scan is sensor_msgs/msg/PointCloud2, not sensor_msgs/msg/LaserScan "
        "(mapping scan)",
        "robot lacks topic /cmd_vel (geometry_msgs/msg/Twist), mapping cmd_vel",
        # a topic of that name is not the service
        "robot lacks service /door/open (std_srvs/srv/Trigger), mapping door",
        "mapping nav: '{namespace}/navigate' needs the robot's namespace, and it has none",
        "mapping scheme does not bind arm",
    ]


def test_the_namespace_decides_where_relative_names_are_looked_for() -> None:
    live = robot(topics=[("/scan", "sensor_msgs/msg/LaserScan")])
    logic = Logic(mappings=["scan"])
    assert logic_fits_interfaces(logic, SCHEME, None, live) == []
    assert logic_fits_interfaces(logic, SCHEME, "/tb3_04", live) == [
        "robot lacks topic /tb3_04/scan (sensor_msgs/msg/LaserScan), mapping scan"
    ]


def test_a_topic_with_several_types_fits_when_one_is_the_type() -> None:
    live = robot(topics=[("/scan", "a/msg/B"), ("/scan", "sensor_msgs/msg/LaserScan")])
    assert logic_fits_interfaces(Logic(mappings=["scan"]), SCHEME, None, live) == []


def test_a_failed_source_proves_nothing_and_a_cut_report_is_said() -> None:
    failed = RobotInterfaces(error="ros2 timed out after 10 s")
    assert logic_fits_interfaces(Logic(mappings=[]), SCHEME, None, failed) == [
        "the robot's interfaces are not known: ros2 timed out after 10 s"
    ]
    cut = RobotInterfaces(truncated=3)
    assert logic_fits_interfaces(Logic(mappings=["cmd_vel"]), SCHEME, None, cut) == [
        "robot lacks topic /cmd_vel (geometry_msgs/msg/Twist), mapping cmd_vel "
        "(3 interface(s) were left out of the report)"
    ]
