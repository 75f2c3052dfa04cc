"""The robot reports its interfaces: real agents, a real Mosquitto, and the stand-in `ros2`
(agent/standin_ros2.py) printing exactly ros2cli's `list -t` format from a graph file."""

from __future__ import annotations

import contextlib
import json
import os
import shlex
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
import pytest

from robotconf.agent.process import is_alive
from robotconf.agent.standin_ros2 import GRAPH_ENV, LOG_ENV, install
from robotconf.contract.interfaces import MAX_INTERFACES, RobotInterfaces
from robotconf.contract.launch import with_digest
from robotconf.contract.mqtt import Connection, make_client
from robotconf.contract.wire import AgentState, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import ROBOT, make_request, publish, read_retained, start_running
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

TOPICS = Topics()
GRAPH: dict[str, Any] = {
    "topics": [
        {"name": "/scan", "type": "sensor_msgs/msg/LaserScan"},
        {"name": "/cmd_vel", "type": "geometry_msgs/msg/Twist"},
        {"name": "/chatter", "type": "std_msgs/msg/String"},
        {"name": "/chatter", "type": "example_interfaces/msg/String"},
        {"name": "/domain_$ROS_DOMAIN_ID", "type": "std_msgs/msg/Empty"},
    ],
    "services": [{"name": "/add_two_ints", "type": "example_interfaces/srv/AddTwoInts"}],
    "actions": [{"name": "/navigate_to_pose", "type": "nav2_msgs/action/NavigateToPose"}],
}


@dataclass
class Ros2:
    """The stand-in `ros2` in a bin directory of its own, its graph file and its call log."""

    bin: Path
    graph: Path
    calls: Path

    def set(self, graph: dict[str, Any]) -> None:
        staged = self.graph.with_suffix(".next")
        staged.write_text(json.dumps(graph), encoding="utf-8")
        os.replace(staged, self.graph)  # the stand-in never reads half a file

    def env(self, **extra: str) -> dict[str, str]:
        """agent.yaml `env:` that puts it on the brain's PATH."""
        path = f"{self.bin}:{os.environ.get('PATH', '/usr/bin:/bin')}"
        env = {"PATH": path, GRAPH_ENV: str(self.graph), LOG_ENV: str(self.calls)}
        return {**env, "ROS_DOMAIN_ID": "0", **extra}

    def runs(self, mode: str | None = None) -> list[tuple[int, str, str]]:
        """(pid, verb, mode) of every run so far."""
        try:
            lines = self.calls.read_text(encoding="utf-8").splitlines()
        except FileNotFoundError:
            return []
        found = [(int(p), v, m) for p, v, m in (line.split() for line in lines)]
        return [run for run in found if mode is None or run[2] == mode]

    def readings(self) -> int:
        """Complete readings: `ros2 action list -t` is the last of each."""
        return sum(1 for _, verb, mode in self.runs() if verb == "action" and mode == "ok")


@pytest.fixture
def ros2(tmp_path: Path) -> Ros2:
    fake = Ros2(tmp_path / "rosbin", tmp_path / "graph.json", tmp_path / "ros2-calls.log")
    install(fake.bin)
    fake.set(GRAPH)
    return fake


class InterfacesWatch:
    """Every message on the interfaces topics, in arrival order."""

    def __init__(self, url: str) -> None:
        self.messages: dict[str, list[bytes]] = {}
        self._cond = threading.Condition()
        self.client = make_client(Connection(url), client_id="test-interfaces")
        self.client.on_connect = lambda c, *a: c.subscribe(TOPICS.all_interfaces, qos=1)
        self.client.on_message = self._on_message
        address = Connection(url).address
        self.client.connect(address.host, address.port)
        self.client.loop_start()

    def _on_message(self, client: paho.Client, userdata: Any, message: paho.MQTTMessage) -> None:
        found = TOPICS.robot_of(message.topic)
        if found is not None:
            with self._cond:
                self.messages.setdefault(found[0], []).append(bytes(message.payload))
                self._cond.notify_all()

    def reports(self, robot_id: str = ROBOT) -> list[RobotInterfaces]:
        with self._cond:
            payloads = list(self.messages.get(robot_id, []))
        return [RobotInterfaces.model_validate_json(p) for p in payloads]

    def wait(
        self, what: str, predicate: Callable[[RobotInterfaces], bool], robot_id: str = ROBOT
    ) -> RobotInterfaces:
        def probe() -> RobotInterfaces | None:
            reports = self.reports(robot_id)
            return reports[-1] if reports and predicate(reports[-1]) else None

        return wait_for(probe, f"{robot_id}'s interfaces: {what}")

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


