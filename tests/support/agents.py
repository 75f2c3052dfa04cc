"""Test harness for the agent: real `robotconf agent` processes, an MQTT observer, requests.

Tests wait for conditions with generous deadlines; nothing here asserts on timing.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import uuid
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
import yaml

from robotconf.agent.process import is_alive, read_pidfile
from robotconf.configurator.types import MappingBinding
from robotconf.contract.launch import (
    LaunchCapability,
    LaunchRequest,
    LaunchScenario,
    make_launch_request,
)
from robotconf.contract.mqtt import Connection, make_client
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

# Fails at its first start, runs at every later one: `failed` until someone restarts it.
FAILS_ONCE = [
    sys.executable,
    "-c",
    "import os, sys, time\n"
    "first = not os.path.exists('ran-once')\n"
    "open('ran-once', 'a').close()\n"
    "print('brain up', os.getpid(), flush=True)\n"
    "sys.exit(3) if first else time.sleep(600)\n",
    "{launch_request}",
]

TIMEOUT = 20.0
ROBOTCONF = Path(sys.executable).parent / "robotconf"
STANDIN = [sys.executable, "-m", "robotconf.agent.standin_brain"]


def agent_argv() -> list[str]:
    if ROBOTCONF.exists():
        return [str(ROBOTCONF), "agent"]
    return [sys.executable, "-m", "robotconf.agent.cli"]


def make_request(
    robot_id: str = "tb3-01",
    variant: int = 0,
    revision: str = "rev-1",
    platform: str = "ROS2",
    template: str | None = "turtlebot3-camera",
    logic: str | list[str] = "follow_with_poses",
    knowledge: dict[str, Any] | None = None,
) -> LaunchRequest:
    """A valid request; a different `variant` gives a different digest, `revision` does not.

    `variant` (a setting) and `knowledge` change the digest but not the restart digest (a
    reload may apply them); another `logic` (or platform, template) changes the capability,
    and so the restart digest."""
    capability = LaunchCapability(
        name="follow-camera",
        platform=platform,
        robot_template=template,
        mapping_scheme="gazebo",
        tasks=["Delivery"],
        actions=["Follow"],
        logics={"Follow": logic},
        mappings={
            "cmd_vel": MappingBinding(kind="topic", name="/cmd_vel", type="geometry_msgs/msg/Twist")
        },
    )
    scenario = LaunchScenario(
        name="delivery-gazebo",
        capability=capability,
        environment_name="GazeboDemo1",
        environment_type="Gazebo",
        robot_settings={"max_linear_speed": 0.1 + variant / 100},
        logic_settings={},
        environment_knowledge=knowledge or {},
        goals=[],
    )
    return make_launch_request(robot_id, "Delivery bot", revision, scenario)


Broker = str | Connection  # a plain URL, or a URL with credentials and TLS files


def _connection(broker: Broker) -> Connection:
    return broker if isinstance(broker, Connection) else Connection(url=broker)


def _client(prefix: str, broker: Broker) -> paho.Client:
    client = make_client(_connection(broker), client_id=f"{prefix}-{uuid.uuid4().hex[:10]}")
    client.reconnect_delay_set(min_delay=1, max_delay=2)
    return client


def publish(broker: Broker, topic: str, payload: bytes, retain: bool = True) -> None:
    """Publish at QoS 1 and wait for the broker's acknowledgement."""
    address = _connection(broker).address
    client = _client("test-pub", broker)
    client.connect(address.host, address.port)
    client.loop_start()
    try:
        info = client.publish(topic, payload, qos=1, retain=retain)
        info.wait_for_publish(TIMEOUT)
        assert info.is_published(), f"publishing to {topic} was not acknowledged"
    finally:
        client.disconnect()
        client.loop_stop()


def publish_many(broker: Broker, messages: dict[str, bytes]) -> None:
    """Publish each (topic, payload) retained at QoS 1 on one connection, as a fleet of agents
    would, and wait for every acknowledgement."""
    address = _connection(broker).address
    client = _client("test-pub-many", broker)
    client.connect(address.host, address.port)
    client.loop_start()
    try:
        sent = [client.publish(t, payload, qos=1, retain=True) for t, payload in messages.items()]
        for info in sent:
            info.wait_for_publish(TIMEOUT * 3)
            assert info.is_published(), "a publish was not acknowledged"
    finally:
        client.disconnect()
        client.loop_stop()


def read_retained(broker: Broker, topic: str) -> bytes:
    """What a newcomer sees on `topic` right now (the topic must hold a retained message)."""
    address = _connection(broker).address
    got: list[bytes] = []
    client = _client("test-read", broker)

    def on_connect(c: paho.Client, u: Any, f: Any, rc: Any, p: Any) -> None:
        c.subscribe(topic, qos=1)

    def on_message(c: paho.Client, u: Any, msg: paho.MQTTMessage) -> None:
        got.append(bytes(msg.payload))

    client.on_connect = on_connect
    client.on_message = on_message
    client.connect(address.host, address.port)
    client.loop_start()
    try:
        wait_for(lambda: bool(got), f"a retained message on {topic}")
    finally:
        client.disconnect()
        client.loop_stop()
    return got[0]


