"""`robotconf up` as a user runs it: a subprocess, stopped with Ctrl-C (SIGINT), SIGTERM, SIGHUP,
a closed terminal or SIGKILL; what it runs never outlives it."""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
import pty
import re
import select
import signal
import socket
import subprocess
import termios
import threading
import urllib.request
from collections.abc import Iterator
from functools import partial
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
import pytest
import yaml
from paho.mqtt.enums import CallbackAPIVersion

from robotconf.agent.config import parse_config
from robotconf.contract.mqtt import Connection
from robotconf.reconciler.desired import load_desired
from robotconf.workstation.broker import EmbeddedBroker, free_port
from robotconf.workstation.broker_login import broker_login
from robotconf.workstation.up import agent_yaml, prepare
from tests.support.fleet import GitLab, Proc, robotconf_argv
from tests.support.mosquitto import Mosquitto
from tests.support.private import write_private
from tests.support.watch import FleetWatch, wait_for


@contextlib.contextmanager
def port_1883_taken() -> Iterator[bool]:
    """Holds 127.0.0.1:1883 when it can; True when this test is the one holding it."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        try:
            sock.bind(("127.0.0.1", 1883))
            sock.listen(1)
            held = True
        except OSError:
            held = False  # someone else has it: taken all the same
        yield held
    finally:
        sock.close()


def processes_mentioning(text: str) -> list[int]:
    """Agents and brains run from `text` (a folder); not the stand-in `ros2` an agent runs
    for a moment every interfaces reading (it ends by itself)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        with contextlib.suppress(OSError):
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            stat = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
            if text in cmdline and stat != "Z" and "/bin/ros2 " not in cmdline:
                found.append(int(entry.name))
    return found


# A test of up's processes, signals and lines needs two robots (the whole example lab is
# tested in test_up_runs_the_whole_loop_and_stops_cleanly), not six agents and brains starting.
TWO_ROBOTS = pytest.mark.robots("tb3-01", "tb3-02")


def start_up(lab: GitLab, tmp_path: Path, *extra: str, log: str = "up.out") -> Proc:
    return Proc(robotconf_argv("up", "--repo", str(lab.root), *extra), tmp_path / log, cwd=lab.root)


def _says(log: Path, text: str) -> bool:
    return text in log.read_text()


def up_folder(lab: GitLab) -> str:
    return str(lab.root / ".robotconf" / "up")


def in_sync(up: Proc, lab: GitLab) -> None:
    wait_for(lambda: "all robots InSync" in up.output(), "up to report InSync")
    # An agent and a brain a robot.
    assert len(processes_mentioning(up_folder(lab))) == 2 * len(lab.robots())


def none_left(folder: str) -> None:
    """Waits (bounded) until no process runs from `folder`, and says which do if some still do."""
    with contextlib.suppress(AssertionError):
        wait_for(lambda: not processes_mentioning(folder), "every agent and brain to end")
    assert processes_mentioning(folder) == [], "still running from " + folder


