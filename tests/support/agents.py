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
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
import yaml
from pydantic import ValidationError

from agent.process import is_alive, read_pidfile
from configurator.launch import LaunchCapability, LaunchRequest, LaunchScenario, make_launch_request
from configurator.mqtt import Connection, make_client
from configurator.safejson import PayloadError, parse_object
from configurator.types import MappingBinding
from configurator.wire import AgentState, AgentStatus, RobotDescription, Topics

TIMEOUT = 20.0
ROBOTCONF = Path(sys.executable).parent / "robotconf"
STANDIN = [sys.executable, "-m", "agent.standin_brain"]


def agent_argv() -> list[str]:
    if ROBOTCONF.exists():
        return [str(ROBOTCONF), "agent"]
    return [sys.executable, "-m", "agent.cli"]


def wait_until(predicate: Callable[[], bool], what: str, timeout: float = TIMEOUT) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.05)


def make_request(
    robot_id: str = "tb3-01",
    variant: int = 0,
    revision: str = "rev-1",
    platform: str = "ROS2",
    template: str | None = "turtlebot3-camera",
) -> LaunchRequest:
    """A valid request; a different `variant` gives a different digest, `revision` does not."""
    capability = LaunchCapability(
        name="follow-camera",
        platform=platform,
        robot_template=template,
        mapping_scheme="gazebo",
        tasks=["Delivery"],
        actions=["Follow"],
        logics={"Follow": "follow_with_poses"},
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
        environment_knowledge={},
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
        wait_until(lambda: bool(got), f"a retained message on {topic}")
    finally:
        client.disconnect()
        client.loop_stop()
    return got[0]


class Observer:
    """Follows robots' status and description topics as `robotconf status` would."""

    def __init__(self, broker: Broker, prefix: str = "robotconf") -> None:
        self.topics = Topics(prefix)
        self._cond = threading.Condition()
        self.statuses: dict[str, list[AgentStatus]] = {}
        self.descriptions: dict[str, RobotDescription] = {}
        self.client = _client("test-observer", broker)
        self.client.on_connect = self._on_connect
        self.client.on_message = self._on_message
        address = _connection(broker).address
        self.client.connect_async(address.host, address.port, keepalive=10)
        self.client.loop_start()

    def _on_connect(self, c: paho.Client, u: Any, f: Any, rc: Any, p: Any) -> None:
        c.subscribe([(self.topics.all_status, 1), (self.topics.all_description, 1)])

    def _on_message(self, c: paho.Client, u: Any, msg: paho.MQTTMessage) -> None:
        found = self.topics.robot_of(msg.topic)
        if found is None or not msg.payload:
            return
        robot, leaf = found
        try:  # tests publish garbage on these topics too: only agents' messages are recorded
            with self._cond:
                if leaf == "status":
                    status = AgentStatus.model_validate(parse_object(msg.payload))
                    self.statuses.setdefault(robot, []).append(status)
                elif leaf == "description":
                    description = RobotDescription.model_validate(parse_object(msg.payload))
                    self.descriptions[robot] = description
                self._cond.notify_all()
        except (PayloadError, ValidationError):
            return

    def history(self, robot: str) -> list[AgentStatus]:
        with self._cond:
            return list(self.statuses.get(robot, []))

    def latest(self, robot: str) -> AgentStatus | None:
        seen = self.history(robot)
        return seen[-1] if seen else None

    def wait_for(
        self,
        robot: str,
        predicate: Callable[[AgentStatus], bool],
        what: str,
        timeout: float = TIMEOUT,
        agent: AgentProc | None = None,
    ) -> AgentStatus:
        """The latest status once it satisfies `predicate`."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                seen = self.statuses.get(robot, [])
                if seen and predicate(seen[-1]):
                    return seen[-1]
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                self._cond.wait(min(remaining, 0.5))
        trail = "\n".join(
            f"  {s.state.value} pid={s.pid} seq={s.seq} {s.message}" for s in seen[-10:]
        )
        log = f"\nagent log:\n{agent.log_tail()}" if agent is not None else ""
        raise AssertionError(f"timed out waiting for {robot}: {what}; statuses:\n{trail}{log}")

    def wait_seen(
        self,
        robot: str,
        predicate: Callable[[AgentStatus], bool],
        what: str,
        since: int = 0,
        timeout: float = TIMEOUT,
    ) -> AgentStatus:
        """A status from `since` (a history index) on that satisfies `predicate`, even if a
        newer one has replaced it already."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for status in self.statuses.get(robot, [])[since:]:
                    if predicate(status):
                        return status
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise AssertionError(f"timed out waiting for {robot}: {what}")
                self._cond.wait(min(remaining, 0.5))

    def wait_state(
        self, robot: str, state: AgentState, agent: AgentProc | None = None, **fields: Any
    ) -> AgentStatus:
        def matches(status: AgentStatus) -> bool:
            return status.state == state and all(
                getattr(status, key) == value for key, value in fields.items()
            )

        described = ", ".join(f"{k}={v}" for k, v in fields.items())
        return self.wait_for(robot, matches, f"state {state.value} {described}", agent=agent)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


class AgentProc:
    """One `robotconf agent --config agent.yaml` process with its own work directory."""

    def __init__(
        self,
        root: Path,
        broker_url: str,
        robot_id: str = "tb3-01",
        command: list[str] | None = None,
        **settings: Any,
    ) -> None:
        self.root = root
        self.robot_id = robot_id
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
                [*agent_argv(), *configs, "--log-level", "debug"],
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
        return b"agent.standin_brain" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False
