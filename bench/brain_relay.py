"""What relaying a busy brain's reports costs its agent: CPU while the brain sends 10 progress
updates a second.

Starts a private Mosquitto and one `robotconf agent` whose brain (a small program written here,
speaking the JSON-lines wire without the library) says hello and ready, then runs goals of 10 s
each, sending 10 progress updates a second, one end per goal and its vitals once a second.
Samples the agent process (not the brain) for --seconds: CPU time from /proc/<pid>/stat. The
same run with a brain that says hello and ready and then nothing gives the baseline (the idle
agent). The summaries and records that reached the broker are counted too (progress is
coalesced to one summary a second). Target: the busy brain's agent under 1 % of one core.
Exit 0 when met, 1 when missed, 2 when the run itself failed.

    python bench/brain_relay.py [--seconds 60] [--rate 10] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import paho.mqtt.client as paho  # noqa: E402
import yaml  # noqa: E402
from paho.mqtt.enums import CallbackAPIVersion  # noqa: E402

from bench.agent_footprint import TICKS, StatusWatch, cpu_ticks  # noqa: E402
from robotconf.contract.wire import Topics  # noqa: E402
from tests.support.agents import make_request  # noqa: E402
from tests.support.mosquitto import Mosquitto  # noqa: E402

CPU_TARGET_PERCENT = 1.0
ROBOT = "bench-01"

BRAIN = r"""
import json, os, socket, sys, time
rate = float(sys.argv[1])
sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
sock.connect(os.environ["ROBOTCONF_BRAIN_SOCKET"])
def send(**fields):
    sock.sendall(json.dumps(fields).encode() + b"\n")
send(type="hello", digest=os.environ["ROBOTCONF_DIGEST"], library="bench/1")
send(type="ready")
if rate <= 0:
    while True:
        time.sleep(3600)
n = 0
next_at = time.monotonic()
while True:
    n += 1
    gid = f"g{n}"
    send(type="goal", id=gid, task="Delivery", state="started")
    steps = int(10 * rate)
    for i in range(steps):
        next_at += 1 / rate
        time.sleep(max(0.0, next_at - time.monotonic()))
        send(type="goal", id=gid, task="Delivery", state="progress", fraction=(i + 1) / steps,
             eta=(steps - i - 1) / rate, note=f"step {i + 1} of {steps}")
        if i % int(rate) == 0:
            send(type="vitals", values={"battery": 1 - n / 1000, "cpu": 0.1, "pose": "1.0,2.0"})
    send(type="goal", id=gid, task="Delivery", state="succeeded")
"""


@dataclass
class Run:
    rate: float
    seconds: float
    cpu_seconds: float
    cpu_percent: float
    summaries: int
    records: int


class GoalsCount:
    def __init__(self, broker: Mosquitto) -> None:
        self.summaries = 0
        self.records = 0
        self.lock = threading.Lock()
        topics = Topics()
        self.client = paho.Client(CallbackAPIVersion.VERSION2, client_id="bench-goals")
        self.client.on_connect = lambda c, *a: c.subscribe(
            [(topics.goals(ROBOT), 1), (topics.goal_outcomes(ROBOT), 1)]
        )
        self.client.on_message = self._on_message
        self.client.connect(broker.host, broker.port)
        self.client.loop_start()

    def _on_message(self, client: paho.Client, userdata: object, msg: paho.MQTTMessage) -> None:
        with self.lock:
            if msg.topic.endswith("/outcomes"):
                self.records += 1
            else:
                self.summaries += 1

    def take(self) -> tuple[int, int]:
        with self.lock:
            counts = (self.summaries, self.records)
            self.summaries = self.records = 0
            return counts

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def measure(seconds: float, rate: float, work: Path) -> Run:
    broker = Mosquitto(work / "broker")
    broker.start()
    agent: subprocess.Popen[bytes] | None = None
    watch: StatusWatch | None = None
    counts: GoalsCount | None = None
    try:
        brain = work / "brain.py"
        brain.write_text(BRAIN, encoding="utf-8")
        config = {
            "broker": broker.url,
            "description": {"id": ROBOT, "recommended_template": "turtlebot3-camera"},
            "command": [sys.executable, str(brain), str(rate)],
            "workdir": str(work / "agent"),
        }
        config_path = work / "agent.yaml"
        config_path.write_text(yaml.safe_dump(config), encoding="utf-8")
        robotconf = Path(sys.executable).parent / "robotconf"
        argv = [str(robotconf), "agent"]
        if not robotconf.exists():
            argv = [sys.executable, "-m", "robotconf.agent.cli"]
        with (work / "agent.stderr").open("wb") as log:
            agent = subprocess.Popen([*argv, "--config", str(config_path)], stdout=log, stderr=log)
        watch = StatusWatch(broker)
        counts = GoalsCount(broker)
        watch.publish(Topics().launch(ROBOT), make_request(ROBOT).payload())
        watch.wait_running(30)  # running from its ready
        time.sleep(2.0)  # past the start: only the steady state is measured
        counts.take()
        start_ticks = cpu_ticks(agent.pid)
        start = time.monotonic()
        time.sleep(seconds)
        wall = time.monotonic() - start
        used = (cpu_ticks(agent.pid) - start_ticks) / TICKS
        summaries, records = counts.take()
        return Run(
            rate=rate,
            seconds=round(wall, 1),
            cpu_seconds=round(used, 3),
            cpu_percent=round(100 * used / wall, 3),
            summaries=summaries,
            records=records,
        )
    finally:
        for closing in (watch, counts):
            if closing is not None:
                closing.close()
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
    parser.add_argument("--seconds", type=float, default=60.0, help="sampling window (60)")
    parser.add_argument("--rate", type=float, default=10.0, help="progress updates a second")
    parser.add_argument("--json", type=Path, help="also write the figures here as JSON")
    args = parser.parse_args(argv)
    runs: list[Run] = []
    try:
        for rate in (0.0, args.rate):
            with tempfile.TemporaryDirectory(prefix="brain-relay-") as tmp:
                runs.append(measure(args.seconds, rate, Path(tmp)))
    except (RuntimeError, OSError, AssertionError) as exc:
        print(f"brain_relay: the run failed: {exc}", file=sys.stderr)
        return 2
    idle, busy = runs
    ok = busy.cpu_percent <= CPU_TARGET_PERCENT
    for run, what in ((idle, "a brain that says ready, then nothing"), (busy, "")):
        label = what or f"{run.rate:g} progress updates a second"
        print(
            f"{label}, {run.seconds:g} s: agent CPU {run.cpu_seconds} s = {run.cpu_percent} % of "
            f"one core; {run.summaries} summaries, {run.records} records published"
        )
    print(
        f"relaying costs {round(busy.cpu_percent - idle.cpu_percent, 3)} % of one core; "
        f"target <= {CPU_TARGET_PERCENT:g} % in all: {'ok' if ok else 'MISSED'}"
    )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps([asdict(r) for r in runs], indent=2) + "\n", "utf-8")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
