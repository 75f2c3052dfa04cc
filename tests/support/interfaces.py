"""Publishing a robot's interfaces report as its agent would: a real MQTT client, retained."""

from __future__ import annotations

import itertools

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion

from robotconf.contract.interfaces import Interface, RobotInterfaces
from robotconf.contract.mqtt import parse_broker_url
from robotconf.contract.wire import Topics

_ids = itertools.count(1)


def publish_interfaces(
    url: str, robot_id: str, report: RobotInterfaces | bytes, prefix: str = "robotconf"
) -> None:
    """Retained on `<prefix>/robots/<id>/interfaces`, acknowledged before it returns; a
    `bytes` report is published as it is (garbage, an oversized one), b"" clears it."""
    address = parse_broker_url(url)
    client = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"test-robot-{next(_ids)}")
    client.connect(address.host, address.port)
    client.loop_start()
    try:
        payload = report if isinstance(report, bytes) else report.model_dump_json().encode()
        info = client.publish(Topics(prefix).interfaces(robot_id), payload, qos=1, retain=True)
        info.wait_for_publish(30)
        assert info.is_published(), f"the broker did not take {robot_id}'s interfaces"
    finally:
        client.disconnect()
        client.loop_stop()


def report(*topics: tuple[str, str], actions: tuple[tuple[str, str], ...] = ()) -> RobotInterfaces:
    """A report of these (name, type) topics and actions, from the ros2 source."""
    return RobotInterfaces(
        topics=[Interface(name=n, type=t) for n, t in topics],
        actions=[Interface(name=n, type=t) for n, t in actions],
        source="ros2",
        at=1.0,
    )


# tb3-04 (patrol-real) reporting only /odom, as a nav_msgs/msg/Path: its drift as JSON.
PATROL_ON_A_PATH_DRIFT = [
    {
        "mapping": "navigate_to_pose",
        "name": "/navigate_to_pose",
        "kind": "action_client",
        "expected_type": "nav2_msgs/action/NavigateToPose",
        "found_type": None,
    },
    {
        "mapping": "odometry",
        "name": "/odom",
        "kind": "topic",
        "expected_type": "nav_msgs/msg/Odometry",
        "found_type": "nav_msgs/msg/Path",
    },
]
