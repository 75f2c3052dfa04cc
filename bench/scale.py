"""Scale: what a commit costs on the 10,000-robot repository, end to end (issue 14's targets).

On the repository bench/generate.py writes (a git repository here, watched locally by a real
`robotconf reconcile` process) and a Mosquitto of its own:

  first     from the reconciler's start until a subscriber on every launch topic has seen
            every assigned robot's request (read, validate, render and publish of a cold
            start); `publishing` is the reconciler's own account (its log) of that publish,
            from its first message to the last PUBACK
  floor     the same broker, one paho client publishing as many request-sized retained QoS 1
            messages to as many topics, unlimited in flight as the reconciler publishes: first
            publish until the last PUBACK (median of three, on the idle machine)
  change    a commit that changes one number in one scenario (the robots assigned to it get
            a new request, no other robot does): from right before `git commit` until the
            subscriber has seen every one of those robots' new requests, i.e. the broker took
            them; p50 and max over --rounds; the commit itself is timed too
  read      a whole-fleet reader (`robotconf status`'s view: every robot topic and the
            reconciler's status) right after the first publish: how many retained messages it
            got of the assigned robots' requests and the reconciler's status, in how long, and
            whether it knows of any dropped (the broker runs with the per-client queue
            `robotconf broker-config` sets for the fleet, not Mosquitto's default of 1,000)
  memory    the reconciler's resident memory after the first publish and after the rounds
            (VmRSS), and its peak (VmHWM)

Targets: change p50 <= 0.3 s; publish <= 1.5x the floor; RSS <= 150 MB; the reader gets every
message and knows of no loss. Exit 0 when they are
met, 1 when one is missed.

    python bench/scale.py [--robots 10000] [--rounds 9] [--shape namespaced] [--code DIR]
                          [--keep] [--json F]
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import generate  # noqa: E402
import paho.mqtt.client as paho  # noqa: E402
import yaml  # noqa: E402
from paho.mqtt.enums import CallbackAPIVersion  # noqa: E402
from rollout import Broker, connect, start_reconciler  # noqa: E402

TIMEOUT = float(os.environ.get("SCALE_TIMEOUT", "300"))
CHANGE_TARGET = 0.3
PUBLISH_TARGET = 1.5
RSS_TARGET_MB = 150.0


class Launches:
    """A subscriber on every launch topic: when each topic last got a payload, and which."""

    def __init__(self, port: int, topics: str = "robotconf/robots/+/launch") -> None:
        self._lock = threading.Lock()
        self.seen: dict[str, tuple[float, bytes]] = {}
        self.changed = threading.Event()
        self.client = paho.Client(
            CallbackAPIVersion.VERSION2, client_id=f"scale-{os.getpid()}-{time.monotonic_ns()}"
        )
        subscribed = threading.Event()
        self.client.on_subscribe = lambda *a: subscribed.set()
        self.client.on_message = self._on_message
        self.client.connect("127.0.0.1", port)
        self.client.loop_start()
        self.client.subscribe(topics, qos=1)
        if not subscribed.wait(10):
            raise RuntimeError("cannot subscribe to the launch topics")

    def _on_message(self, c: paho.Client, u: Any, m: paho.MQTTMessage) -> None:
        now = time.perf_counter()
        with self._lock:
            self.seen[m.topic] = (now, bytes(m.payload))
        self.changed.set()

    def snapshot(self) -> dict[str, tuple[float, bytes]]:
        with self._lock:
            return dict(self.seen)

    def wait(self, done: Any, timeout: float) -> dict[str, tuple[float, bytes]]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.changed.clear()
            seen = self.snapshot()
            if done(seen):
                return seen
            self.changed.wait(0.05)
        raise RuntimeError("timed out waiting for the launch topics")

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def floor(port: int, payloads: dict[str, bytes]) -> float:
    """One client publishes every payload retained at QoS 1: first publish to last PUBACK."""
    pub = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"scale-floor-{os.getpid()}")
    pub.max_inflight_messages_set(0)  # as the reconciler publishes
    connect(pub, port)
    try:
        started = time.perf_counter()
        infos = [pub.publish(t, payload, qos=1, retain=True) for t, payload in payloads.items()]
        for info in infos:
            info.wait_for_publish(TIMEOUT)
        acked = time.perf_counter() - started
        for topic in payloads:  # leave the broker as it was
            pub.publish(topic, b"", qos=1, retain=True).wait_for_publish(TIMEOUT)
    finally:
        pub.disconnect()
        pub.loop_stop()
    return acked


def publishing_time(log: Path) -> float:
    """The reconciler's own account of its cold start's publishing: first message to last
    PUBACK, as the floor is timed."""
    found = re.search(r"first message to last PUBACK, ([0-9.]+) s", log.read_text())
    if found is None:
        raise RuntimeError(f"{log}: no publishing time logged")
    return float(found.group(1))


def whole_fleet_read(url: str) -> tuple[float, int, str | None]:
    """`robotconf status`'s view of the broker: seconds until synced, messages, loss known."""
    from robotconf.contract.mqtt import Connection
    from robotconf.workstation.fleet_status import open_view

    view = open_view(Connection(url), "robotconf")
    started = time.perf_counter()
    view.start()
    try:
        if not view.wait_synced(TIMEOUT):
            raise RuntimeError("the whole-fleet reader never synced")
        return time.perf_counter() - started, len(view.snapshot()), view.lost
    finally:
        view.stop()