@pytest.fixture
def seen(mosquitto: Mosquitto) -> Iterator[InterfacesWatch]:
    watcher = InterfacesWatch(mosquitto.url)
    try:
        yield watcher
    finally:
        watcher.close()


def names(report: RobotInterfaces, kind: str = "topics") -> list[tuple[str, str]]:
    return [(i.name, i.type) for i in getattr(report, kind)]


def test_the_robot_reports_its_interfaces_retained_read_with_the_brains_environment(
    make_agent: AgentFactory,
    watch: FleetWatch,
    mosquitto: Mosquitto,
    seen: InterfacesWatch,
    ros2: Ros2,
) -> None:
    agent = make_agent(interfaces={"interval": 0.5}, env=ros2.env(ROS_DOMAIN_ID="7"))
    status = start_running(agent, watch, mosquitto)
    report = seen.wait("reported", lambda r: bool(r.topics))
    assert names(report) == [
        ("/chatter", "example_interfaces/msg/String"),
        ("/chatter", "std_msgs/msg/String"),
        ("/cmd_vel", "geometry_msgs/msg/Twist"),
        ("/domain_7", "std_msgs/msg/Empty"),  # agent.yaml's ROS_DOMAIN_ID reached `ros2`
        ("/scan", "sensor_msgs/msg/LaserScan"),
    ]
    assert names(report, "services") == [("/add_two_ints", "example_interfaces/srv/AddTwoInts")]
    assert names(report, "actions") == [("/navigate_to_pose", "nav2_msgs/action/NavigateToPose")]
    assert report.source == "ros2" and report.truncated == 0 and report.error is None
    assert report.at is not None
    # Retained: a reader that comes later gets it, exactly as published.
    retained = json.loads(read_retained(mosquitto.url, TOPICS.interfaces(ROBOT)))
    assert "error" not in retained and RobotInterfaces.model_validate(retained) == report
    assert sorted({verb for _, verb, _ in ros2.runs()}) == ["action", "service", "topic"]
    latest = watch.status(ROBOT)
    assert latest is not None and latest.interfaces_error is None and latest.pid == status.pid


def test_a_change_is_published_and_an_unchanged_reading_is_not(
    make_agent: AgentFactory, watch: FleetWatch, seen: InterfacesWatch, ros2: Ros2
) -> None:
    agent = make_agent(interfaces={"interval": 0.2}, env=ros2.env(ROS_DOMAIN_ID="3")).start()
    first = seen.wait("reported", lambda r: bool(r.topics))
    changed = {
        **GRAPH,
        "topics": [*GRAPH["topics"], {"name": "/odom", "type": "nav_msgs/msg/Odometry"}],
    }
    ros2.set(changed)
    second = seen.wait("/odom appeared", lambda r: ("/odom", "nav_msgs/msg/Odometry") in names(r))
    assert len(names(second)) == len(names(first)) + 1
    after = ros2.readings()
    wait_for(lambda: ros2.readings() >= after + 3, "three more readings")
    assert len(seen.reports()) == 2, "an unchanged reading was published again"
    assert agent.proc is not None and agent.proc.poll() is None


def test_reporting_is_off_unless_configured(
    make_agent: AgentFactory, watch: FleetWatch, seen: InterfacesWatch, ros2: Ros2, tmp_path: Path
) -> None:
    """Two robots of one agent process, one loop: the one without `interfaces` runs no `ros2`
    and publishes nothing, while the other reads several times."""
    quiet = Ros2(ros2.bin, ros2.graph, tmp_path / "quiet-calls.log")
    on = make_agent("on", interfaces={"interval": 0.2}, env=ros2.env(ROS_DOMAIN_ID="1"))
    off = make_agent("off", robot_id="tb3-02", env=quiet.env(ROS_DOMAIN_ID="1"))
    on.start(off)
    watch.wait_state("tb3-02", AgentState.IDLE, agent=on)
    seen.wait("reported", lambda r: bool(r.topics))
    wait_for(lambda: ros2.readings() >= 3, "three readings of the robot that reports")
    assert quiet.runs() == [] and seen.reports("tb3-02") == []
    status = watch.status("tb3-02")
    assert status is not None and status.interfaces_error is None


