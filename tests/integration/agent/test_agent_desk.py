"""Logs and restarts from the desk, end to end: real agents, a real Mosquitto, `robotconf logs`
and `robotconf restart` as processes."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
import pytest

from robotconf.agent.logs import BURST, RATE
from robotconf.contract.launch import RestartRequest
from robotconf.contract.mqtt import Connection, make_client
from robotconf.contract.signing import generate_keys, load_private_key, sign
from robotconf.contract.wire import (
    LOG_FOLLOW_TTL,
    MAX_LOG_MESSAGE_BYTES,
    AgentState,
    AgentStatus,
    Topics,
)
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import FAILS_ONCE, ROBOT, TIMEOUT, make_request, publish
from tests.support.lab import ROBOTCONF
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

TOPICS = Topics()
SECRET = "s3cr3t-api-token-42"
# Prints a secret from its environment, then a numbered tick five times a second.
CHATTY = [
    sys.executable,
    "-u",
    "-c",
    "import os, time\n"
    "print('token', os.environ['API_TOKEN'])\n"
    "n = 0\n"
    "while True:\n"
    "    print('tick', n)\n"
    "    n += 1\n"
    "    time.sleep(0.2)\n",
    "{launch_request}",
]
# Five ticks, then quiet: its whole log fits a 20-line tail however slow the machine is (a
# loaded run took 4 s to ask, and CHATTY's ticks had pushed the token out of the tail).
FIVE_TICKS = [
    *CHATTY[:3],
    "import os, time\n"
    "print('token', os.environ['API_TOKEN'])\n"
    "for n in range(5):\n"
    "    print('tick', n)\n"
    "    time.sleep(0.2)\n"
    "time.sleep(3600)\n",
    "{launch_request}",
]
# A long line, then a flood of lines at once, then quiet.
FLOOD = [
    sys.executable,
    "-c",
    "import sys, time\n"
    "sys.stdout.write('L' * 300000 + '\\n')\n"
    "sys.stdout.write(''.join('flood %d\\n' % n for n in range(3000)))\n"
    "sys.stdout.flush()\n"
    "time.sleep(600)\n",
    "{launch_request}",
]


def robotconf(
    *args: str, broker: Mosquitto, timeout: float = 60.0
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(ROBOTCONF), *args, "--broker", broker.url],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def run_brain(
    make_agent: AgentFactory,
    watch: FleetWatch,
    broker: Mosquitto,
    command: list[str],
    **settings: Any,
) -> Any:
    agent = make_agent(command=command, **settings).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    request = make_request()
    publish(broker.url, TOPICS.launch(ROBOT), request.payload())
    return agent, request


class Listener:
    """A raw subscriber on one topic: every message, its size and when it came."""

    def __init__(self, broker: Mosquitto, topic: str) -> None:
        self.messages: list[tuple[float, bytes]] = []
        self._lock = threading.Lock()
        subscribed = threading.Event()
        self.client = make_client(Connection(url=broker.url), f"listener-{time.monotonic_ns()}")

        def on_connect(c: paho.Client, u: Any, f: Any, rc: Any, p: Any) -> None:
            c.subscribe(topic, qos=1)

        def on_subscribe(c: paho.Client, u: Any, mid: Any, rc: Any, p: Any) -> None:
            subscribed.set()

        def on_message(c: paho.Client, u: Any, msg: paho.MQTTMessage) -> None:
            with self._lock:
                self.messages.append((time.monotonic(), bytes(msg.payload)))

        self.client.on_connect = on_connect
        self.client.on_subscribe = on_subscribe
        self.client.on_message = on_message
        self.client.connect(broker.host, broker.port)
        self.client.loop_start()
        assert subscribed.wait(TIMEOUT)

    def taken(self) -> list[tuple[float, bytes]]:
        with self._lock:
            return list(self.messages)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


# ---------------------------------------------------------------- logs


def test_logs_show_the_brain_and_its_agent_without_secrets(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent, request = run_brain(make_agent, watch, mosquitto, FIVE_TICKS, env={"API_TOKEN": SECRET})
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    wait_for(lambda: "tick 4" in agent.brain_log(), "the brain's ticks")
    assert SECRET in agent.brain_log()  # the brain printed it; the desk must not see it

    done = robotconf("logs", ROBOT, "--lines", "20", broker=mosquitto)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert 6 <= len(lines) <= 20
    assert SECRET not in done.stdout and "token [redacted]" in done.stdout
    assert "--- robotconf agent" in done.stdout and "started pid" in done.stdout
    # Ticks in order, the newest last: the tail of the log.
    ticks = [int(line.split()[1]) for line in lines if line.startswith("tick ")]
    assert ticks == sorted(ticks) and len(ticks) >= 3
    last = robotconf("logs", ROBOT, "-n", "3", broker=mosquitto).stdout.splitlines()
    assert len(last) == 3 and all(line.startswith("tick ") for line in last)


def test_logs_follow_streams_until_nobody_asks(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent, request = run_brain(make_agent, watch, mosquitto, CHATTY, env={"API_TOKEN": SECRET})
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    wait_for(lambda: "tick 1" in agent.brain_log(), "the brain's ticks")
    follower = subprocess.Popen(
        [str(ROBOTCONF), "logs", ROBOT, "--follow", "--lines", "1", "--broker", mosquitto.url],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    listener = Listener(mosquitto, TOPICS.logs(ROBOT))
    try:
        assert follower.stdout is not None
        seen: list[str] = []
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline and sum(s.startswith("tick") for s in seen) < 6:
            seen.append(follower.stdout.readline().rstrip("\n"))
        ticks = [int(s.split()[1]) for s in seen if s.startswith("tick ")]
        # New lines keep coming, each once, in order.
        assert len(ticks) >= 6 and ticks == list(range(ticks[0], ticks[0] + len(ticks)))
        follower.send_signal(signal.SIGINT)
        assert follower.wait(TIMEOUT) == 0
        stopped_asking = time.monotonic()
        # The agent streams on for at most LOG_FOLLOW_TTL after the last ask, then stops,
        # while its brain goes on writing.
        time.sleep(LOG_FOLLOW_TTL + 3)
        quiet_from = len(listener.taken())
        time.sleep(2.0)
        assert len(listener.taken()) == quiet_from, "the agent still streams its log"
        last = max(t for t, _ in listener.taken())
        assert last - stopped_asking <= LOG_FOLLOW_TTL + 3
        assert "tick" in agent.brain_log().splitlines()[-1]  # the brain did not stop
    finally:
        listener.close()
        if follower.poll() is None:
            follower.kill()
        follower.communicate()


def test_log_messages_are_bounded_cut_and_paced(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent, request = run_brain(make_agent, watch, mosquitto, FLOOD)
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    wait_for(lambda: "flood 2999" in agent.brain_log(), "the flood in the brain's log")
    listener = Listener(mosquitto, TOPICS.logs(ROBOT))
    try:
        asked = time.monotonic()
        done = robotconf("logs", ROBOT, "--lines", "1000", broker=mosquitto)
        assert done.returncode == 0, done.stderr
        lines = done.stdout.splitlines()
        assert len(lines) == 1000 and lines[-1] == "flood 2999"
        messages = listener.taken()
        assert messages and all(len(p) <= MAX_LOG_MESSAGE_BYTES for _, p in messages)
        # About RATE lines a second: never more than the burst and the rate allow.
        for at, _ in messages:
            sent = sum(len(json.loads(p)["lines"]) for t, p in messages if t <= at)
            assert sent <= BURST + RATE * (at - asked) + 20
        tail = robotconf("logs", ROBOT, "--lines", "3", broker=mosquitto).stdout.splitlines()
        assert tail == ["flood 2997", "flood 2998", "flood 2999"]
    finally:
        listener.close()
    long_line = [line for line in agent.brain_log().splitlines() if line.startswith("LLLL")]
    assert len(long_line[0]) == 300_000


def test_a_long_line_reaches_the_desk_cut_with_a_marker(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    command = [
        sys.executable,
        "-c",
        "import sys, time\nprint('L' * 300000, flush=True)\nprint('after', flush=True)\n"
        "time.sleep(600)",
        "{launch_request}",
    ]
    agent, request = run_brain(make_agent, watch, mosquitto, command)
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    wait_for(lambda: "after" in agent.brain_log(), "the brain's lines")
    done = robotconf("logs", ROBOT, "--lines", "2", broker=mosquitto)
    assert done.returncode == 0, done.stderr
    cut, after = done.stdout.splitlines()
    assert cut.startswith("L" * 1000) and cut.endswith("[robotconf: line cut, 300,000 bytes]")
    assert len(cut.encode()) < MAX_LOG_MESSAGE_BYTES and after == "after"


def test_logs_of_an_unknown_or_offline_robot_are_refused(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent, request = run_brain(make_agent, watch, mosquitto, CHATTY, env={"API_TOKEN": "x"})
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    unknown = robotconf("logs", "tb3-O1", broker=mosquitto)
    assert unknown.returncode == 1
    assert "unknown robot 'tb3-O1'" in unknown.stderr and "did you mean tb3-01" in unknown.stderr
    assert "Traceback" not in unknown.stderr
    bad = robotconf("logs", "../tb3-01/#", broker=mosquitto)
    assert bad.returncode == 1 and "is not a robot id" in bad.stderr
    agent.signal(signal.SIGTERM)
    agent.wait()
    watch.wait_state(ROBOT, AgentState.OFFLINE)
    offline = robotconf("logs", ROBOT, broker=mosquitto)
    assert offline.returncode == 1 and "is offline" in offline.stderr


def test_garbage_log_requests_leave_the_agent_serving(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent, request = run_brain(make_agent, watch, mosquitto, CHATTY, env={"API_TOKEN": "x"})
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    topic = TOPICS.logs_request(ROBOT)
    for payload in (
        b"[" * 100_000,
        b"\xff\xfe",
        b'{"session": "s", "lines": 100000000}',
        b'{"session": "../#", "lines": 1}',
        json.dumps({"session": "s", "lines": 1, "follow": True}).encode() * 1000,
        b"{}",
    ):
        publish(mosquitto.url, topic, payload, retain=False)
    publish(mosquitto.url, topic, b'{"session": "s", "lines": 5}', retain=True)  # stale
    done = robotconf("logs", ROBOT, "--lines", "2", broker=mosquitto)
    assert done.returncode == 0, done.stderr
    assert agent.proc is not None and agent.proc.poll() is None
    assert "logs request refused" in agent.log_tail(200)
    assert "Traceback" not in agent.log_tail(400)
    publish(mosquitto.url, topic, b"", retain=True)


# ---------------------------------------------------------------- restart


def status_json(broker: Mosquitto, cwd: Path) -> dict[str, Any]:
    done = subprocess.run(
        [str(ROBOTCONF), "status", "--json", "--broker", broker.url, "--repo", str(cwd)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    data: dict[str, Any] = json.loads(done.stdout)
    return data


def test_restart_starts_a_failed_brain_again_and_status_says_who(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    agent, request = run_brain(
        make_agent,
        watch,
        mosquitto,
        FAILS_ONCE,
        restart={"policy": "on-failure", "max_restarts": 0},
    )
    failed = watch.wait_state(ROBOT, AgentState.FAILED, agent=agent, digest=request.digest)
    assert failed.restart_requested_by is None
    done = robotconf("restart", ROBOT, "--as", "alice", broker=mosquitto)
    assert done.returncode == 0, done.stderr
    assert f"{ROBOT}: restart requested by alice" in done.stdout
    running = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    assert running.restart_requested_by == "alice" and running.restart_requested_at is not None
    assert running.restarts == 0
    assert "restart requested by alice" in agent.brain_log()
    robot = next(r for r in status_json(mosquitto, tmp_path)["robots"] if r["robot_id"] == ROBOT)
    assert robot["restart"]["requested_by"] == "alice"
    text = subprocess.run(
        [str(ROBOTCONF), "status", "--broker", mosquitto.url, "--repo", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
    ).stdout
    assert f"restart: {ROBOT} by alice at " in text


def test_a_restart_line_goes_once_a_later_request_restarted_the_brain(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    """The screen shows the brain's latest restart: a commit that restarts it after the desk's
    restart takes `restart: ROBOT by alice at ...` away (table and --json)."""
    agent, request = run_brain(make_agent, watch, mosquitto, CHATTY, env={"API_TOKEN": "x"})
    first = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(first.pid)
    assert robotconf("restart", ROBOT, "--as", "alice", broker=mosquitto).returncode == 0
    again = new_brain(watch, agent, first.pid)
    assert again.restart_requested_by == "alice"
    later = make_request(variant=1)  # a later commit; the agent has no reload: a restart
    publish(mosquitto.url, TOPICS.launch(ROBOT), later.payload())
    now = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=later.digest)
    agent.note_brain(now.pid)
    assert now.pid != again.pid and now.restart_requested_by is None
    robot = next(r for r in status_json(mosquitto, tmp_path)["robots"] if r["robot_id"] == ROBOT)
    assert robot["restart"] is None
    text = subprocess.run(
        [str(ROBOTCONF), "status", "--broker", mosquitto.url, "--repo", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
    ).stdout
    assert f"{ROBOT} " in text and "restart: " not in text


def new_brain(watch: FleetWatch, agent: Any, before: int | None) -> AgentStatus:
    """The robot's status once it runs a brain other than `before`."""
    status = watch.wait_for(
        ROBOT,
        lambda s: s.state is AgentState.RUNNING and s.pid not in (None, before),
        f"running a brain other than pid {before}",
        agent=agent,
    )
    agent.note_brain(status.pid)
    return status


