"""Rollout latency: from `git commit` until every robot reports `running` with its new digest.

For each fleet size, on a fresh Mosquitto (its own port; default limits except the
per-client queue `robotconf broker-config` sets for the fleet's size) and a fresh git repository
holding the example lab with N robots spread over its five scenarios:

  rollout    `robotconf reconcile` (a real subprocess) watches the repository; every round
             commits a fleet.yaml that renames every robot (so that every digest changes) and
             waits, on a status subscriber, until each robot's retained status says `running`
             with its new digest. The clock starts right before `git commit`.
  delivered  the same clock, until the last new request reached that subscriber: the
             reconciler's share (notice, read, validate, render, diff, publish) plus the broker.
  floor      the same broker delivering N request-sized QoS 1 messages (the payload of one
             robot's request) from one publisher to one subscriber: first publish until the
             N-th message arrives; five times before the fleet starts and five times after
             it has stopped, on the idle machine: the lower median counts.

Agents are the real agent (`agent.runtime.Agent`) with a cheap brain that must stay up
--startsecs (default 0.1 s) before it counts as `running`; 0 would report `running` as soon as
the brain is spawned. The brain is --brain: `pause` (default; bench/pause.c, a program that
only waits for a signal, built with the C compiler, else `sleep`), `sleep`, or any command.
Up to --process-max robots, each agent is its own `robotconf agent` process; beyond that,
worker processes host --per-worker agents each on one thread, as a simulation host runs its
robots (`robotconf agent --config a.yaml --config b.yaml ...`), robots dealt out round-robin.
All of them share this machine's cores, unlike a real fleet, so the CPU seconds per round are
shown for the broker, the reconciler, the agents (brains included) and this measuring process.
Work folders live on /dev/shm when it exists (each robot has its own disk). Targets: 100
robots p50 <= 1 s; 1,000 robots p50 <= 3 s and <= 10x the floor. Exit 0 when they are met, 1
when one is missed.

    python bench/rollout.py [--sizes 10,100,1000] [--rounds 7] [--startsecs 0.1]
                            [--brain pause|sleep|CMD] [--server-priority] [--keep] [--json F]
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import json
import os
import re
import resource
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import paho.mqtt.client as paho  # noqa: E402
import yaml  # noqa: E402
from paho.mqtt.enums import CallbackAPIVersion  # noqa: E402

from robotconf.configurator.brokerconf import queue_lines  # noqa: E402
from robotconf.configurator.render import render_fleet  # noqa: E402
from robotconf.configurator.workspace import check  # noqa: E402
from robotconf.contract.wire import AgentStatus  # noqa: E402
from tests.support.mosquitto import find_mosquitto, free_port  # noqa: E402
from tests.support.watch import FleetWatch  # noqa: E402

SCENARIOS = [
    "delivery-gazebo",
    "guide-gazebo",
    "delivery-bluetooth-gazebo",
    "patrol-real",
    "patrol-noetic-gazebo",
]
TIMEOUT = 120.0
# `robotconf` of the checkout it runs in (its working folder, first on sys.path for `-c`): one
# from before the one namespace (issue 33) has its commands at the top, as `workstation.cli`.
ROBOTCONF = [
    sys.executable,
    "-c",
    "import os, sys\n"
    "if os.path.isdir('robotconf/workstation'):\n"
    "    from robotconf.workstation.cli import main\n"
    "else:\n"
    "    from workstation.cli import main\n"
    "sys.exit(main())",
]
TARGETS = {100: (1.0, None), 1000: (3.0, 10.0)}  # size: (p50 seconds, ratio to the floor)
WAVE_GAP_TARGET = 0.1  # seconds from a wave's last healthy robot to the next wave's publish


# ------------------------------------------------------------------ infrastructure


class Broker:
    """A Mosquitto of the benchmark's own, on a free port."""

    def __init__(self, folder: Path, robots: int) -> None:
        binary = find_mosquitto()
        if binary is None:
            raise SystemExit("mosquitto is not installed (./dev setup installs it)")
        self.port = free_port()
        conf = folder / "mosquitto.conf"
        # The queue `robotconf broker-config` sets for a fleet of this size: the floor's single
        # subscriber gets N QoS 1 messages at once, and every whole-fleet reader all of them.
        lines = [f"listener {self.port} 127.0.0.1", "allow_anonymous true", "persistence false"]
        conf.write_text("\n".join([*lines, *queue_lines(robots)]) + "\n", encoding="utf-8")
        self.log = (folder / "mosquitto.log").open("wb")
        self.proc = subprocess.Popen(
            [binary, "-c", str(conf)], stdout=self.log, stderr=self.log, start_new_session=True
        )
        time.sleep(0.3)

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(10)
        self.log.close()