def test_a_command_replaces_ros2_and_gets_the_brains_environment(
    make_agent: AgentFactory, watch: FleetWatch, seen: InterfacesWatch, tmp_path: Path
) -> None:
    script = tmp_path / "list_interfaces.py"
    script.write_text(
        "import json, os\n"
        "print(json.dumps({'topics': [{'name': '/tag_' + os.environ['LAB_TAG'],\n"
        "                              'type': 'sensor_msgs/LaserScan'}],\n"
        "                  'actions': [{'name': '/move_base',\n"
        "                               'type': 'move_base_msgs/MoveBaseAction'}]}))\n",
        encoding="utf-8",
    )
    command = [sys.executable, str(script)]
    make_agent(interfaces={"interval": 0.5, "command": command}, env={"LAB_TAG": "x7"}).start()
    report = seen.wait("reported", lambda r: bool(r.topics))
    assert names(report) == [("/tag_x7", "sensor_msgs/LaserScan")]  # a ROS 1 type is kept
    assert names(report, "actions") == [("/move_base", "move_base_msgs/MoveBaseAction")]
    assert report.services == [] and report.source == shlex.join(command)


def test_what_a_source_leaves_behind_is_killed_with_each_reading(
    make_agent: AgentFactory, seen: InterfacesWatch, tmp_path: Path
) -> None:
    """A source that forks a daemon (its output elsewhere) and succeeds: each reading ends
    with its whole process group, so no process is left behind per interval."""
    left = tmp_path / "left-behind.pids"
    script = tmp_path / "leaky_source.py"
    script.write_text(
        "import json, subprocess, sys\n"
        "daemon = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(600)'],\n"
        "    stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)\n"
        f"with open({str(left)!r}, 'a') as log:\n"
        "    log.write(f'{daemon.pid}\\n')\n"
        "print(json.dumps({'topics': [{'name': '/leaky', 'type': 'std_msgs/msg/Empty'}]}))\n",
        encoding="utf-8",
    )
    command = [sys.executable, str(script)]
    agent = make_agent(interfaces={"interval": 0.2, "command": command}).start()

    def pids() -> list[int]:
        try:
            return [int(line) for line in left.read_text(encoding="utf-8").split()]
        except (FileNotFoundError, ValueError):
            return []

    try:
        report = seen.wait("reported", lambda r: bool(r.topics))
        assert names(report) == [("/leaky", "std_msgs/msg/Empty")] and report.error is None
        # Three readings done: the daemons of the first two had their readings end.
        done = wait_for(lambda: pids()[:2] if len(pids()) >= 3 else None, "three readings")
        wait_for(lambda: not any(is_alive(pid) for pid in done), "the daemons killed")
        assert seen.reports()[-1].error is None  # the group's end is no failure of the reading
        # The agent stopped mid-interval or mid-reading: no daemon outlives it either.
        agent.signal(signal.SIGTERM)
        assert agent.wait() == 0
        wait_for(lambda: not any(is_alive(pid) for pid in pids()), "every daemon gone")
    finally:
        for pid in pids():  # a failed run leaves none behind either
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def test_a_failing_source_is_reported_with_its_reason_and_the_brain_keeps_running(
    make_agent: AgentFactory,
    watch: FleetWatch,
    mosquitto: Mosquitto,
    seen: InterfacesWatch,
    ros2: Ros2,
) -> None:
    agent = make_agent(interfaces={"interval": 0.2, "timeout": 2}, env=ros2.env())
    running = start_running(agent, watch, mosquitto)
    good = seen.wait("reported", lambda r: bool(r.topics) and r.error is None)
    for mode, reason in [
        ("fail", "`ros2 topic list -t` exited with code 1: !rclpy.ok(): the stand-in was told"),
        ("garbage", "`ros2 topic list -t` printed 'Traceback? \\x1b[31mnot a list\\x1b[0m'"),
        ("hang", "`ros2 topic list -t` did not finish in 2 s"),
    ]:
        ros2.set({**GRAPH, "mode": {"topic": mode}})
        report = seen.wait(mode, lambda r, reason=reason: (r.error or "").startswith(reason))
        # The last good lists stay, with the reason beside them and the time they were read.
        assert names(report) == names(good) and report.at == good.at
        watch.wait_for(
            ROBOT, lambda s, why=reason: (s.interfaces_error or "").startswith(why), mode
        )
    hung = ros2.runs("hang")[0][0]
    assert not is_alive(hung), "the hanging source's process group was not killed"
    ros2.set(GRAPH)
    seen.wait("recovered", lambda r: r.error is None)
    status = watch.wait_for(ROBOT, lambda s: s.interfaces_error is None, "the error cleared")
    assert status.state is AgentState.RUNNING and status.pid == running.pid
    assert status.restarts == 0 and agent.proc is not None and agent.proc.poll() is None


