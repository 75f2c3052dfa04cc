"""CPU an agent spends reporting 2,000 interfaces every 5 s (issue 21: under 1 % of one core).

Starts a private Mosquitto, one `robotconf agent` with the stand-in brain running and
`interfaces: {interval: 5}`, the default source being the stand-in `ros2` (agent/standin_ros2.py)
on the brain's PATH, printing 2,000 interfaces in ros2cli's `list -t` format (1,400 topics,
400 services, 200 actions). `--changing` (the default) rewrites one topic's type before every
reading, so that each reading is parsed, bounded, serialised and published; `--steady` leaves
the graph alone (each reading parsed and compared, nothing published). Measures the agent
process's own CPU time (utime + stime of /proc/<pid>/stat; its children's, the three `ros2`
runs per reading, are shown apart) over --seconds. Exit 0 when under the target, 1 when not,
2 when the run itself failed.

    python bench/interfaces_cpu.py [--seconds 60] [--steady] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import paho.mqtt.client as paho  # noqa: E402
import yaml  # noqa: E402
from paho.mqtt.enums import CallbackAPIVersion  # noqa: E402

from robotconf.agent.standin_ros2 import GRAPH_ENV, LOG_ENV, install  # noqa: E402
from robotconf.contract.wire import Topics  # noqa: E402
from tests.support.agents import agent_argv, make_request  # noqa: E402
from tests.support.mosquitto import Mosquitto  # noqa: E402

CPU_TARGET_PERCENT = 1.0
ROBOT = "bench-01"
INTERVAL = 5.0
SHAPE = {"topics": 1400, "services": 400, "actions": 200}
TYPE_OF = {"topics": "sensor_msgs/msg/Range", "services": "std_srvs/srv/Trigger"}
TICKS = os.sysconf("SC_CLK_TCK")


@dataclass
class Result:
    seconds: float
    interfaces: int
    changing: bool
    readings: int
    published: int
    agent_cpu_seconds: float
    agent_cpu_percent: float
    children_cpu_seconds: float
    payload_bytes: int


def graph(variant: int) -> dict[str, list[dict[str, str]]]:
    """2,000 interfaces of a robot with many namespaced sensors; `variant` changes one type."""
    out: dict[str, list[dict[str, str]]] = {}
    for kind, count in SHAPE.items():
        kind_type = TYPE_OF.get(kind, "nav2_msgs/action/NavigateToPose")
        out[kind] = [
            {"name": f"/robot/sensor_{i // 20:03d}/{kind[:-1]}_{i:04d}", "type": kind_type}
            for i in range(count)
        ]
    out["topics"][0]["type"] = f"bench_msgs/msg/Variant{variant}"
    return out


def ticks(pid: int) -> tuple[int, int]:
    """(own utime + stime, waited-for children's cutime + cstime) of a process, in ticks."""
    raw = Path(f"/proc/{pid}/stat").read_bytes()
    fields = raw[raw.rindex(b")") + 2 :].split()
    return int(fields[11]) + int(fields[12]), int(fields[13]) + int(fields[14])


class Watch:
    """Counts the interfaces messages and waits for the brain to run."""

    def __init__(self, broker: Mosquitto) -> None:
        self.topics = Topics()
        self.messages: list[int] = []  # payload sizes
        self.running = threading.Event()
        self.client = paho.Client(CallbackAPIVersion.VERSION2, client_id="bench-interfaces")
        self.client.on_connect = lambda c, *a: c.subscribe(
            [(self.topics.interfaces(ROBOT), 1), (self.topics.status(ROBOT), 1)]
        )
        self.client.on_message = self._on_message
        self.client.connect(broker.host, broker.port)
        self.client.loop_start()

    def _on_message(self, client: paho.Client, userdata: object, msg: paho.MQTTMessage) -> None:
        if msg.topic.endswith("/interfaces"):
            self.messages.append(len(msg.payload))
        elif b'"running"' in msg.payload:
            self.running.set()

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def _readings(calls: Path) -> int:
    try:
        return calls.read_text(encoding="utf-8").count(" action ")
    except FileNotFoundError:
        return 0


def _wait(probe: Callable[[], object], what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not probe():
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out waiting for {what}")
        time.sleep(0.05)


def _start_agent(
    broker: Mosquitto, work: Path, graph_file: Path, calls: Path
) -> subprocess.Popen[bytes]:
    shim = install(work / "rosbin")
    env = {
        "PATH": f"{shim.parent}:{os.environ.get('PATH', '/usr/bin:/bin')}",
        GRAPH_ENV: str(graph_file),
        LOG_ENV: str(calls),
    }
    config = {
        "broker": broker.url,
        "description": {"id": ROBOT, "recommended_template": "turtlebot3-camera"},
        "command": [sys.executable, "-m", "robotconf.agent.standin_brain", "{launch_request}"],
        "workdir": str(work / "agent"),
        "interfaces": {"interval": INTERVAL},
        "env": env,
    }
    config_path = work / "agent.yaml"
    config_path.write_text(yaml.safe_dump(config), encoding="utf-8")
    with (work / "agent.stderr").open("wb") as log:
        return subprocess.Popen(
            [*agent_argv(), "--config", str(config_path)], stdout=log, stderr=log
        )


def _write(path: Path, data: object) -> None:
    staged = path.with_suffix(".next")
    staged.write_text(json.dumps(data), encoding="utf-8")
    os.replace(staged, path)


def measure(seconds: float, changing: bool, work: Path) -> Result:
    broker = Mosquitto(work / "broker")
    broker.start()
    graph_file, calls = work / "graph.json", work / "ros2-calls.log"
    _write(graph_file, graph(0))
    agent: subprocess.Popen[bytes] | None = None
    watch: Watch | None = None
    try:
        agent = _start_agent(broker, work, graph_file, calls)
        watch = Watch(broker)
        watch.client.publish(Topics().launch(ROBOT), make_request(ROBOT).payload(), 1, True)
        if not watch.running.wait(60):
            raise RuntimeError("the agent's brain did not reach running")
        _wait(lambda: watch is not None and watch.messages, "the first interfaces message")
        start_own, start_children = ticks(agent.pid)
        start, start_readings, start_published = (
            time.monotonic(),
            _readings(calls),
            len(watch.messages),
        )
        variant = 0
        while (elapsed := time.monotonic() - start) < seconds:
            if changing:  # one changed type per reading, written between readings
                before = _readings(calls)
                _wait(lambda n=before: _readings(calls) > n, "a reading", INTERVAL * 4)
                variant += 1
                _write(graph_file, graph(variant))
            else:
                time.sleep(min(1.0, seconds - elapsed))
        wall = time.monotonic() - start
        own, children = ticks(agent.pid)
        used = (own - start_own) / TICKS
        return Result(
            seconds=round(wall, 1),
            interfaces=sum(SHAPE.values()),
            changing=changing,
            readings=_readings(calls) - start_readings,
            published=len(watch.messages) - start_published,
            agent_cpu_seconds=round(used, 3),
            agent_cpu_percent=round(100 * used / wall, 3),
            children_cpu_seconds=round((children - start_children) / TICKS, 3),
            payload_bytes=watch.messages[-1],
        )
    finally:
        if watch is not None:
            watch.close()
        if agent is not None and agent.poll() is None:
            agent.send_signal(signal.SIGTERM)
            try:
                agent.wait(15)
            except subprocess.TimeoutExpired:
                agent.kill()
                agent.wait()
        broker.kill()


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="measuring window (60)")
    parser.add_argument(
        "--steady", action="store_true", help="the graph never changes (default: every reading)"
    )
    parser.add_argument("--json", type=Path, help="also write the figures here as JSON")
    args = parser.parse_args(argv)
    try:
        with tempfile.TemporaryDirectory(prefix="interfaces-cpu-") as tmp:
            result = measure(args.seconds, not args.steady, Path(tmp))
    except (RuntimeError, OSError) as exc:
        print(f"interfaces_cpu: the run failed: {exc}", file=sys.stderr)
        return 2
    ok = result.agent_cpu_percent < CPU_TARGET_PERCENT
    what = "changing at every reading" if result.changing else "steady"
    print(
        f"agent reporting {result.interfaces:,} interfaces every {INTERVAL:g} s ({what}), "
        f"{result.seconds:g} s: {result.readings} readings, {result.published} published "
        f"({result.payload_bytes:,} bytes each)"
    )
    print(
        f"  agent CPU {result.agent_cpu_seconds} s = {result.agent_cpu_percent} % of one core"
        f"  target < {CPU_TARGET_PERCENT:g} %: {'ok' if ok else 'MISSED'}"
    )
    print(
        f"  (the stand-in ros2 runs themselves: {result.children_cpu_seconds} s, not the agent's)"
    )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(asdict(result), indent=2) + "\n", encoding="utf-8")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