def client(name: str) -> paho.Client:
    c = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"bench-{name}-{os.getpid()}")
    c.max_inflight_messages_set(200)
    return c


def connect(c: paho.Client, port: int) -> None:
    connected = threading.Event()
    c.on_connect = lambda *a: connected.set()
    c.connect("127.0.0.1", port)
    c.loop_start()
    if not connected.wait(10):
        raise RuntimeError("cannot connect to the benchmark broker")


class Convergence:
    """When every robot of a target runs the digest it should have: fed each agent status by
    the tests' fleet watcher (tests/support/watch.py), with its arrival time."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.target: dict[str, str] = {}
        self.done: set[str] = set()
        self.latest: dict[str, tuple[str, str | None]] = {}
        self.reached = threading.Event()
        self.reached_at = 0.0

    def expect(self, target: dict[str, str]) -> None:
        with self.lock:
            self.target = dict(target)
            self.done = {r for r, d in self.target.items() if self.latest.get(r) == ("running", d)}
            self.reached.clear()
            if len(self.done) == len(self.target):
                self.reached_at = time.perf_counter()
                self.reached.set()

    def __call__(self, robot: str, status: AgentStatus, arrived: float) -> None:
        seen = (status.state.value, status.digest)
        with self.lock:
            self.latest[robot] = seen
            want = self.target.get(robot)
            if want is None:
                return
            if seen == ("running", want):
                self.done.add(robot)
            else:
                self.done.discard(robot)
            if len(self.done) == len(self.target) and not self.reached.is_set():
                self.reached_at = arrived
                self.reached.set()

    def missing(self) -> str:
        with self.lock:
            late = sorted(set(self.target) - self.done)
            shown = ", ".join(f"{r} {self.latest.get(r)}" for r in late[:5])
        return f"{len(late)} of {len(self.target)} not running the new digest (e.g. {shown})"


# ------------------------------------------------------------------ the lab


def git(root: Path, *args: str) -> str:
    done = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, check=True)
    return done.stdout.strip()


def robot_ids(size: int) -> list[str]:
    return [f"r{i:04d}" for i in range(1, size + 1)]


# Three waves: one robot in a hundred as canaries, then half the fleet, then all of it.
WAVES_POLICY = """\
rollout:
  waves: [{name: canary, selector: {ring: canary}}, {name: half, percent: 50}, {name: all}]
  healthy_after: 0
  max_failures: "5%"
  wave_timeout: 600