def memory(pid: int) -> tuple[float, float]:
    """(VmRSS, VmHWM) in MB."""
    text = Path(f"/proc/{pid}/status").read_text()
    rss = int(re.search(r"VmRSS:\s+(\d+)", text).group(1))  # type: ignore[union-attr]
    hwm = int(re.search(r"VmHWM:\s+(\d+)", text).group(1))  # type: ignore[union-attr]
    return rss / 1024, hwm / 1024


def git(root: Path, *args: str) -> None:
    subprocess.run(["git", *args], cwd=root, check=True, stdout=subprocess.DEVNULL)


@dataclass
class Result:
    robots: int
    assigned: int
    first_s: float
    publish_s: float
    floor_s: float
    publish_ratio: float
    delivered_s: float = 0.0  # first to last request seen by the subscriber
    change_s: list[float] = field(default_factory=list)
    change_p50_s: float = 0.0
    change_max_s: float = 0.0
    commit_p50_s: float = 0.0
    affected: list[int] = field(default_factory=list)
    read_s: float = 0.0
    read_messages: int = 0
    read_lost: str | None = None
    rss_first_mb: float = 0.0
    rss_after_mb: float = 0.0
    peak_mb: float = 0.0


def renewed(seen: dict[str, tuple[float, bytes]], old: dict[str, bytes], topics: list[str]) -> bool:
    """Every one of `topics` holds another payload than it held before."""
    return all(topic in seen and seen[topic][1] != old.get(topic) for topic in topics)


def assignments(lab: Path) -> dict[str, list[str]]:
    """scenario -> the robots assigned to it (not suspended)."""
    fleet = yaml.load((lab / "configs/fleet.yaml").read_text(), Loader=yaml.CSafeLoader)
    out: dict[str, list[str]] = {}
    for robot_id, entry in fleet["robots"].items():
        if not entry.get("suspended"):
            out.setdefault(entry["scenario"], []).append(robot_id)
    return out