class AgentProc:
    """One `robotconf agent --config agent.yaml` process with its own work directory."""

    def __init__(
        self,
        root: Path,
        broker_url: str,
        robot_id: str = "tb3-01",
        command: list[str] | None = None,
        *,
        program: list[str] | None = None,
        **settings: Any,
    ) -> None:
        self.root = root
        self.program = program or agent_argv()  # another install's agent, e.g. a robot-only one
        self.robot_id = robot_id
        self.says_ready = command is None  # the stand-in brain says ready through the library
        self.workdir = root / "work"
        self.config_path = root / "agent.yaml"
        self.stderr_path = root / "agent.stderr"
        config: dict[str, Any] = {
            "broker": broker_url,
            "description": {
                "id": robot_id,
                "name": "Delivery bot",
                "recommended_template": "turtlebot3-camera",
                "platform": "ROS2",
            },
            "command": command or [*STANDIN, "{launch_request}"],
            "workdir": str(self.workdir),
            "stop_timeout": 3,
            "startsecs": 0.3,
            "keepalive": 5,
            "restart": {
                "policy": "on-failure",
                "max_restarts": 3,
                "backoff_initial": 0.1,
                "backoff_max": 0.4,
            },
        }
        config.update(settings)
        root.mkdir(parents=True, exist_ok=True)
        self.config_path.write_text(yaml.safe_dump(config, sort_keys=False), encoding="utf-8")
        self.proc: subprocess.Popen[bytes] | None = None
        self.brain_pids: set[int] = set()

    def start(self, *hosted: AgentProc) -> AgentProc:
        """Starts the agent process; with `hosted`, their robots' agents run in it too (one
        `--config` each), and their own `proc` stays None."""
        configs = [arg for a in (self, *hosted) for arg in ("--config", str(a.config_path))]
        with self.stderr_path.open("ab") as err:
            self.proc = subprocess.Popen(
                [*self.program, *configs, "--log-level", "debug"],
                stdin=subprocess.DEVNULL,
                stdout=err,
                stderr=err,
                start_new_session=True,
            )
        return self

    @property
    def pid(self) -> int:
        assert self.proc is not None
        return self.proc.pid

    def signal(self, sig: signal.Signals) -> None:
        assert self.proc is not None
        self.proc.send_signal(sig)

    def wait(self, timeout: float = TIMEOUT) -> int:
        assert self.proc is not None
        return self.proc.wait(timeout)

    def log_tail(self, lines: int = 30) -> str:
        try:
            text = self.stderr_path.read_text(encoding="utf-8", errors="replace")
        except OSError:
            return ""
        return "\n".join(text.splitlines()[-lines:])

    def brain_log(self) -> str:
        return (self.workdir / "brain.log").read_text(encoding="utf-8", errors="replace")

    def request_on_disk(self) -> dict[str, Any]:
        data: dict[str, Any] = json.loads((self.workdir / "launch-request.json").read_bytes())
        return data

    def note_brain(self, pid: int | None) -> None:
        if pid is not None:
            self.brain_pids.add(pid)

    def cleanup(self) -> None:
        """Whatever a failed test left behind: the agent, its brains, orphans included."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        record = read_pidfile(self.workdir / "brain.pid")
        pids = {pid for pid in self.brain_pids if is_alive(pid) and _is_standin(pid)}
        if record is not None and record.is_running():
            pids.add(record.pid)  # its start time proves it is the brain, whatever it runs
        for pid in pids:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(pid, signal.SIGKILL)


def _is_standin(pid: int) -> bool:
    """Only ever kill our own stand-in brains, never a process that reused a pid."""
    try:
        return b"robotconf.agent.standin_brain" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False


ROBOT = "tb3-01"  # the robot of the agent tests


def start_running(
    agent: AgentProc, watch: FleetWatch, broker: Mosquitto, variant: int = 0
) -> AgentStatus:
    """Start the agent, give it a request, return its `running` status."""
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    request = make_request(variant=variant)
    publish(broker.url, Topics().launch(ROBOT), request.payload())
    status = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    if agent.says_ready:
        # A loaded machine may count the brain running at startsecs, before its hello: it is
        # then `starting` again until it says ready. Tests compare what follows with this.
        status = watch.wait_for(
            ROBOT,
            lambda s: s.state is AgentState.RUNNING and (s.message or "").endswith(", ready)"),
            "running from the brain's ready",
            agent=agent,
        )
    agent.note_brain(status.pid)
    assert status.pid is not None and is_alive(status.pid)
    # `running` says the brain stayed up startsecs, not that it is done starting: wait until
    # it has printed its modules (and so handles SIGTERM) before tests stop it.
    wait_for(lambda: "platform module: ROS2" in agent.brain_log(), "the brain's output")
    return status
