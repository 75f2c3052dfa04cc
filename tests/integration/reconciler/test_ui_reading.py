"""The UI reads one robot's change alone (workstation/fleet_reader.py): after any sequence of
retained messages, its rows are those `status` works out from the whole broker, on a real
Mosquitto (statuses that change, appear, lie or cannot be read, and topics cleared)."""

from __future__ import annotations

import json
import random
from collections.abc import Iterator

import paho.mqtt.client as paho
import pytest

from robotconf.contract.mqtt import Connection
from robotconf.contract.wire import AgentState, Topics
from robotconf.workstation.fleet_status import DesiredCache, fleet_status
from robotconf.workstation.ui.state import LiveFleet
from tests.support.fleet import GitLab
from tests.support.mosquitto import Mosquitto
from tests.support.watch import wait_for


@pytest.fixture
def publisher(mosquitto: Mosquitto) -> Iterator[paho.Client]:
    client = paho.Client(paho.CallbackAPIVersion.VERSION2, client_id="ui-reading")
    client.connect("127.0.0.1", mosquitto.port)
    client.loop_start()
    try:
        yield client
    finally:
        client.disconnect()
        client.loop_stop()


def status(robot_id: str, state: AgentState, digest: str | None, restarts: int) -> bytes:
    return json.dumps(
        {"robot_id": robot_id, "state": state.value, "digest": digest, "restarts": restarts}
    ).encode()


def test_rows_read_one_robot_at_a_time_are_those_read_whole(
    lab: GitLab, mosquitto: Mosquitto, publisher: paho.Client
) -> None:
    topics = Topics()
    requests = lab.requests()
    robots = [*sorted(requests), "stray-1", "stray-2"]
    live = LiveFleet(Connection(mosquitto.url), topics.prefix, lab.root)
    live.start()
    try:
        wait_for(lambda: live.snapshot.fleet, "the first state")
        rng = random.Random(24)
        for step in range(60):
            robot = rng.choice(robots)
            digest = requests[robot].digest if robot in requests and rng.random() < 0.7 else None
            payload = rng.choice(
                [
                    status(robot, rng.choice(list(AgentState)), digest, step),
                    b"\x00\xffnot json",
                    b"",  # cleared
                    json.dumps({"robot_id": "someone-else", "state": "running"}).encode(),
                ]
            )
            topic = topics.status(robot) if rng.random() < 0.8 else topics.description(robot)
            publisher.publish(topic, payload, 1, True).wait_for_publish(10)
        # A robot known only to the broker, then gone from it: its row goes.
        publisher.publish(
            topics.status("stray-3"), status("stray-3", AgentState.IDLE, None, 0), 1, True
        )
        wait_for(lambda: live.snapshot.row("stray-3"), "stray-3 shown")
        publisher.publish(topics.status("stray-3"), b"", 1, True).wait_for_publish(10)

        def same() -> bool | None:
            whole = fleet_status(live.view.snapshot(), topics, DesiredCache(lab.root, None))
            shown = live.snapshot.fleet
            return (shown is not None and shown.rows == whole.rows) or None

        wait_for(same, "the rows read one robot at a time equal to those read whole")
    finally:
        live.stop()
        for robot in [*robots, "stray-3"]:
            for topic in (topics.status(robot), topics.description(robot)):
                publisher.publish(topic, b"", 1, True).wait_for_publish(10)