def test_up_runs_the_whole_loop_and_stops_cleanly(lab: GitLab, tmp_path: Path) -> None:
    lab.replace("configs/scenarios/guide-gazebo.yaml", "goal_tolerance: 0.2", "goal_tolerance: 0.3")
    # The login an earlier `up` made for a robot that has left fleet.yaml since.
    stale = Path(up_folder(lab)) / "broker" / "tb3-99.password"
    stale.parent.mkdir(parents=True)
    stale.write_text("left-over\n")
    with port_1883_taken() as held:
        up = start_up(lab, tmp_path)
        try:
            wait_for(lambda: "all robots InSync" in up.output(), "up to report InSync")
            out = up.output()
            if held:
                assert "port 1883 is taken" in out
            assert "uncommitted change(s) in configs/ or models/ are NOT applied" in out
            match = re.search(r"embedded amqtt at (mqtt://[\d.]+:\d+)", out)
            assert match, out
            url = match.group(1)
            # The options it prints are the ones that work: the broker takes no one else.
            password = Path(up_folder(lab)) / "broker" / "operator.password"
            login = ["--username", "operator", "--password-file", str(password)]
            assert "another terminal: robotconf status    robotconf logs ROBOT" in out
            assert oct(password.stat().st_mode & 0o777) == "0o600"
            assert not stale.exists()
            assert "logins removed of robots no longer in the fleet: tb3-99" in out

            def run(*argv: str) -> subprocess.CompletedProcess[str]:
                return subprocess.run(
                    robotconf_argv(*argv, "--broker", url),
                    capture_output=True,
                    text=True,
                    timeout=60,
                )

            status = run("status", "--repo", str(lab.root), *login)
            assert status.returncode == 0, status.stdout + status.stderr
            assert len(re.findall(r"^tb3-0\d\s+InSync\s", status.stdout, re.M)) == 6
            logs = run("logs", "tb3-01", "--lines", "5", *login)
            assert logs.returncode == 0 and logs.stdout.strip(), logs.stdout + logs.stderr
            # Any other user of the machine can reach 127.0.0.1, but not read a robot's log.
            spy = run("logs", "tb3-01", "--lines", "5")
            assert spy.returncode != 0 and logs.stdout.strip() not in spy.stdout, spy.stdout

            # A commit while it runs is rolled out too (the uncommitted edit goes with it).
            head = lab.commit("looser guide")
            wait_for(lambda: f"all robots InSync with {head[:12]}" in up.output(), "the new commit")
            workdir = str(lab.root / ".robotconf" / "up")
            assert len(processes_mentioning(workdir)) >= 12  # six agents, six brains
        finally:
            code = up.stop(signal.SIGINT, timeout=60)
    assert code == 0, up.output()
    assert "stopped" in up.output()
    assert processes_mentioning(workdir) == []
    assert "Traceback" not in up.output()
    log = (lab.root / ".robotconf" / "up" / "up.log").read_text(encoding="utf-8")
    assert " ERROR " not in log and "Traceback" not in log, log


@TWO_ROBOTS
def test_up_with_an_existing_broker(lab: GitLab, tmp_path: Path, mosquitto: Mosquitto) -> None:
    up = start_up(lab, tmp_path, "--broker", mosquitto.url)
    try:
        wait_for(lambda: "all robots InSync" in up.output(), "up to report InSync")
        watch = FleetWatch(mosquitto.url)
        try:
            status = watch.reconciler()
            assert status is not None and status.last_applied_revision == lab.head()
            assert watch.running(lab.requests()) is not None
        finally:
            watch.close()
    finally:
        code = up.stop(signal.SIGINT, timeout=60)
    assert code == 0, up.output()
    assert "amqtt" not in up.output()


