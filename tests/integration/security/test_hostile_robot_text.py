"""A robot's own text reaches the desk as data: `robotconf restart` confirms a restart from a
robot (a test client on a real Mosquitto, no agent) whose status message would forge lines
and clear the operator's terminal (issue 20, item 4)."""

from __future__ import annotations

import json
import subprocess
import threading
from typing import Any

import paho.mqtt.client as paho

from robotconf.contract.mqtt import Connection, make_client
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from tests.support.agents import publish
from tests.support.lab import ROBOTCONF
from tests.support.mosquitto import Mosquitto
from tests.support.watch import wait_for

ROBOT = "tb3-01"
TOPICS = Topics()
FORGED = "\nERROR forged line\r\x1b[2J\x1b]0;owned\x07\u202egnp.exe"


class HostileRobot:
    """Says it runs; confirms each restart asked of it with a status whose message is FORGED."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.asked = threading.Event()
        self.client = make_client(Connection(url), client_id="hostile-robot")
        self.client.on_message = self._asked
        address = Connection(url).address
        self.client.connect(address.host, address.port)
        self.client.subscribe(TOPICS.restart(ROBOT), qos=1)
        self.client.loop_start()
        self._say(AgentStatus(robot_id=ROBOT, state=AgentState.RUNNING, message="up"))

    def _say(self, status: AgentStatus) -> None:
        publish(self.url, TOPICS.status(ROBOT), status.model_dump_json().encode())

    def _asked(self, client: paho.Client, userdata: Any, message: paho.MQTTMessage) -> None:
        request = json.loads(message.payload)
        self.asked.set()
        threading.Thread(
            target=self._say,
            args=(
                AgentStatus(
                    robot_id=ROBOT,
                    state=AgentState.RUNNING,
                    message=FORGED,
                    restart_requested_by=request["requested_by"],
                    restart_requested_at=request["issued_at"],
                ),
            ),
            daemon=True,
        ).start()

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()


def test_restart_prints_the_robots_confirmation_escaped(mosquitto: Mosquitto) -> None:
    robot = HostileRobot(mosquitto.url)
    try:
        done = subprocess.run(
            [ROBOTCONF, "restart", ROBOT, "--broker", mosquitto.url, "--as", "alice"],
            capture_output=True,
            timeout=120,
        )
        wait_for(robot.asked.is_set, "the restart asked of the robot")
    finally:
        robot.close()
    assert done.returncode == 0, done.stderr
    out = done.stdout.decode("utf-8")
    assert b"\x1b" not in done.stdout and b"\r" not in done.stdout and "\u202e" not in out
    assert out.splitlines() == [
        f"{ROBOT}: restart requested by alice: running "
        "(\\nERROR forged line\\r\\x1b[2J\\x1b]0;owned\\x07\\u202egnp.exe)"
    ]


def test_status_shows_a_robot_s_hostile_interfaces_escaped(mosquitto: Mosquitto) -> None:
    """The types a robot reports are its own text: a drift line quoting them forges nothing."""
    from robotconf.contract.interfaces import Interface, RobotInterfaces
    from tests.support.agents import make_request
    from tests.support.interfaces import publish_interfaces

    request = make_request(ROBOT)  # the lab (cwd) wants /tb3_01/cmd_vel as a Twist
    publish(mosquitto.url, TOPICS.launch(ROBOT), request.payload())
    running = AgentStatus(robot_id=ROBOT, state=AgentState.RUNNING, digest=request.digest)
    publish(mosquitto.url, TOPICS.status(ROBOT), running.model_dump_json().encode())
    hostile = RobotInterfaces(
        topics=[Interface(name="/tb3_01/cmd_vel", type=FORGED)], source=FORGED
    )
    publish_interfaces(mosquitto.url, ROBOT, hostile)
    for args in ([], ["--json"]):
        done = subprocess.run(
            [ROBOTCONF, "status", "--broker", mosquitto.url, "--wait", "5", *args],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert "not geometry_msgs/msg/Twist" in done.stdout or "found_type" in done.stdout
        for raw in ("\x1b", "\x07", "\r", "\u202e", "\nERROR forged line"):
            assert raw not in done.stdout + done.stderr, (args, raw)
