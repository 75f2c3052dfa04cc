"""`robotconf up`'s embedded broker holds each client to the topics the generated ACL gives it: a
robot of `up`, with the login `up` made for it, uses its own topics and nobody else's."""

from __future__ import annotations

import re
import signal
import threading
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion

from robotconf.contract.wire import AgentStatus, LogsRequest
from tests.support.fleet import GitLab, Proc, robotconf_argv
from tests.support.watch import wait_for

ROBOTS = "robotconf/robots"


class Client:
    """A paho client of the embedded broker: its CONNACK, SUBACK codes and what it received."""

    def __init__(
        self,
        port: int,
        client_id: str,
        user: str,
        password: str,
        will: str | None = None,
    ) -> None:
        self.connacks: list[Any] = []
        self.subacks: list[bool] = []  # per filter: refused
        self.received: list[tuple[str, bytes]] = []
        self._lock = threading.Lock()
        self.paho = paho.Client(CallbackAPIVersion.VERSION2, client_id=client_id)
        self.paho.username_pw_set(user, password)
        if will is not None:
            self.paho.will_set(will, b"forged will", qos=1, retain=True)
        self.paho.on_connect = lambda c, u, f, code, p: self.connacks.append(code)
        self.paho.on_message = self._on_message
        self.paho.on_subscribe = lambda c, u, mid, codes, p: self.subacks.extend(
            code.is_failure for code in codes
        )
        self.paho.connect("127.0.0.1", port)
        self.paho.loop_start()
        wait_for(lambda: self.connacks, f"{client_id}'s CONNACK")

    def _on_message(self, client: Any, userdata: Any, message: paho.MQTTMessage) -> None:
        with self._lock:
            self.received.append((message.topic, bytes(message.payload)))

    @property
    def refused(self) -> bool:
        return bool(self.connacks[0].is_failure)

    def subscribe(self, *filters: str) -> list[bool]:
        """Whether each filter was refused, in order."""
        before = len(self.subacks)
        self.paho.subscribe([(f, 1) for f in filters])
        wait_for(lambda: len(self.subacks) >= before + len(filters), "the SUBACK")
        return self.subacks[before:]

    def got(self, topic: str) -> list[bytes]:
        with self._lock:
            return [payload for t, payload in self.received if t == topic]

    def close(self) -> None:
        self.paho.loop_stop()
        self.paho.disconnect()


class UpBroker:
    """The embedded broker of a running `up`, and clients of it with the logins `up` made."""

    def __init__(self, root: Path, output: str) -> None:
        self.port = int(re.findall(r"embedded amqtt at mqtt://[\d.]+:(\d+)", output)[0])
        self.logins = root / ".robotconf" / "up" / "broker"
        self.clients: list[Client] = []

    def client(self, client_id: str, user: str, will: str | None = None) -> Client:
        password = (self.logins / f"{user}.password").read_text(encoding="utf-8").strip()
        made = Client(self.port, client_id, user, password, will)
        self.clients.append(made)
        return made

    def close(self) -> None:
        for made in self.clients:
            made.close()


def _writes_to_other_robots_are_dropped(robot: Client, desk: Client) -> None:
    """Its writes to another robot's topics are dropped; to its own, delivered (in order: the
    fence on its own logs topic comes after them)."""
    robot.paho.publish(f"{ROBOTS}/tb3-01/status", b"forged status", qos=1, retain=True)
    robot.paho.publish(f"{ROBOTS}/tb3-01/interfaces", b"forged interfaces", qos=1, retain=True)
    robot.paho.publish(f"{ROBOTS}/tb3-02/logs", b"fence", qos=1)
    wait_for(lambda: desk.got(f"{ROBOTS}/tb3-02/logs"), "the robot's own log line")
    assert desk.got(f"{ROBOTS}/tb3-02/logs") == [b"fence"]
    forged = [p for _, p in desk.received if p.startswith(b"forged")]
    assert forged == []


def _only_its_own_log_request_reaches_it(robot: Client, desk: Client) -> None:
    """The desk asks tb3-01 for its log, then tb3-02: only tb3-02's own ask reaches it."""
    for robot_id in ("tb3-01", "tb3-02"):
        ask = LogsRequest(session=f"s-{robot_id}", lines=1).model_dump_json().encode()
        desk.paho.publish(f"{ROBOTS}/{robot_id}/logs/request", ask, qos=1)
    wait_for(lambda: robot.got(f"{ROBOTS}/tb3-02/logs/request"), "its own log request")
    topics = {topic for topic, _ in robot.received}
    assert topics == {f"{ROBOTS}/tb3-02/launch", f"{ROBOTS}/tb3-02/logs/request"}, topics


def test_a_robot_of_up_reads_and_writes_its_own_topics_and_no_other_robots(
    lab: GitLab, tmp_path: Path
) -> None:
    up = Proc(robotconf_argv("up", "--repo", str(lab.root)), tmp_path / "up.out", cwd=lab.root)
    broker: UpBroker | None = None
    try:
        wait_for(lambda: "all robots InSync" in up.output(), "up to report InSync")
        broker = UpBroker(lab.root, up.output())
        # Refused at the door: another robot's client id (it would take over that agent's
        # session), and a Last Will on another robot's status (amqtt sends wills unchecked).
        assert broker.client("robotconf-agent-tb3-01", "tb3-02").refused
        assert broker.client("tb3-02", "tb3-02", will=f"{ROBOTS}/tb3-01/status").refused

        desk = broker.client("desk", "operator")
        assert desk.subscribe(
            f"{ROBOTS}/tb3-01/status", f"{ROBOTS}/tb3-01/interfaces", f"{ROBOTS}/tb3-02/logs"
        ) == [False, False, False]
        robot = broker.client("tb3-02", "tb3-02")  # the id alone is a robot's own client id too
        assert not robot.refused
        # Another robot's request topic and every robot's launch are refused; its own are not.
        assert robot.subscribe(
            f"{ROBOTS}/tb3-01/logs/request",
            f"{ROBOTS}/+/launch",
            f"{ROBOTS}/tb3-02/launch",
            f"{ROBOTS}/tb3-02/logs/request",
        ) == [True, True, False, False]
        _writes_to_other_robots_are_dropped(robot, desk)
        _only_its_own_log_request_reaches_it(robot, desk)

        # What is retained for tb3-01 is still its agent's own.
        reader = broker.client("reader", "operator")
        reader.subscribe(f"{ROBOTS}/tb3-01/status", f"{ROBOTS}/tb3-01/interfaces")
        status = wait_for(lambda: reader.got(f"{ROBOTS}/tb3-01/status"), "tb3-01's status")
        assert AgentStatus.model_validate_json(status[-1]).robot_id == "tb3-01"
        assert all(not p.startswith(b"forged") for _, p in reader.received)
    finally:
        if broker is not None:
            broker.close()
        code = up.stop(signal.SIGINT, timeout=60)
    assert code == 0, up.output()