def test_up_refuses_a_folder_that_is_not_a_git_repository(tmp_path: Path) -> None:
    lab = tmp_path / "plain"
    lab.mkdir()
    (lab / "configs").mkdir()
    done = subprocess.run(
        robotconf_argv("up", "--repo", str(lab)), capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 2
    assert "not a git repository" in done.stderr and "git init" in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize("branch", ["nope"])
def test_up_names_a_missing_branch(lab: GitLab, branch: str) -> None:
    done = subprocess.run(
        robotconf_argv("up", "--repo", str(lab.root), "--branch", branch),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert f"branch '{branch}' does not exist" in done.stderr


def test_the_generated_agent_yaml_is_valid_with_credentials_and_tls(
    lab: GitLab, tmp_path: Path
) -> None:
    secrets = {}
    for name in ("password", "ca.crt", "client.crt", "client.key"):
        secrets[name] = tmp_path / name
        write_private(secrets[name], "x\n")
    connection = Connection(
        url="mqtts://broker.lab:8883",
        username="lab",
        password_file=secrets["password"],
        ca_file=secrets["ca.crt"],
        cert_file=secrets["client.crt"],
        key_file=secrets["client.key"],
    )
    fleet = lab.requests()

    render = load_desired(lab.root, lab.head()).fleet
    assert render is not None
    settings = agent_yaml(render, "tb3-01", tmp_path / "work", connection, "robotconf")
    config = parse_config(yaml.safe_dump(settings), "agent.yaml", base=tmp_path)
    assert config.robot_id == "tb3-01"
    assert config.description.recommended_template == (fleet["tb3-01"].robot_template)
    assert config.connection().address.tls and config.username == "lab"
    assert config.tls is not None and config.tls.ca_file == secrets["ca.crt"]


@TWO_ROBOTS
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_stop_signal_stops_every_agent_and_brain(
    lab: GitLab, tmp_path: Path, sig: signal.Signals
) -> None:
    up = start_up(lab, tmp_path)
    try:
        in_sync(up, lab)
    finally:
        code = up.stop(sig, timeout=60)
    assert code == 0, up.output()
    assert "stopped" in up.output() and "Traceback" not in up.output()
    # up waits for its agents, and each agent for its brain: nothing is left, at once.
    assert processes_mentioning(up_folder(lab)) == []


class Terminal:
    """A pseudo-terminal that becomes a process's controlling terminal, as a shell's is, so
    that closing it hangs the process up for real; what is drawn on it is kept."""

    def __init__(self) -> None:
        self.master, self.slave = pty.openpty()
        self.screen = bytearray()
        self._stop = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        # select, not a blocking read: a read in progress would keep the master open after
        # close() and the hangup would never happen.
        while not self._stop.is_set():
            if select.select([self.master], [], [], 0.1)[0]:
                try:
                    self.screen.extend(os.read(self.master, 65536))
                except OSError:
                    return

    def run(self, argv: list[str], cwd: Path) -> subprocess.Popen[bytes]:
        proc = subprocess.Popen(
            argv,
            stdin=self.slave,
            stdout=self.slave,
            stderr=self.slave,
            cwd=cwd,
            start_new_session=True,
            preexec_fn=lambda: fcntl.ioctl(0, termios.TIOCSCTTY, 0),
        )
        os.close(self.slave)
        return proc

    def close(self) -> None:
        """The terminal window is closed."""
        if not self._stop.is_set():
            self._stop.set()
            self._reader.join()
            os.close(self.master)


@TWO_ROBOTS
def test_closing_the_terminal_stops_everything(lab: GitLab, tmp_path: Path) -> None:
    """up on a terminal (the live screen) whose terminal goes away: the kernel's SIGHUP, then
    every write failing. The refused commit is drawn on the live screen, framed."""
    terminal = Terminal()
    up = terminal.run(robotconf_argv("up", "--repo", str(lab.root)), lab.root)
    try:
        screen = terminal.screen
        wait_for(lambda: b"all robots InSync" in screen, "the live screen to report InSync")
        assert b"tb3-02" in screen  # the fleet is drawn, not said as lines
        assert len(processes_mentioning(up_folder(lab))) == 2 * len(lab.robots())
        lab.replace("configs/scenarios/guide-gazebo.yaml", "capability: ", "capability: nope-")
        bad = lab.commit("typo")
        # Framed above the robots on the live screen, not only said in a line over it.
        wait_for(lambda: b"commit refused" in screen, "the live screen to show the refusal")
        assert f"REFUSED: commit {bad[:12]}".encode() in screen
        terminal.close()
        assert up.wait(60) == 0  # up stopped itself: SIGHUP did not just kill it
    finally:
        terminal.close()
        if up.poll() is None:
            up.kill()
            up.wait()
    none_left(up_folder(lab))
    log = (lab.root / ".robotconf" / "up" / "up.log").read_text(encoding="utf-8")
    assert "Traceback" not in log


@TWO_ROBOTS
def test_a_killed_up_takes_its_agents_and_brains_along_and_the_next_starts_cleanly(
    lab: GitLab, tmp_path: Path
) -> None:
    folder = up_folder(lab)
    first = start_up(lab, tmp_path, log="first.out")
    try:
        in_sync(first, lab)
        # Each brain past its start-up (it says what it runs): a brain killed while Python
        # still starts cannot stop cleanly, and a loaded run got there within a second.
        for robot_id in lab.robots():
            log = lab.root / ".robotconf" / "up" / robot_id / "brain.log"
            wait_for(partial(_says, log, "stand-in brain for"), f"{robot_id}'s brain up")
        os.kill(first.pid, signal.SIGKILL)  # up alone: no chance to stop anything itself
        first.popen.wait()
        none_left(folder)
    finally:
        first.kill()
    for robot_id in lab.robots():
        robot = lab.root / ".robotconf" / "up" / robot_id
        # Each agent stopped its brain cleanly (not killed): it was told that up died.
        assert "SIGHUP received: stopping" in (robot / "agent.log").read_text(), robot_id
        assert "SIGTERM received, stopping" in (robot / "brain.log").read_text(), robot_id

    second = start_up(lab, tmp_path, log="second.out")
    try:
        in_sync(second, lab)
    finally:
        code = second.stop(signal.SIGINT, timeout=60)
    assert code == 0, second.output()
    assert "Traceback" not in second.output() and "left running" not in second.output()


@TWO_ROBOTS
def test_up_stops_an_agent_a_previous_up_left_running(lab: GitLab, tmp_path: Path) -> None:
    """Where no parent-death signal stopped it (another OS, or an agent still stopping): its
    work directory's lock names it, and the next up stops it before starting its own."""
    first = start_up(lab, tmp_path, log="first.out")
    try:
        in_sync(first, lab)
    finally:
        assert first.stop(signal.SIGINT, timeout=60) == 0, first.output()
    robot = lab.root / ".robotconf" / "up" / "tb3-01"
    left = start_agent_from(robot, tmp_path)
    try:
        wait_for(lambda: (robot / "agent.lock").read_text().strip() == str(left.pid), "its lock")
        second = start_up(lab, tmp_path, log="second.out")
        try:
            in_sync(second, lab)
            out = second.output()
            assert f"stopping agent pid {left.pid} left running in {robot}" in out, out
            assert not left.alive()
        finally:
            assert second.stop(signal.SIGINT, timeout=60) == 0, second.output()
    finally:
        left.kill()
    assert processes_mentioning(up_folder(lab)) == []


def start_agent_from(robot: Path, tmp_path: Path, config: Path | None = None) -> Proc:
    """The agent of an earlier up's robot, started by hand (so not told to die with any up)."""
    config = config or robot / "agent.yaml"
    return Proc(robotconf_argv("agent", "--config", str(config)), tmp_path / "left.out")


@TWO_ROBOTS
def test_up_leaves_alone_an_agent_it_did_not_start(lab: GitLab, tmp_path: Path) -> None:
    """An agent of the same work directory run from another agent.yaml (a robot's own, say)
    is not up's to stop: up says so and starts nothing."""
    first = start_up(lab, tmp_path, log="first.out")
    try:
        in_sync(first, lab)
    finally:
        assert first.stop(signal.SIGINT, timeout=60) == 0, first.output()
    robot = lab.root / ".robotconf" / "up" / "tb3-01"
    own = tmp_path / "own-agent.yaml"
    own.write_text((robot / "agent.yaml").read_text(encoding="utf-8"), encoding="utf-8")
    other = start_agent_from(robot, tmp_path, own)
    try:
        wait_for(lambda: (robot / "agent.lock").read_text().strip() == str(other.pid), "its lock")
        done = subprocess.run(
            robotconf_argv("up", "--repo", str(lab.root)),
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 2, done.stdout + done.stderr
        assert f"another agent (pid {other.pid}) is using {robot}" in done.stderr
        assert other.alive()
    finally:
        other.stop()
    assert processes_mentioning(up_folder(lab)) == []


def events(lab: GitLab, kind: str) -> str:
    """The revisions of `kind` events `robotconf events --json` reads in up's folder."""
    done = subprocess.run(
        robotconf_argv("events", "--repo", str(lab.root), "--kind", kind, "--json"),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "Traceback" not in done.stdout + done.stderr, done.stderr
    return " ".join(str(e.get("revision")) for e in json.loads(done.stdout or "[]"))


@TWO_ROBOTS
def test_a_refused_commit_is_said_in_the_line_output(lab: GitLab, tmp_path: Path) -> None:
    up = start_up(lab, tmp_path)
    try:
        in_sync(up, lab)
        good = lab.head()
        lab.replace(
            "configs/scenarios/delivery-gazebo.yaml",
            "capability: turtlebot3-camera",
            "capability: nope",
        )
        bad = lab.commit("typo")
        said = f"REFUSED: commit {bad[:12]} of 'main' is not applied (BuildFailed); "
        wait_for(lambda: said in up.output(), "up to say the commit is refused")
        out = up.output()
        after = out[out.index(said) :].splitlines()
        assert f"the robots keep {good[:12]}" in after[0], after[0]
        # The first diagnostics follow, each naming its file: what to fix, without a search.
        assert "delivery-gazebo.yaml" in after[1] and "nope" in after[1], after[:4]
        # up keeps the timeline as the reconciler does: `robotconf events` finds it.
        wait_for(lambda: bad in events(lab, "commit_refused"), "the refusal in the timeline")
        assert good in events(lab, "commit_applied")
    finally:
        assert up.stop(signal.SIGINT, timeout=60) == 0, up.output()
    assert out.count(said) == 1  # said once, not at every status change


def test_the_embedded_broker_takes_many_clients_at_once_without_an_error(tmp_path: Path) -> None:
    """amqtt 0.11/0.12 raised "dictionary changed size during iteration" when a client
    connected while others subscribed (workstation/broker.py): up's six agents did, at most
    starts. Thirty clients with five subscriptions each make it happen at every run."""
    errors: list[logging.LogRecord] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            errors.append(record)

    keep = Keep(logging.ERROR)
    logging.getLogger().addHandler(keep)
    broker = EmbeddedBroker(broker_login(tmp_path), port=free_port("127.0.0.1"))
    broker.start()
    # The reconciler's login: it writes and reads every robot's launch topic (topics.py).
    password = broker_login(tmp_path, "reconciler").password()
    clients: list[paho.Client] = []
    try:
        publisher = paho.Client(CallbackAPIVersion.VERSION2)
        publisher.username_pw_set("reconciler", password)
        publisher.connect("127.0.0.1", broker.port)
        publisher.loop_start()
        clients.append(publisher)
        for n in range(50):
            topic = f"robotconf/robots/r{n}/launch"
            publisher.publish(topic, "x", qos=1, retain=True).wait_for_publish(10)
        subscribed = threading.Semaphore(0)

        def on_connect(client: paho.Client, first: Any, *_: Any) -> None:
            client.subscribe(
                [(f"robotconf/robots/r{n}/launch", 0) for n in range(first, first + 5)]
            )

        def on_subscribe(*_: Any) -> None:
            subscribed.release()

        def connect(n: int) -> None:
            client = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"c{n}", userdata=n)
            client.username_pw_set("reconciler", password)
            client.on_connect = on_connect
            client.on_subscribe = on_subscribe
            client.connect("127.0.0.1", broker.port)
            client.loop_start()
            clients.append(client)

        starting = [threading.Thread(target=connect, args=(n,)) for n in range(30)]
        for thread in starting:
            thread.start()
        for thread in starting:
            thread.join()
        for _ in starting:  # each client connected and subscribed: none was dropped
            assert subscribed.acquire(timeout=30), [r.getMessage() for r in errors]
    finally:
        for client in clients:
            client.loop_stop()
            client.disconnect()
        broker.stop()
        logging.getLogger().removeHandler(keep)
    assert [r.getMessage() for r in errors] == []


class Client:
    """A paho client of the embedded broker; what its CONNACKs said and what it received."""

    def __init__(
        self, port: int, client_id: str, password: str | None = None, user: str = "operator"
    ) -> None:
        self.connacks: list[Any] = []
        self.received: list[bytes] = []
        self.subscribed = threading.Event()
        self.paho = paho.Client(CallbackAPIVersion.VERSION2, client_id=client_id)
        if password is not None:
            self.paho.username_pw_set(user, password)
        self.paho.on_connect = lambda c, u, f, code, p: self.connacks.append(code)
        self.paho.on_message = lambda c, u, message: self.received.append(message.payload)
        self.paho.on_subscribe = lambda *_: self.subscribed.set()
        self.paho.connect("127.0.0.1", port)
        self.paho.loop_start()
        wait_for(lambda: self.connacks, f"{client_id}'s CONNACK")

    @property
    def refused(self) -> bool:
        return bool(self.connacks[0].is_failure)

    def close(self) -> None:
        self.paho.loop_stop()
        self.paho.disconnect()


def test_the_embedded_broker_takes_only_up_s_login(tmp_path: Path) -> None:
    """Every local user can reach 127.0.0.1: without up's login a client reads no robot's log
    request and, with an agent's client id, does not knock that agent off its subscriptions (amqtt
    alone would drop them before refusing it); a client that never sends its CONNECT is closed."""
    login = broker_login(tmp_path / "broker")
    assert oct((tmp_path / "broker").stat().st_mode & 0o777) == "0o700"
    broker = EmbeddedBroker(login, port=free_port("127.0.0.1"), connect_timeout=1.0)
    broker.start()
    password = login.password()
    robot = broker_login(tmp_path / "broker", "tb3-01").password()  # the agent's, as up makes it
    clients: list[Client] = []
    try:
        agent = Client(broker.port, "robotconf-agent-tb3-01", robot, user="tb3-01")
        clients.append(agent)
        assert not agent.refused
        agent.paho.subscribe("robotconf/robots/tb3-01/logs/request", qos=1)
        assert agent.subscribed.wait(30)
        spy = Client(broker.port, "spy")
        thief = Client(broker.port, "robotconf-agent-tb3-01")
        guess = Client(broker.port, "guess", password[:-1])
        clients += [spy, thief, guess]
        assert spy.refused and thief.refused and guess.refused
        spy.paho.subscribe("robotconf/robots/+/logs/request", qos=1)

        operator = Client(broker.port, "operator", password)
        clients.append(operator)
        operator.paho.publish("robotconf/robots/tb3-01/logs/request", b"a request", qos=1)
        wait_for(lambda: agent.received, "the agent, still subscribed, to get the request")
        assert agent.received == [b"a request"]
        assert spy.received == [] and thief.received == []

        with socket.create_connection(("127.0.0.1", broker.port)) as silent:
            silent.settimeout(60)
            assert silent.recv(16) == b""  # closed by the broker, never by us
    finally:
        for client in clients:
            client.close()
        broker.stop()


def test_up_builds_its_head_once_and_hands_that_build_to_the_reconciler(lab: GitLab) -> None:
    """`up` checks the head before starting anything; the controller's own first build of
    it then reuses every file and every robot (no second full build at start)."""
    setup = prepare(lab.root, "main", None)
    assert setup.head == lab.first and setup.fleet.requests
    first = setup.builder.cache.stats
    assert first.files_parsed > 0 and first.robots_rendered == len(setup.fleet.requests)
    again = setup.builder(lab.root, setup.head)
    stats = setup.builder.cache.stats
    assert stats.files_parsed == 0 and stats.robots_rendered == 0 and not stats.units_run
    assert again.fleet is not None
    assert {r: q.payload() for r, q in again.fleet.requests.items()} == {
        r: q.payload() for r, q in setup.fleet.requests.items()
    }


def test_up_serves_the_fleet_page_when_asked(lab: GitLab, tmp_path: Path) -> None:
    port = free_port("127.0.0.1")
    up = start_up(lab, tmp_path, "--ui", f"127.0.0.1:{port}")
    try:
        wait_for(lambda: "all robots InSync" in up.output(), "up to report InSync")
        assert f"ui: the fleet's web page is at http://127.0.0.1:{port}/" in up.output()

        def page() -> str | None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10) as answer:
                    body: str = answer.read().decode()
            except OSError:
                return None
            synced = re.findall(r'<tr data-robot="tb3-0\d" data-verdict="InSync"', body)
            return body if len(synced) == 6 else None

        body = wait_for(page, "the fleet page with every robot InSync")
        assert 'data-reconciler-state="Ready"' in body
    finally:
        code = up.stop(signal.SIGINT, timeout=60)
    assert code == 0, up.output()
    assert "Traceback" not in up.output()