def measure(robots: int, rounds: int, folder: Path, shape: str, code: Path) -> Result:
    lab = folder / "lab"
    print(f"generating {robots} robots ({shape} shape) ...", flush=True)
    generate.generate(lab, generate.Sizes(robots=robots), use_git=True, shape=shape)
    by_scenario = assignments(lab)
    assigned = sum(len(r) for r in by_scenario.values())
    broker = Broker(folder, robots)
    launches = Launches(broker.port)
    reconciler: subprocess.Popen[bytes] | None = None
    try:
        print("starting the reconciler ...", flush=True)
        started = time.perf_counter()
        reconciler = start_reconciler(lab, broker.url, 3600, folder / "reconciler.log", code)
        seen = launches.wait(lambda s: len(s) >= assigned, TIMEOUT)
        times = sorted(t for t, _ in seen.values())
        first, delivered = times[-1] - started, times[-1] - times[0]
        time.sleep(0.5)  # its log line follows the last PUBACK
        publish = publishing_time(folder / "reconciler.log")
        time.sleep(2.0)
        rss_first, _ = memory(reconciler.pid)
        read = whole_fleet_read(broker.url)
        sample = next(iter(seen.values()))[1]
        payloads = {f"bench/floor/{i}": sample for i in range(assigned)}
        floors = [floor(broker.port, payloads) for _ in range(3)]
        result = Result(
            robots, assigned, first, publish, statistics.median(floors), 0.0,
            rss_first_mb=rss_first, delivered_s=delivered,
            read_s=read[0], read_messages=read[1], read_lost=read[2],
        )  # fmt: skip
        result.publish_ratio = result.publish_s / result.floor_s
        print(
            f"first build + publish {first:.2f} s; publishing {publish:.2f} s, floor "
            f"{result.floor_s:.2f} s ({result.publish_ratio:.2f}x); RSS {rss_first:.0f} MB",
            flush=True,
        )
        scenarios = sorted(s for s, r in by_scenario.items() if len(r) >= 5) or sorted(by_scenario)
        commits: list[float] = []
        for n in range(1, rounds + 1):
            time.sleep(1.0)
            scenario = scenarios[(n * 37) % len(scenarios)]
            path = lab / "configs/scenarios" / f"{scenario}.yaml"
            text = path.read_text()
            edited = re.sub(r"\{ID: (\d+),", lambda m: f"{{ID: {int(m.group(1)) + 100000},", text)
            assert edited != text, f"{path}: no ID to change"
            path.write_text(edited)
            git(lab, "add", str(path))
            affected = [f"robotconf/robots/{r}/launch" for r in by_scenario[scenario]]
            before = launches.snapshot()
            t0 = time.perf_counter()
            git(lab, "commit", "-q", "-m", f"change {scenario}")
            commits.append(time.perf_counter() - t0)

            old = {topic: payload for topic, (_, payload) in before.items()}
            seen = launches.wait(functools.partial(renewed, old=old, topics=affected), TIMEOUT)
            took = max(seen[t][0] for t in affected) - t0
            others = [t for t in seen if t not in affected and old.get(t) != seen[t][1]]
            if others:
                raise RuntimeError(f"round {n}: {len(others)} robots not on {scenario} changed")
            result.change_s.append(took)
            result.affected.append(len(affected))
            print(f"  round {n}: {scenario} ({len(affected)} robots) {took:.3f} s", flush=True)
        result.change_p50_s = statistics.median(result.change_s)
        result.change_max_s = max(result.change_s)
        result.commit_p50_s = statistics.median(commits)
        result.rss_after_mb, result.peak_mb = memory(reconciler.pid)
        return result
    finally:
        if reconciler is not None:
            reconciler.terminate()
            reconciler.wait(30)
        launches.close()
        broker.stop()


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=int, default=10_000)
    parser.add_argument("--rounds", type=int, default=9)
    generate.add_shape_option(parser)
    parser.add_argument(
        "--code",
        type=Path,
        default=ROOT,
        help="the checkout whose reconciler runs, for a before figure (default: this one)",
    )
    parser.add_argument("--keep", action="store_true", help="keep the work folder")
    parser.add_argument("--json", type=Path, help="write the result here")
    args = parser.parse_args(argv)
    base = "/dev/shm" if Path("/dev/shm").is_dir() else None
    folder = Path(tempfile.mkdtemp(prefix="scale-", dir=base))
    try:
        result = measure(args.robots, args.rounds, folder, args.shape, args.code.resolve())
    finally:
        if not args.keep:
            subprocess.run(["rm", "-rf", str(folder)], check=False)
    print(
        f"\n{result.robots} robots ({result.assigned} assigned)\n"
        f"  first build + publish   {result.first_s:.2f} s\n"
        f"  publishing              {result.publish_s:.2f} s  floor {result.floor_s:.2f} s  "
        f"{result.publish_ratio:.2f}x (target <= {PUBLISH_TARGET}x; first to last request "
        f"seen by the subscriber {result.delivered_s:.2f} s)\n"
        f"  one-scenario change     p50 {result.change_p50_s:.3f} s  max "
        f"{result.change_max_s:.3f} s  (target p50 <= {CHANGE_TARGET} s; git commit itself "
        f"{result.commit_p50_s:.3f} s)\n"
        f"  whole-fleet read        {result.read_messages} retained messages in "
        f"{result.read_s:.2f} s (of {result.assigned} requests and the reconciler's status); "
        f"loss known: {result.read_lost or 'none'}\n"
        f"  reconciler memory       {result.rss_first_mb:.0f} MB after the first publish, "
        f"{result.rss_after_mb:.0f} MB after the rounds, peak {result.peak_mb:.0f} MB "
        f"(target <= {RSS_TARGET_MB:.0f} MB)"
    )
    if args.json:
        args.json.write_text(json.dumps(asdict(result), indent=2) + "\n")
    met = (
        result.change_p50_s <= CHANGE_TARGET
        and result.publish_ratio <= PUBLISH_TARGET
        and max(result.rss_first_mb, result.rss_after_mb) <= RSS_TARGET_MB
        and result.read_lost is None
        and result.read_messages >= result.assigned + 1
    )
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