"""


def write_fleet(root: Path, size: int, generation: int, mode: str = "restart") -> None:
    """fleet.yaml of `size` robots. A round of `restart` and `waves` renames every robot (every
    digest changes); `knowledge` and `reload` keep the names and change every scenario's
    knowledge instead (the capability, hence restart_digest, stays)."""
    named = generation if mode in ("restart", "waves") else 0
    lines = ["robots:"]
    for index, robot in enumerate(robot_ids(size)):
        scenario = SCENARIOS[index % len(SCENARIOS)]
        labels = ", labels: {ring: canary}" if mode == "waves" and index % 100 == 0 else ""
        # Each robot in a namespace of its own: robots of one world must not share a topic
        # (RC505).
        lines.append(
            f"  {robot}: {{scenario: {scenario}, name: {robot} v{named}, "
            f"namespace: {robot}{labels}}}"
        )
    policy = WAVES_POLICY if mode == "waves" else ""
    (root / "configs" / "fleet.yaml").write_text("\n".join(lines) + "\n" + policy, "utf-8")
    if mode in ("knowledge", "reload"):
        for name in SCENARIOS:
            path = root / "configs" / "scenarios" / f"{name}.yaml"
            scenario = yaml.safe_load(path.read_text(encoding="utf-8"))
            scenario.setdefault("knowledge", {})["ROUND"] = generation
            path.write_text(yaml.safe_dump(scenario, sort_keys=False), encoding="utf-8")


def expected(root: Path) -> tuple[dict[str, str], bytes]:
    """Each robot's digest in the work tree, and one request's payload (for the floor)."""
    checked = check(root)
    assert checked.ok, [str(d) for d in checked.errors[:5]]
    fleet = render_fleet(checked.repo)
    first = next(iter(fleet.requests.values()))
    return {r: q.digest for r, q in fleet.requests.items()}, first.payload()


def make_lab(folder: Path, size: int, mode: str = "restart") -> Path:
    root = folder / "lab"
    root.mkdir()
    for part in ("models", "configs"):
        shutil.copytree(ROOT / part, root / part)
    # Hundreds of robots share each world here: every mapping name relative, resolved in each
    # robot's namespace (the example's absolute names would have them drive each other, RC505).
    for scheme in root.glob("models/platforms/*/mapping-schemes/*.yaml"):
        text = scheme.read_text(encoding="utf-8")
        scheme.write_text(re.sub(r"name: /", "name: ", text), encoding="utf-8")
    write_fleet(root, size, 0, mode)
    git(root, "init", "-q", "-b", "main")
    git(root, "config", "user.email", "bench@example.org")
    git(root, "config", "user.name", "bench")
    git(root, "config", "commit.gpgsign", "false")
    git(root, "add", "configs", "models")
    git(root, "commit", "-q", "-m", "fleet v0")
    return root


# ------------------------------------------------------------------ agents


def brain_command(choice: str, folder: Path) -> list[str]:
    """The brain every simulated robot runs: `pause` (bench/pause.c, built here with the C
    compiler; `sleep` when there is none), `sleep`, or a command line of one's own."""
    if choice == "sleep":
        return ["sleep", "86400"]
    if choice != "pause":
        return choice.split()
    compiler = shutil.which("cc") or shutil.which("gcc")
    binary = folder / "pause"
    if compiler is not None:
        flags = ["-static", "-nostdlib"] if os.uname().machine == "x86_64" else []
        built = subprocess.run(
            [compiler, "-O2", *flags, "-o", str(binary), str(ROOT / "bench" / "pause.c")],
            capture_output=True,
            text=True,
        )
        if built.returncode == 0:
            return [str(binary)]
        print(f"  (cannot build bench/pause.c: {built.stderr.strip()[:200]}; using sleep)")
    else:
        print("  (no C compiler: the brain is `sleep`)")
    return ["sleep", "86400"]


def agent_config(
    folder: Path, robot: str, url: str, startsecs: float, brain: list[str], reload: bool = False
) -> Path:
    work = folder / "agents" / robot
    work.mkdir(parents=True)
    config = {
        "broker": url,
        "description": {"id": robot},
        "command": brain,
        "workdir": str(work),
        "startsecs": startsecs,
        "stop_timeout": 5,
    }
    if reload:
        config["reload"] = {"signal": "SIGHUP"}
    path = work / "agent.yaml"
    path.write_text(yaml.safe_dump(config), encoding="utf-8")
    return path


def host_command(paths: Sequence[Path]) -> list[str]:
    """One agent process for several robots: the agent's own `--config` repeated."""
    configs = [arg for path in paths for arg in ("--config", str(path))]
    return [sys.executable, "-m", "robotconf.agent.cli", "--log-level", "warning", *configs]


