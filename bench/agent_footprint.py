"""Footprint of an idle robot agent: resident memory and CPU while its brain runs.

Starts a private Mosquitto, one `robotconf agent` with the stand-in brain, publishes a Launch
Request, waits for `running`, then samples the agent process (not the brain) for --seconds:
resident memory from /proc/<pid>/status (VmRSS, and VmHWM for the peak) and CPU time from
/proc/<pid>/stat (utime + stime). Targets: RSS <= 40 MB and CPU <= 1 % of one core.
Exit 0 when both targets are met, 1 when one is missed, 2 when the run itself failed.

    python bench/agent_footprint.py [--seconds 60] [--interval 1] [--json FILE]
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
from dataclasses import asdict, dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import paho.mqtt.client as paho  # noqa: E402
import yaml  # noqa: E402
from paho.mqtt.enums import CallbackAPIVersion  # noqa: E402

from robotconf.contract.wire import AgentState, AgentStatus, Topics  # noqa: E402
from tests.support.agents import make_request  # noqa: E402
from tests.support.mosquitto import Mosquitto  # noqa: E402

RSS_TARGET_MB = 40.0
CPU_TARGET_PERCENT = 1.0
ROBOT = "bench-01"
TICKS = os.sysconf("SC_CLK_TCK")


@dataclass
class Footprint:
    seconds: float
    samples: int
    rss_start_mb: float
    rss_mean_mb: float
    rss_max_mb: float
    rss_end_mb: float
    hwm_mb: float
    cpu_seconds: float
    cpu_percent: float
    brain_rss_mb: float
    brain_kept_pid: bool


def status_kb(pid: int, field: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text(encoding="ascii").splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise RuntimeError(f"no {field} for pid {pid}")


def cpu_ticks(pid: int) -> int:
    raw = Path(f"/proc/{pid}/stat").read_bytes()
    fields = raw[raw.rindex(b")") + 2 :].split()
    return int(fields[11]) + int(fields[12])  # utime, stime (fields 14 and 15)


class StatusWatch:
    def __init__(self, broker: Mosquitto) -> None:
        self.latest: AgentStatus | None = None
        self.changed = threading.Condition()
        self.topics = Topics()
        self.client = paho.Client(CallbackAPIVersion.VERSION2, client_id="bench-watch")
        self.client.on_connect = lambda c, *a: c.subscribe(self.topics.status(ROBOT), qos=1)
        self.client.on_message = self._on_message
        self.client.connect(broker.host, broker.port)
        self.client.loop_start()

    def _on_message(self, client: paho.Client, userdata: object, msg: paho.MQTTMessage) -> None:
        with self.changed:
            self.latest = AgentStatus.model_validate_json(msg.payload)
            self.changed.notify_all()

    def wait_running(self, timeout: float) -> AgentStatus:
        deadline = time.monotonic() + timeout
        with self.changed:
            while self.latest is None or self.latest.state != AgentState.RUNNING:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise RuntimeError(f"the agent did not reach running: {self.latest}")
                self.changed.wait(left)
            return self.latest

    def publish(self, topic: str, payload: bytes) -> None:
        self.client.publish(topic, payload, qos=1, retain=True).wait_for_publish(10)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def measure(seconds: float, interval: float, work: Path) -> Footprint:
    broker = Mosquitto(work / "broker")
    broker.start()
    agent: subprocess.Popen[bytes] | None = None
    watch: StatusWatch | None = None
    try:
        config = {
            "broker": broker.url,
            "description": {"id": ROBOT, "recommended_template": "turtlebot3-camera"},
            "command": [sys.executable, "-m", "robotconf.agent.standin_brain", "{launch_request}"],
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
        watch.publish(Topics().launch(ROBOT), make_request(ROBOT).payload())
        running = watch.wait_running(30)
        assert running.pid is not None
        brain_pid = running.pid

        rss: list[int] = []
        start_ticks = cpu_ticks(agent.pid)
        start = time.monotonic()
        while True:
            rss.append(status_kb(agent.pid, "VmRSS"))
            elapsed = time.monotonic() - start
            if elapsed >= seconds:
                break
            time.sleep(min(interval, seconds - elapsed))
        wall = time.monotonic() - start
        used = (cpu_ticks(agent.pid) - start_ticks) / TICKS
        hwm = status_kb(agent.pid, "VmHWM")
        brain_rss = status_kb(brain_pid, "VmRSS")
        kept = watch.latest is not None and watch.latest.pid == brain_pid
        return Footprint(
            seconds=round(wall, 1),
            samples=len(rss),
            rss_start_mb=round(rss[0] / 1024, 1),
            rss_mean_mb=round(sum(rss) / len(rss) / 1024, 1),
            rss_max_mb=round(max(rss) / 1024, 1),
            rss_end_mb=round(rss[-1] / 1024, 1),
            hwm_mb=round(hwm / 1024, 1),
            cpu_seconds=round(used, 3),
            cpu_percent=round(100 * used / wall, 3),
            brain_rss_mb=round(brain_rss / 1024, 1),
            brain_kept_pid=kept,
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
    parser.add_argument("--seconds", type=float, default=60.0, help="sampling window (60)")
    parser.add_argument("--interval", type=float, default=1.0, help="seconds between RSS samples")
    parser.add_argument("--json", type=Path, help="also write the figures here as JSON")
    args = parser.parse_args(argv)
    try:
        with tempfile.TemporaryDirectory(prefix="agent-footprint-") as tmp:
            result = measure(args.seconds, args.interval, Path(tmp))
    except (RuntimeError, OSError, AssertionError) as exc:
        print(f"agent_footprint: the run failed: {exc}", file=sys.stderr)
        return 2
    rss_ok = result.rss_max_mb <= RSS_TARGET_MB
    cpu_ok = result.cpu_percent <= CPU_TARGET_PERCENT
    print(f"idle agent with a running brain, {result.seconds:g} s, {result.samples} samples")
    print(
        f"  RSS  start {result.rss_start_mb} MB  mean {result.rss_mean_mb} MB  "
        f"max {result.rss_max_mb} MB  end {result.rss_end_mb} MB  (peak VmHWM {result.hwm_mb} MB)"
        f"  target <= {RSS_TARGET_MB:g} MB: {'ok' if rss_ok else 'MISSED'}"
    )
    print(
        f"  CPU  {result.cpu_seconds} s over the window = {result.cpu_percent} % of one core"
        f"  target <= {CPU_TARGET_PERCENT:g} %: {'ok' if cpu_ok else 'MISSED'}"
    )
    print(
        f"  (the stand-in brain itself: {result.brain_rss_mb} MB; same pid throughout: "
        f"{result.brain_kept_pid})"
    )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(asdict(result), indent=2) + "\n", encoding="utf-8")
    return 0 if rss_ok and cpu_ok else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
