"""Readers keep a robot's interfaces as the payload's bytes (KeptInterfaces), not as a model
per entry: the same drift as the parsed report, at the cost of the bytes the view holds."""

from __future__ import annotations

import json
import tracemalloc

from hypothesis import given
from hypothesis import strategies as st

from robotconf.configurator.drift import Need, drift_of
from robotconf.contract.interfaces import KeptInterfaces, RobotInterfaces, index
from robotconf.contract.wire import Topics
from robotconf.readmodel.observed import parse_retained

TOPICS = Topics()
NAMES = st.sampled_from(["/scan", "/odom", "/cmd_vel", "/tb3_01/scan", "/navigate_to_pose"])
TYPES = st.sampled_from(
    ["sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry", "geometry_msgs/Twist", "x/msg/Y"]
)
ENTRIES = st.lists(st.fixed_dictionaries({"name": NAMES, "type": TYPES}), max_size=8)
NEEDS = (
    Need("scan", "/scan", "topic", "sensor_msgs/msg/LaserScan", ("patrol",)),
    Need("odometry", "/odom", "topic", "nav_msgs/msg/Odometry", ("patrol",)),
    Need("cmd_vel", "/cmd_vel", "topic", "geometry_msgs/msg/Twist", ("patrol",)),
    Need("nav", "/navigate_to_pose", "action_client", "nav2_msgs/action/NavigateToPose", ()),
)


def report(i: int, entries: int) -> bytes:
    topics = [
        {"name": f"/r{i:05d}/sensors/s{k}/data", "type": "std_msgs/msg/Float32"}
        for k in range(entries)
    ]
    body = {"topics": topics, "services": [], "actions": [], "source": "ros2", "at": 1.0}
    return json.dumps(body).encode()


@given(ENTRIES, ENTRIES, ENTRIES, st.integers(0, 3), st.none() | st.just("ros2 timed out"))
def test_kept_bytes_judge_as_the_parsed_report(
    topics: list[dict[str, str]],
    services: list[dict[str, str]],
    actions: list[dict[str, str]],
    truncated: int,
    error: str | None,
) -> None:
    body = {"topics": topics, "services": services, "actions": actions, "truncated": truncated}
    payload = json.dumps({**body, "error": error} if error else body).encode()
    parsed = RobotInterfaces.model_validate_json(payload)
    kept = KeptInterfaces(payload, parsed)
    assert index(kept) == index(parsed)
    assert drift_of("r1", NEEDS, kept) == drift_of("r1", NEEDS, parsed)
    assert kept.report() == parsed and kept.verdict == parsed.verdict


def test_the_reconciler_keeps_a_report_as_its_payload() -> None:
    payloads = {TOPICS.interfaces(f"r{i:05d}"): report(i, 300) for i in range(100)}
    tracemalloc.start()
    try:
        seen = parse_retained(payloads, TOPICS)
        held, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    kept = seen.robots["r00007"].interfaces
    assert isinstance(kept, KeptInterfaces) and kept.count == 300
    assert kept.payload is payloads[TOPICS.interfaces("r00007")]  # the view's own bytes
    # Parsed into models these reports would take about nine times their 2 MB of payload;
    # kept as the payloads they take a few hundred bytes each.
    assert held < 100 * 2_000, f"{held:,} bytes held for 100 reports"