def start_agents(folder: Path, size: int, url: str, options: Options) -> subprocess.Popen[bytes]:
    """The simulated fleet: one launcher process, in a session of its own, and its children."""
    brain = brain_command(options.brain, folder)
    reload = options.mode == "reload"
    paths = [
        agent_config(folder, r, url, options.startsecs, brain, reload) for r in robot_ids(size)
    ]
    if size <= options.process_max:
        commands = [
            [sys.executable, "-m", "robotconf.agent.cli", "--config", str(p)] for p in paths
        ]
    else:
        # Robots dealt out like cards: the reconciler publishes in robot order, and consecutive
        # robots in one worker would make each worker busy in turn, unlike robots that each
        # have a computer of their own.
        workers = -(-len(paths) // options.per_worker)
        commands = [host_command(paths[k::workers]) for k in range(workers)]
    listing = folder / "fleet.json"
    listing.write_text(json.dumps(commands), encoding="utf-8")
    logs = folder / "agent-logs"
    logs.mkdir()
    with (logs / "launcher.log").open("wb") as out:
        # One launcher to start and stop the whole simulated fleet.
        return subprocess.Popen(
            [sys.executable, __file__, "fleet", str(listing), str(logs)],
            cwd=ROOT,
            stdout=out,
            stderr=out,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )


def launcher(listing: str, logs: str) -> int:
    """Starts every agent command as a child and stops them all on SIGTERM."""
    commands = json.loads(Path(listing).read_text(encoding="utf-8"))
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    signal.signal(signal.SIGINT, lambda *a: stop.set())
    children = []
    for n, argv in enumerate(commands):
        with (Path(logs) / f"{n}.log").open("wb") as out:
            children.append(
                subprocess.Popen(
                    argv,
                    cwd=ROOT,
                    stdout=out,
                    stderr=out,
                    stdin=subprocess.DEVNULL,
                    # Each its own session, as separately started programs would be.
                    start_new_session=True,
                )
            )
    stop.wait()
    for child in children:
        with contextlib.suppress(ProcessLookupError):
            child.send_signal(signal.SIGTERM)
    for child in children:
        try:
            child.wait(30)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()
    return 0


def stop_fleet(proc: subprocess.Popen[bytes] | None) -> None:
    if proc is None:
        return
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(60)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


# ------------------------------------------------------------------ measurements


def descendants(pid: int) -> list[int]:
    """The fleet launcher and its children (the agents or workers)."""
    found = [pid]
    with contextlib.suppress(OSError):
        for task in Path(f"/proc/{pid}/task").iterdir():
            text = (task / "children").read_text().split()
            found += [int(c) for c in text]
    return found


def cpu_times(broker: Broker, reconciler: Any, fleet: Any) -> dict[str, float]:
    """CPU seconds (user + system, children included) per participant, from /proc."""
    tick = os.sysconf("SC_CLK_TCK")

    def of(pid: int) -> float:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            return 0.0
        return sum(int(f) for f in fields[11:15]) / tick

    own = resource.getrusage(resource.RUSAGE_SELF)  # the status watch; not git, a child
    return {
        "bench": own.ru_utime + own.ru_stime,
        "broker": of(broker.proc.pid),
        "reconciler": of(reconciler.pid) if reconciler else 0.0,
        "agents": sum(of(pid) for pid in descendants(fleet.pid)) if fleet else 0.0,
    }


def floor(port: int, size: int, payload: bytes) -> float:
    """One publisher, one subscriber, `size` QoS 1 messages of `payload`'s size."""
    got = 0
    done = threading.Event()
    finished = 0.0

    def on_message(c: paho.Client, u: Any, m: paho.MQTTMessage) -> None:
        nonlocal got, finished
        got += 1
        if got == size:
            finished = time.perf_counter()
            done.set()

    sub = client("floor-sub")
    sub.on_message = on_message
    subscribed = threading.Event()
    sub.on_subscribe = lambda *a: subscribed.set()
    connect(sub, port)
    sub.subscribe("bench/floor/+", qos=1)
    subscribed.wait(10)
    pub = client("floor-pub")
    connect(pub, port)
    started = time.perf_counter()
    for i in range(size):
        pub.publish(f"bench/floor/{i}", payload, qos=1)
    if not done.wait(TIMEOUT):
        raise RuntimeError(f"floor: only {got} of {size} messages arrived")
    for c in (pub, sub):
        c.disconnect()
        c.loop_stop()
    return finished - started


@dataclass
class Options:
    rounds: int
    process_max: int
    per_worker: int
    startsecs: float
    brain: str
    server_priority: bool
    verbose: bool
    keep: bool = False
    mode: str = "restart"


@dataclass
class Result:
    robots: int
    agents: str
    rounds: list[float]
    p50: float
    max: float
    delivered_p50: float  # commit until the last request reached a subscriber
    floor_p50: float
    ratio: float  # p50 / floor
    delivered_ratio: float
    initial: float  # agents and reconciler started until the first convergence
    cpu: dict[str, float]  # CPU seconds per round (median) of bench, broker, reconciler, agents
    mode: str = "restart"
    gaps: list[float] = field(default_factory=list)  # waves: last healthy -> next wave published
    gap_p50: float | None = None


def start_reconciler(
    lab: Path, url: str, interval: float, log: Path, code: Path = ROOT
) -> subprocess.Popen[bytes]:
    """`robotconf reconcile` watching `lab`'s main branch, its output in `log`; `code`: the
    checkout whose reconciler runs (this one by default)."""
    with log.open("wb") as out:
        return subprocess.Popen(
            [*ROBOTCONF, "reconcile", "--repo", str(lab), "--branch", "main",
             "--broker", url, "--interval", f"{interval:g}"],
            cwd=code, stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
        )  # fmt: skip


def prioritise(pids: Sequence[int]) -> bool:
    """Linux autogroup nice -10 for the server side; False when not allowed (not root)."""
    try:
        for pid in pids:
            Path(f"/proc/{pid}/autogroup").write_text("-10")
    except OSError:
        return False
    return True


@contextlib.contextmanager
def work_folder(prefix: str, base: Path | None, keep: bool) -> Iterator[str]:
    folder = tempfile.mkdtemp(prefix=prefix, dir=base)
    try:
        yield folder
    finally:
        if keep:
            print(f"  kept {folder}", flush=True)
        else:
            shutil.rmtree(folder, ignore_errors=True)


def measure(size: int, options: Options) -> Result:
    base = Path("/dev/shm") if Path("/dev/shm").is_dir() else None
    with work_folder(f"rollout-{size}-", base, options.keep) as tmp:
        folder = Path(tmp)
        lab = make_lab(folder, size, options.mode)
        broker = Broker(folder, size)
        fleet: subprocess.Popen[bytes] | None = None
        reconciler: subprocess.Popen[bytes] | None = None
        converged = Convergence()
        watch = FleetWatch(broker.url, listener=converged)
        times: list[float] = []
        delivered: list[float] = []
        gaps: list[float] = []
        cpu: list[dict[str, float]] = []
        try:
            digests, payload = expected(lab)
            # On the idle machine, before the fleet exists (and again after it is gone).
            floors_before = [floor(broker.port, size, payload) for _ in range(5)]
            converged.expect(digests)
            started = time.perf_counter()
            fleet = start_agents(folder, size, broker.url, options)
            reconciler = start_reconciler(lab, broker.url, 60, folder / "reconciler.log")
            if options.server_priority and not prioritise(
                [broker.proc.pid, reconciler.pid, os.getpid()]
            ):
                print("  (--server-priority needs root: running without it)", flush=True)
            if not converged.reached.wait(TIMEOUT * 2):
                raise RuntimeError(f"{size} robots never converged: {converged.missing()}")
            initial = converged.reached_at - started
            for generation in range(1, options.rounds + 1):
                time.sleep(1.0)  # let the previous round's last messages settle
                write_fleet(lab, size, generation, options.mode)
                digests, _ = expected(lab)
                converged.expect(digests)
                watch.live_launches.clear()
                watch.timeline.clear()
                git(lab, "add", "configs")
                before = cpu_times(broker, reconciler, fleet)
                t0 = time.perf_counter()
                git(lab, "commit", "-q", "-m", f"fleet v{generation}")
                if not converged.reached.wait(TIMEOUT):
                    raise RuntimeError(f"round {generation}: not converged: {converged.missing()}")
                times.append(converged.reached_at - t0)
                delivered.append(max((t for _, _, t in watch.live_launches), default=t0) - t0)
                if options.mode == "waves":
                    gaps += wave_gaps(watch, digests, size)
                time.sleep(0.5)  # the agents' last status messages, for the CPU figures
                after = cpu_times(broker, reconciler, fleet)
                cpu.append({k: after[k] - before[k] for k in before})
                if options.verbose:
                    print(
                        f"  round {generation}: {times[-1]:.3f} s; requests delivered "
                        f"{delivered[-1]:.3f} s; CPU s "
                        + ", ".join(f"{k} {v:.2f}" for k, v in cpu[-1].items()),
                        flush=True,
                    )
        finally:
            if reconciler is not None:
                reconciler.terminate()
                reconciler.wait(30)
            stop_fleet(fleet)
            watch.close()
            if options.verbose:
                print((folder / "reconciler.log").read_text(errors="replace")[-2000:])
        try:
            floors_after = [floor(broker.port, size, payload) for _ in range(5)]
        finally:
            broker.stop()
    p50 = statistics.median(times)
    # The lower of the two medians: the stricter target.
    floor_p50 = min(statistics.median(floors_before), statistics.median(floors_after))
    delivered_p50 = statistics.median(delivered)
    workers = -(-size // options.per_worker)
    agents = "processes" if size <= options.process_max else f"{workers} worker processes"
    cpu_p50 = {k: round(statistics.median(c[k] for c in cpu), 3) for k in cpu[0]}
    return Result(
        size, agents, times, p50, max(times), delivered_p50, floor_p50,
        p50 / floor_p50, delivered_p50 / floor_p50, initial, cpu_p50, options.mode,
        gaps, statistics.median(gaps) if gaps else None,
    )  # fmt: skip


def wave_gaps(watch: FleetWatch, digests: dict[str, str], size: int) -> list[float]:
    """Per wave boundary of the round just done: from the moment the last robot of a wave
    reported running its new request (healthy_after is 0) until the first request of the next
    wave was published, both as seen by the watcher."""
    ids = robot_ids(size)
    canary = {r for i, r in enumerate(ids) if i % 100 == 0}
    half = set((sorted(canary) + [r for r in ids if r not in canary])[: -(-size // 2)])
    waves = [canary, half - canary, set(ids) - half]
    running: dict[str, float] = {}
    for at, robot, status in watch.timeline:
        if status.state.value == "running" and status.digest == digests.get(robot):
            running.setdefault(robot, at)
    published: dict[str, float] = {}
    for topic, payload, at in watch.live_launches:
        if payload:
            published.setdefault(topic.split("/")[-2], at)
    found = []
    for earlier, later in itertools.pairwise(waves):
        healthy = max(running.get(r, float("inf")) for r in earlier)
        first = min(published.get(r, float("inf")) for r in later)
        if healthy != float("inf") and first != float("inf"):
            found.append(first - healthy)
    return found


def verdicts(results: list[Result]) -> Iterator[tuple[str, bool]]:
    for r in results:
        if r.gap_p50 is not None:
            yield (
                f"{r.robots} robots wave gap p50 {r.gap_p50 * 1000:.0f} ms <= "
                f"{WAVE_GAP_TARGET * 1000:.0f} ms",
                r.gap_p50 <= WAVE_GAP_TARGET,
            )
        if r.mode != "restart":
            continue  # the latency targets are the all-at-once restart's
        target = TARGETS.get(r.robots)
        if target is None:
            continue
        seconds, ratio = target
        yield f"{r.robots} robots p50 {r.p50:.3f} s <= {seconds:g} s", r.p50 <= seconds
        if ratio is not None:
            yield f"{r.robots} robots p50 {r.ratio:.1f}x the floor <= {ratio:g}x", r.ratio <= ratio


def main(argv: list[str]) -> int:
    if argv[:1] == ["fleet"]:
        return launcher(argv[1], argv[2])
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--sizes", default="10,100,1000", help="fleet sizes (default: %(default)s)")
    parser.add_argument("--rounds", type=int, default=7, help="commits per size")
    parser.add_argument(
        "--process-max", type=int, default=100, help="up to this size, one process per agent"
    )
    parser.add_argument("--per-worker", type=int, default=50, help="agents per worker beyond")
    parser.add_argument(
        "--startsecs",
        type=float,
        default=0.1,
        help="seconds a brain must stay up to count as running (default: %(default)s)",
    )
    parser.add_argument(
        "--brain",
        default="pause",
        help="pause (bench/pause.c, built with cc), sleep, or a command (default: %(default)s)",
    )
    parser.add_argument(
        "--server-priority",
        action="store_true",
        help="run broker, reconciler and this measuring process at autogroup nice -10 (root)",
    )
    parser.add_argument("--verbose", action="store_true", help="per round details, logs")
    parser.add_argument(
        "--keep", action="store_true", help="keep each size's work folder (logs) afterwards"
    )
    parser.add_argument("--json", type=Path, default=None, help="also write the results here")
    parser.add_argument(
        "--mode",
        choices=["restart", "waves", "knowledge", "reload"],
        default="restart",
        help="restart: rename every robot, all at once; waves: the same in three health-gated "
        "waves (canary 1%%, half, all; healthy_after 0); knowledge: a knowledge-only change, "
        "agents restart; reload: the same change, agents reload (default: %(default)s)",
    )
    args = parser.parse_args(argv)
    options = Options(
        args.rounds,
        args.process_max,
        args.per_worker,
        args.startsecs,
        args.brain,
        args.server_priority,
        args.verbose,
        args.keep,
        args.mode,
    )
    results = []
    for size in (int(s) for s in args.sizes.split(",")):
        print(f"{size} robots, {args.mode} ...", flush=True)
        results.append(measure(size, options))
        r = results[-1]
        print(f"  rounds: {', '.join(f'{t:.3f}' for t in r.rounds)} s", flush=True)
        if r.gap_p50 is not None:
            shown = ", ".join(f"{g * 1000:.0f}" for g in r.gaps)
            print(f"  wave gaps (last healthy -> next wave published): {shown} ms", flush=True)
    print()
    print(
        f"{'robots':>7} {'agents':<20} {'p50 s':>7} {'max s':>7} {'delivered s':>11} "
        f"{'floor s':>8} {'p50/floor':>9} {'delivered/floor':>15}   CPU s per round"
    )
    for r in results:
        cpu = ", ".join(f"{k} {v:.2f}" for k, v in r.cpu.items())
        print(
            f"{r.robots:>7} {r.agents:<20} {r.p50:>7.3f} {r.max:>7.3f} {r.delivered_p50:>11.3f} "
            f"{r.floor_p50:>8.3f} {r.ratio:>9.1f} {r.delivered_ratio:>15.1f}   {cpu}"
        )
    print()
    ok = True
    for text, met in verdicts(results):
        print(f"{'met   ' if met else 'MISSED'} {text}")
        ok &= met
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps([asdict(r) for r in results], indent=2) + "\n")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