def test_the_agent_serves_its_brain_while_the_source_hangs(
    make_agent: AgentFactory,
    watch: FleetWatch,
    mosquitto: Mosquitto,
    seen: InterfacesWatch,
    ros2: Ros2,
) -> None:
    ros2.set({**GRAPH, "mode": "hang"})
    agent = make_agent(interfaces={"interval": 0.2, "timeout": 120}, env=ros2.env()).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    hung = wait_for(lambda: ros2.runs("hang"), "ros2 hanging")[0][0]
    request = make_request()
    publish(mosquitto.url, TOPICS.launch(ROBOT), request.payload())
    status = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(status.pid)
    assert is_alive(hung), "the request waited for the hanging source"
    assert seen.reports() == []
    agent.signal(signal.SIGTERM)
    assert agent.wait() == 0
    wait_for(lambda: not is_alive(hung), "the hanging source gone with its agent")


def test_no_ros2_on_the_path_is_an_error_and_no_interface_is_claimed(
    make_agent: AgentFactory, watch: FleetWatch, seen: InterfacesWatch, tmp_path: Path
) -> None:
    empty = tmp_path / "empty-bin"
    empty.mkdir()
    agent = make_agent(interfaces={"interval": 0.3}, env={"PATH": str(empty)}).start()
    report = seen.wait("an error", lambda r: r.error is not None)
    assert report.error is not None and report.error.startswith("no `ros2` on the brain's PATH")
    assert report.topics == [] and report.at is None and report.verdict == "error"
    status = watch.wait_for(ROBOT, lambda s: s.interfaces_error == report.error, "the error")
    assert status.state is AgentState.IDLE and agent.proc is not None and agent.proc.poll() is None


def test_more_interfaces_than_the_bound_are_cut_and_counted(
    make_agent: AgentFactory, watch: FleetWatch, seen: InterfacesWatch, ros2: Ros2
) -> None:
    topics = [
        {"name": f"/robot/t{i:05d}", "type": "std_msgs/msg/Empty"}
        for i in range(MAX_INTERFACES + 50)
    ]
    ros2.set({"topics": topics, "services": GRAPH["services"] * 3, "actions": []})
    make_agent(interfaces={"interval": 5}, env=ros2.env()).start()
    report = seen.wait("reported", lambda r: bool(r.topics))
    assert len(report.topics) == MAX_INTERFACES and report.topics[0].name == "/robot/t00000"
    assert report.services == [] and report.truncated == 50 + 1  # a duplicate is no entry


def test_a_broker_that_lost_its_retained_messages_gets_the_report_again(
    make_agent: AgentFactory, watch: FleetWatch, mosquitto: Mosquitto, ros2: Ros2
) -> None:
    """Published at every connection: an hour-long interval, so no reading causes it."""
    agent = make_agent(interfaces={"interval": 3600}, env=ros2.env()).start()
    first = RobotInterfaces.model_validate_json(
        read_retained(mosquitto.url, TOPICS.interfaces(ROBOT))
    )
    idle = watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    mosquitto.kill()
    mosquitto.start()  # same port, retained messages gone (no persistence)
    watch.wait_for(ROBOT, lambda s: s.seq > idle.seq, "a new connection", agent=agent)
    again = RobotInterfaces.model_validate_json(
        read_retained(mosquitto.url, TOPICS.interfaces(ROBOT))
    )
    assert again == first and ros2.readings() == 1


def test_the_interfaces_are_read_in_the_request_s_ros_domain(
    make_agent: AgentFactory,
    watch: FleetWatch,
    mosquitto: Mosquitto,
    seen: InterfacesWatch,
    ros2: Ros2,
) -> None:
    """The source looks where the brain runs: the request's `ros_domain_id`, unless
    agent.yaml's env overrides it; before any request, the agent's own environment."""
    env = ros2.env()
    del env["ROS_DOMAIN_ID"]
    agent = make_agent(interfaces={"interval": 0.2}, env=env).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    request = with_digest(make_request().model_copy(update={"ros_domain_id": 5}))
    publish(mosquitto.url, TOPICS.launch(ROBOT), request.payload())
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    seen.wait("the request's domain", lambda r: ("/domain_5", "std_msgs/msg/Empty") in names(r))