def test_restart_replaces_a_running_brain(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent, request = run_brain(make_agent, watch, mosquitto, CHATTY, env={"API_TOKEN": "x"})
    first = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(first.pid)
    done = robotconf("restart", ROBOT, broker=mosquitto)
    assert done.returncode == 0, done.stderr
    again = new_brain(watch, agent, first.pid)
    assert again.digest == request.digest and again.restart_requested_by is not None


def test_restart_is_refused_for_unknown_idle_and_offline_robots(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    unknown = robotconf("restart", "tb3-99", broker=mosquitto)
    assert unknown.returncode == 1 and "unknown robot 'tb3-99'" in unknown.stderr
    agent = make_agent().start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    idle = robotconf("restart", ROBOT, broker=mosquitto)
    assert idle.returncode == 1 and "nothing to restart" in idle.stderr
    agent.signal(signal.SIGTERM)
    agent.wait()
    watch.wait_state(ROBOT, AgentState.OFFLINE)
    offline = robotconf("restart", ROBOT, broker=mosquitto)
    assert offline.returncode == 1 and "is offline" in offline.stderr
    for done in (unknown, idle, offline):
        assert "Traceback" not in done.stderr


def test_a_verifying_agent_restarts_only_for_a_fresh_signed_request(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    keys = generate_keys(tmp_path / "keys")
    private = load_private_key(keys.private)
    agent = make_agent(command=CHATTY, env={"API_TOKEN": "x"}, public_key=str(keys.public))
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    request = sign(make_request(), private)
    publish(mosquitto.url, TOPICS.launch(ROBOT), request.payload())
    first = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(first.pid)
    restarts = Listener(mosquitto, TOPICS.restart(ROBOT))
    try:
        unsigned = robotconf("restart", ROBOT, "--wait", "3", broker=mosquitto)
        assert unsigned.returncode == 1 and "did not confirm" in unsigned.stderr
        wait_for(lambda: "restart refused: restart is not signed" in agent.log_tail(100), "why")

        signed = robotconf(
            "restart", ROBOT, "--signing-key", str(keys.private), "--as", "ops", broker=mosquitto
        )
        assert signed.returncode == 0, signed.stderr
        second = new_brain(watch, agent, first.pid)
        assert second.restart_requested_by == "ops"
        # The signed restart, replayed as it was captured, and forged: nothing happens.
        captured = restarts.taken()[-1][1]
        publish(mosquitto.url, TOPICS.restart(ROBOT), captured, retain=False)
        forged = json.loads(captured)
        forged["issued_at"] = time.time()
        forged_bytes = RestartRequest.model_validate(forged).payload()
        publish(mosquitto.url, TOPICS.restart(ROBOT), forged_bytes, retain=False)
        wait_for(lambda: "not newer than the last one" in agent.log_tail(100), "the replay")
        wait_for(lambda: "signature does not verify" in agent.log_tail(100), "the forgery")
        time.sleep(1.0)
        latest = watch.latest(ROBOT)
        assert latest is not None and latest.pid == second.pid
        assert latest.state is AgentState.RUNNING
    finally:
        restarts.close()


@pytest.mark.parametrize("name", ["", "alice; rm -rf /", "x" * 65])
def test_restart_refuses_a_requester_name_that_cannot_be_recorded(
    mosquitto: Mosquitto, name: str
) -> None:
    done = robotconf("restart", ROBOT, "--as", name, broker=mosquitto)
    assert done.returncode == 2 and "cannot name who asks" in done.stderr


def test_garbage_restart_requests_restart_nothing(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    topic = TOPICS.restart(ROBOT)
    # Retained before the agent connects: it comes with the retain flag, and is refused (a
    # live subscriber gets a new message without the flag, as MQTT delivers it).
    stale = RestartRequest(robot_id=ROBOT, requested_by="ops", issued_at=round(time.time(), 6))
    publish(mosquitto.url, topic, stale.payload(), retain=True)
    agent, request = run_brain(make_agent, watch, mosquitto, CHATTY, env={"API_TOKEN": "x"})
    first = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(first.pid)
    wait_for(lambda: "it came retained" in agent.log_tail(200), "the retained one refused")
    publish(mosquitto.url, topic, b"", retain=True)
    for payload in (
        b"[" * 100_000,
        b"\xff\xfe\x00",
        b"x" * 2_000_000,
        RestartRequest(robot_id="tb3-02", requested_by="ops", issued_at=time.time()).payload(),
        RestartRequest(robot_id=ROBOT, requested_by="ops", issued_at=time.time() - 3600).payload(),
        b'{"apiVersion": "robotconf/v1", "kind": "Restart", "robot_id": "tb3-01"}',
    ):
        publish(mosquitto.url, topic, payload, retain=False)
    # Refusals are logged a few per 10 s (anyone who may publish here could fill the disk).
    wait_for(lambda: agent.log_tail(200).count("restart refused") >= 4, "the refusals")
    latest = watch.latest(ROBOT)
    assert latest is not None and latest.pid == first.pid and latest.restart_requested_by is None
    assert agent.proc is not None and agent.proc.poll() is None
    assert "Traceback" not in agent.log_tail(400)
    # Still served: a good one afterwards restarts the brain.
    done = robotconf("restart", ROBOT, "--as", "ops", broker=mosquitto)
    assert done.returncode == 0, done.stderr
    new_brain(watch, agent, first.pid)


# ---------------------------------------------------------------- fairness and clocks

# Writes 300 numbered lines at once, then a tick five times a second: a log worth polling.
WORDY = [
    sys.executable,
    "-u",
    "-c",
    "import time\n"
    "print(''.join('early %d\\n' % n for n in range(300)), end='')\n"
    "n = 0\n"
    "while True:\n"
    "    print('tick', n)\n"
    "    n += 1\n"
    "    time.sleep(0.2)\n",
    "{launch_request}",
]


class Poller:
    """A dashboard: asks for the last `lines` four times a second, over one session or a new
    one per ask, and counts the tails it got whole (their `end`)."""

    def __init__(self, broker: Mosquitto, lines: int, fresh_sessions: bool) -> None:
        self.lines = lines
        self.fresh_sessions = fresh_sessions
        self.asked = 0
        self.ends = 0
        self._sessions: set[str] = set()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self.client = make_client(Connection(url=broker.url), f"dashboard-{time.monotonic_ns()}")
        subscribed = threading.Event()

        def on_connect(c: paho.Client, u: Any, f: Any, rc: Any, p: Any) -> None:
            c.subscribe(TOPICS.logs(ROBOT), qos=1)

        def on_subscribe(c: paho.Client, u: Any, mid: Any, rc: Any, p: Any) -> None:
            subscribed.set()

        def on_message(c: paho.Client, u: Any, msg: paho.MQTTMessage) -> None:
            chunk = json.loads(msg.payload)
            with self._lock:
                if chunk.get("end") and chunk.get("session") in self._sessions:
                    self.ends += 1

        self.client.on_connect = on_connect
        self.client.on_subscribe = on_subscribe
        self.client.on_message = on_message
        self.client.connect(broker.host, broker.port)
        self.client.loop_start()
        assert subscribed.wait(TIMEOUT)
        self._thread = threading.Thread(target=self._poll, daemon=True)
        self._thread.start()

    def _poll(self) -> None:
        n = 0
        while not self._stop.wait(0.25):
            session = f"dash{n}" if self.fresh_sessions else "dash"
            n += 1
            with self._lock:
                self._sessions.add(session)
                self.asked += 1
            payload = json.dumps({"session": session, "lines": self.lines}).encode()
            self.client.publish(TOPICS.logs_request(ROBOT), payload, qos=1)

    def answered(self) -> int:
        with self._lock:
            return self.ends

    def close(self) -> None:
        self._stop.set()
        self._thread.join(TIMEOUT)
        self.client.disconnect()
        self.client.loop_stop()


@pytest.mark.parametrize("fresh_sessions", [False, True], ids=["one-session", "new-sessions"])
def test_a_polling_dashboard_does_not_starve_an_operators_tail(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, fresh_sessions: bool
) -> None:
    agent, request = run_brain(make_agent, watch, mosquitto, WORDY)
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    wait_for(lambda: "early 299" in agent.brain_log(), "the brain's first lines")
    dashboard = Poller(mosquitto, lines=50, fresh_sessions=fresh_sessions)
    try:
        # The dashboard asks for more than the robot sends (200 lines a second): let its
        # backlog build before the operator asks, and go on asking while the operator does.
        wait_for(lambda: dashboard.asked >= 12 and dashboard.answered() >= 2, "dashboard tails")
        for attempt in range(5):
            done = robotconf("logs", ROBOT, "-n", "5", broker=mosquitto)
            assert done.returncode == 0, (attempt, done.stderr, agent.log_tail(40))
            assert len(done.stdout.splitlines()) == 5, (attempt, done.stdout)
        # The dashboard is served too, at its share.
        before = dashboard.answered()
        wait_for(lambda: dashboard.answered() > before, "the dashboard's next tail")
    finally:
        dashboard.close()
    assert agent.proc is not None and agent.proc.poll() is None


def replays_refused(
    mosquitto: Mosquitto,
    watch: FleetWatch,
    agent: Any,
    replays: tuple[bytes, bytes],
    current: AgentStatus,
) -> None:
    """Two restarts carried out before, published again: both refused, the brain still the
    one running as `current`."""
    refusals_before = agent.log_tail(400).count("restart refused")
    for payload in replays:
        publish(mosquitto.url, TOPICS.restart(ROBOT), payload, retain=False)
    wait_for(
        lambda: agent.log_tail(400).count("restart refused") >= refusals_before + 2,
        "both replays refused",
    )
    latest = watch.latest(ROBOT)
    assert latest is not None and latest.pid == current.pid, latest
    assert latest.state is AgentState.RUNNING


def test_a_restart_dated_ahead_locks_out_no_later_restart_and_replays_stay_refused(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    keys = generate_keys(tmp_path / "keys")
    private = load_private_key(keys.private)
    agent = make_agent(command=CHATTY, env={"API_TOKEN": "x"}, public_key=str(keys.public))
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    request = sign(make_request(), private)
    publish(mosquitto.url, TOPICS.launch(ROBOT), request.payload())
    first = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(first.pid)

    # A desk whose clock runs four minutes fast: within the five minutes either way, so done.
    ahead = sign(
        RestartRequest(robot_id=ROBOT, requested_by="fastdesk", issued_at=0),
        private,
        time.time() + 240,
    ).payload()
    publish(mosquitto.url, TOPICS.restart(ROBOT), ahead, retain=False)
    second = new_brain(watch, agent, first.pid)
    assert second.restart_requested_by == "fastdesk"

    # Then an operator with a correct clock: carried out, not refused as older.
    restarts = Listener(mosquitto, TOPICS.restart(ROBOT))
    try:
        done = robotconf(
            "restart", ROBOT, "--signing-key", str(keys.private), "--as", "ops", broker=mosquitto
        )
        assert done.returncode == 0, (done.stderr, agent.log_tail(40))
        third = new_brain(watch, agent, second.pid)
        assert third.restart_requested_by == "ops"
        genuine = restarts.taken()[-1][1]
    finally:
        restarts.close()

    replays_refused(mosquitto, watch, agent, (ahead, genuine), third)

    # A dead robot is a killed agent: what it remembers of the restarts survives it.
    assert agent.proc is not None
    agent.proc.kill()
    agent.proc.wait()
    agent.start()
    fourth = new_brain(watch, agent, third.pid)  # the orphan stopped, the request again
    replays_refused(mosquitto, watch, agent, (ahead, genuine), fourth)
    # And nobody is locked out: the next genuine restart is carried out.
    done = robotconf(
        "restart", ROBOT, "--signing-key", str(keys.private), "--as", "ops2", broker=mosquitto
    )
    assert done.returncode == 0, (done.stderr, agent.log_tail(40))
    assert new_brain(watch, agent, fourth.pid).restart_requested_by == "ops2"


# Prints a private key's first lines, waits for a file named `go` (the test makes it once a
# follower listens), then the rest of the key, the API token in the forms programs print
# secrets in, and a tick a second.
KEY_BODY = [
    f"MIIEv{n:02d}QIBADANBgkqhkiG9w0BAQEFAASCBKcwggSjAgEAAoIBAQC7{n:02d}" for n in range(20)
]
KEYED = [
    sys.executable,
    "-u",
    "-c",
    "import base64, json, os, time, urllib.parse\n"
    f"body = {KEY_BODY!r}\n"
    "print('-----BEGIN PRIVATE KEY-----')\n"
    "print('\\n'.join(body[:5]))\n"
    "while not os.path.exists('go'):\n"
    "    time.sleep(0.05)\n"
    "print('\\n'.join(body[5:]))\n"
    "print('-----END PRIVATE KEY-----')\n"
    "print('after the key')\n"
    "token = os.environ['API_TOKEN']\n"
    "print('url', urllib.parse.quote(token, safe=''))\n"
    "print('json', json.dumps({'token': token}))\n"
    "print('b64', base64.b64encode(token.encode()).decode())\n"
    "print('colour', token[:5] + '\\x1b[31m' + token[5:] + '\\x1b[0m')\n"
    "n = 0\n"
    "while True:\n"
    "    print('tick', n)\n"
    "    n += 1\n"
    "    time.sleep(1)\n",
    "{launch_request}",
]
TRICKY = 'p@ss/w0rd+"quoted" &more'


def test_no_window_of_the_log_shows_a_key_or_an_encoded_secret(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    import base64
    import urllib.parse

    agent, request = run_brain(make_agent, watch, mosquitto, KEYED, env={"API_TOKEN": TRICKY})
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    wait_for(lambda: KEY_BODY[4] in agent.brain_log(), "the key's first lines")
    forms = [
        TRICKY,
        urllib.parse.quote(TRICKY, safe=""),
        json.dumps(TRICKY)[1:-1],
        base64.b64encode(TRICKY.encode()).decode(),
    ]
    follower = subprocess.Popen(
        [str(ROBOTCONF), "logs", ROBOT, "-f", "-n", "0", "--broker", mosquitto.url],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        # The stream starts inside the key: the agent knows it, and shows none of the rest.
        wait_for(lambda: "streaming the brain's log" in agent.log_tail(200), "the follower")
        (agent.workdir / "go").touch()
        assert follower.stdout is not None
        streamed: list[str] = []
        deadline = time.monotonic() + TIMEOUT
        while not any(line.startswith("tick") for line in streamed):
            assert time.monotonic() < deadline and follower.poll() is None, streamed
            streamed.append(follower.stdout.readline().rstrip("\n"))
        follower.send_signal(signal.SIGINT)
        assert follower.wait(TIMEOUT) == 0
    finally:
        if follower.poll() is None:
            follower.kill()
        follower.communicate()
    assert "after the key" in streamed and "[redacted]" in streamed
    shown = "\n".join(streamed)
    assert not [b for b in KEY_BODY if b in shown], shown
    assert not [f for f in forms if f in shown] and "\x1b" not in shown, shown
    assert [line.split()[0] for line in streamed[-5:-1]] == ["url", "json", "b64", "colour"]
    assert all("[redacted]" in line for line in streamed[-5:-1]), streamed
    # Tails of every length, begun anywhere inside the key or after it.
    log_lines = len(agent.brain_log().splitlines())
    for count in (1, 3, 8, 14, 20, 26, 30, log_lines):
        done = robotconf("logs", ROBOT, "-n", str(count), broker=mosquitto)
        assert done.returncode == 0, done.stderr
        assert not [b for b in KEY_BODY if b in done.stdout], (count, done.stdout)
        assert not [f for f in forms if f in done.stdout], (count, done.stdout)
    assert all(b in agent.brain_log() for b in KEY_BODY)  # the file keeps everything
