"""`robotconf broker-config` against a real Mosquitto: ACLs, passwords, anonymous, TLS."""

from __future__ import annotations

import json
import subprocess
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import paho.mqtt.client as paho
import pytest

from robotconf.contract.mqtt import Connection, make_client
from tests.support.lab import ROBOTCONF, ROOT
from tests.support.private import write_private
from tests.support.secure import Secured, start_secured

WAIT = 10.0


@pytest.fixture(scope="module")
def broker(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Secured]:
    secured = start_secured(tmp_path_factory.mktemp("secured"), ROOT)
    try:
        yield secured
    finally:
        secured.server.kill()


@dataclass
class Session:
    client: paho.Client
    connected: threading.Event = field(default_factory=threading.Event)
    reason: str = ""
    messages: list[tuple[str, bytes]] = field(default_factory=list)
    granted: list[int] = field(default_factory=list)
    suback: threading.Event = field(default_factory=threading.Event)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def connect(conn: Connection, client_id: str) -> Session:
    client = make_client(conn, client_id)
    client.reconnect_delay_set(60, 120)  # a refused client must not hammer the broker
    session = Session(client)

    def on_connect(c: paho.Client, u: object, flags: object, rc: object, props: object) -> None:
        session.reason = str(rc)
        session.connected.set()

    def on_message(c: paho.Client, u: object, msg: paho.MQTTMessage) -> None:
        session.messages.append((msg.topic, msg.payload))

    def on_subscribe(
        c: paho.Client, u: object, mid: int, codes: list[object], props: object
    ) -> None:
        session.suback.set()

    client.on_connect = on_connect
    client.on_message = on_message
    client.on_subscribe = on_subscribe
    client.connect(conn.address.host, conn.address.port)
    client.loop_start()
    assert session.connected.wait(WAIT), "no CONNACK"
    return session


def publish(session: Session, topic: str, payload: bytes, *, retain: bool = True) -> None:
    info = session.client.publish(topic, payload, qos=1, retain=retain)
    info.wait_for_publish(WAIT)


def test_anonymous_client_is_refused(broker: Secured) -> None:
    session = connect(broker.connection(None), "anon")
    try:
        assert session.reason != "Success" and "authori" in session.reason.lower()
    finally:
        session.close()


def test_wrong_password_is_refused(broker: Secured, tmp_path: Path) -> None:
    wrong = tmp_path / "wrong.password"
    write_private(wrong, "not-the-password\n")
    session = connect(broker.connection("tb3-01", password_file=wrong), "tb3-01")
    try:
        assert session.reason != "Success"
    finally:
        session.close()
    right = connect(broker.connection("tb3-01"), "tb3-01")
    try:
        assert right.reason == "Success"
    finally:
        right.close()


def test_robot_reads_only_its_own_launch_topic(broker: Secured) -> None:
    reconciler = connect(broker.connection("reconciler"), "reconciler")
    a = connect(broker.connection("tb3-01"), "tb3-01")
    b = connect(broker.connection("tb3-02"), "tb3-02")
    try:
        assert reconciler.reason == a.reason == b.reason == "Success"
        publish(reconciler, "robotconf/robots/tb3-02/launch", b"for-b")
        publish(reconciler, "robotconf/robots/tb3-01/launch", b"for-a")
        for session in (a, b):
            session.suback.clear()
            session.client.subscribe("robotconf/robots/tb3-02/launch", qos=1)
            session.client.subscribe("robotconf/robots/tb3-01/launch", qos=1)
            assert session.suback.wait(WAIT)
        deadline = time.monotonic() + WAIT
        while time.monotonic() < deadline and not (a.messages and b.messages):
            time.sleep(0.05)
        # Each robot gets its own request and never the other's (the broker drops it).
        time.sleep(0.5)
        assert [p for _, p in a.messages] == [b"for-a"]
        assert [p for _, p in b.messages] == [b"for-b"]
    finally:
        for session in (reconciler, a, b):
            session.close()


def test_robot_cannot_overwrite_another_robots_status(broker: Secured) -> None:
    a = connect(broker.connection("tb3-01"), "tb3-01")
    b = connect(broker.connection("tb3-02"), "tb3-02")
    try:
        publish(b, "robotconf/robots/tb3-02/status", json.dumps({"state": "running"}).encode())
        publish(a, "robotconf/robots/tb3-02/status", json.dumps({"state": "forged"}).encode())
        publish(a, "robotconf/robots/tb3-02/launch", b"forged request")
    finally:
        a.close()
        b.close()
    viewer = connect(broker.connection("viewer"), "viewer")
    try:
        viewer.client.subscribe("robotconf/robots/tb3-02/status", qos=1)
        viewer.client.subscribe("robotconf/robots/tb3-02/launch", qos=1)
        deadline = time.monotonic() + WAIT
        while time.monotonic() < deadline and not viewer.messages:
            time.sleep(0.05)
        time.sleep(0.5)
        statuses = [json.loads(p) for t, p in viewer.messages if t.endswith("/status")]
        assert statuses == [{"state": "running"}]
        assert all(p != b"forged request" for _, p in viewer.messages)
    finally:
        viewer.close()


def test_viewer_cannot_publish_a_launch_request(broker: Secured) -> None:
    viewer = connect(broker.connection("viewer"), "viewer")
    robot = connect(broker.connection("tb3-03"), "tb3-03")
    try:
        robot.suback.clear()
        robot.client.subscribe("robotconf/robots/tb3-03/launch", qos=1)
        assert robot.suback.wait(WAIT)
        robot.messages.clear()
        publish(viewer, "robotconf/robots/tb3-03/launch", b"from viewer", retain=False)
        time.sleep(1.0)
        assert all(p != b"from viewer" for _, p in robot.messages)
    finally:
        viewer.close()
        robot.close()


def test_unverifiable_server_is_refused_unless_told_otherwise(broker: Secured) -> None:
    untrusted = Connection(
        url=broker.service_url,
        username="viewer",
        password_file=broker.secret("viewer"),
    )
    client = make_client(untrusted, "viewer-untrusted")
    with pytest.raises(OSError, match=r"CERTIFICATE_VERIFY_FAILED|certificate verify failed"):
        client.connect("127.0.0.1", broker.server.service_port)
    insecure = Connection(
        url=untrusted.url, username="viewer", password_file=broker.secret("viewer"), insecure=True
    )
    session = connect(insecure, "viewer-insecure")
    try:
        assert session.reason == "Success"
    finally:
        session.close()


def test_plain_text_listener_is_not_offered(broker: Secured) -> None:
    """The listener speaks TLS only: a plain MQTT client gets no CONNACK."""
    plain = Connection(
        url=f"mqtt://127.0.0.1:{broker.server.port}",
        username="viewer",
        password_file=broker.secret("viewer"),
    )
    client = make_client(plain, "plain")
    connected = threading.Event()
    client.on_connect = lambda *a: connected.set()
    try:
        client.connect("127.0.0.1", broker.server.port)
        client.loop_start()
        assert not connected.wait(2.0)
    except OSError:
        pass  # the broker may reset the connection at once: refused either way
    finally:
        client.loop_stop()


def test_broker_config_check_notices_a_new_robot(tmp_path: Path) -> None:
    from tests.support.lab import Lab

    lab = Lab(tmp_path / "lab")
    out = tmp_path / "broker"
    args = ["broker-config", "--repo", str(lab.root), "--out", str(out)]
    assert subprocess.run([ROBOTCONF, *args], capture_output=True).returncode == 0
    assert subprocess.run([ROBOTCONF, *args, "--check"], capture_output=True).returncode == 0
    lab.replace("configs/fleet.yaml", "robots:", "robots:\n  tb3-99: {scenario: guide-gazebo}")
    done = subprocess.run([ROBOTCONF, *args, "--check"], capture_output=True, text=True)
    assert done.returncode == 1 and "missing tb3-99" in done.stderr
    # Existing passwords are kept; the new robot gets one.
    before = (out / "secrets" / "tb3-01.password").read_text()
    assert subprocess.run([ROBOTCONF, *args], capture_output=True).returncode == 0
    assert (out / "secrets" / "tb3-01.password").read_text() == before
    assert (out / "secrets" / "tb3-99.password").is_file()
    assert "tb3-99:$7$" in (out / "passwd").read_text()


def test_a_service_user_that_cannot_be_a_file_name_is_refused(tmp_path: Path) -> None:
    """A service user names its password file and an ACL line: `../x` would write outside
    the secrets folder, a line break another ACL rule. Refused before anything is written."""
    from tests.support.lab import Lab

    lab = Lab(tmp_path / "lab")
    out = tmp_path / "broker"
    for bad in ("../../escaped", "viewer\nuser intruder"):
        args = ["broker-config", "--repo", str(lab.root), "--out", str(out), "--viewer-user", bad]
        done = subprocess.run([ROBOTCONF, *args], capture_output=True, text=True)
        assert done.returncode == 2 and "--viewer-user '" in done.stderr, done.stderr
        assert "cannot name a file" in done.stderr and len(done.stderr.splitlines()) == 1
    assert not out.exists() and not (tmp_path / "escaped.password").exists()


def test_a_robot_cannot_take_another_robots_session(broker: Secured) -> None:
    """Connecting with robot B's client id under robot A's credentials must neither knock B
    off nor set off B's Last Will (issue 10, item 8): the robots' listener makes every client
    id its user name."""
    b = make_client(broker.connection("tb3-02"), "robotconf-agent-tb3-02")
    b_status = "robotconf/robots/tb3-02/status"
    b.will_set(b_status, b'{"state": "offline"}', qos=1, retain=True)
    dropped = threading.Event()
    b.on_disconnect = lambda *args: dropped.set()
    up = threading.Event()
    b.on_connect = lambda *args: up.set()
    b.connect("127.0.0.1", broker.server.port)
    b.loop_start()
    watcher = connect(broker.connection("viewer"), "viewer-watching")
    try:
        assert up.wait(WAIT)
        b.publish(b_status, b'{"state": "running"}', qos=1, retain=True).wait_for_publish(WAIT)
        watcher.client.subscribe(b_status, qos=1)
        for stolen in ("robotconf-agent-tb3-02", "tb3-02"):
            a = connect(broker.connection("tb3-01"), stolen)
            assert a.reason == "Success"  # it connects, as itself
            a.close()
        time.sleep(1.0)  # what a takeover would have done by now: nothing may happen
        assert not dropped.is_set()
        assert all(b"offline" not in payload for _, payload in watcher.messages)
    finally:
        watcher.close()
        b.disconnect()
        b.loop_stop()


def test_robots_have_no_credentials_on_the_service_listener(broker: Secured) -> None:
    robot = connect(broker.connection("tb3-01", url=broker.service_url), "tb3-01")
    try:
        assert robot.reason != "Success"
    finally:
        robot.close()
    # The reconciler holds several connections, and viewers may be many: none knocks another off.
    sessions = [
        connect(broker.connection(user), f"robotconf-{user}-{n}")
        for user in ("reconciler", "viewer")
        for n in range(2)
    ]
    try:
        assert [s.reason for s in sessions] == ["Success"] * 4
        time.sleep(0.5)
        assert all(s.client.is_connected() for s in sessions)
    finally:
        for session in sessions:
            session.close()


def _subscribed(session: Session, *topics: str) -> Session:
    session.suback.clear()
    session.client.subscribe([(t, 1) for t in topics])
    assert session.suback.wait(WAIT)
    session.messages.clear()
    return session


def test_only_operators_and_the_reconciler_ask_a_robot_for_restarts_and_logs(
    broker: Secured,
) -> None:
    """The desk's topics: operators ask for logs and restarts and read the logs; the
    reconciler may ask for a restart; a viewer and another robot may do neither."""
    base = "robotconf/robots/tb3-01"
    users = {u: connect(broker.connection(u), u) for u in ("operator", "reconciler", "viewer")}
    robot = connect(broker.connection("tb3-01"), "tb3-01")
    other = connect(broker.connection("tb3-02"), "tb3-02")
    sessions = [*users.values(), robot, other]
    try:
        assert all(s.reason == "Success" for s in sessions)
        _subscribed(robot, f"{base}/restart", f"{base}/logs/request")
        _subscribed(users["operator"], f"{base}/logs")
        _subscribed(users["viewer"], f"{base}/logs")
        _subscribed(other, f"{base}/logs", "robotconf/robots/tb3-02/restart")
        for name, session in [*users.items(), ("tb3-02", other)]:
            publish(session, f"{base}/restart", f"restart from {name}".encode(), retain=False)
            publish(session, f"{base}/logs/request", f"logs from {name}".encode(), retain=False)
        publish(robot, f"{base}/logs", b"the log", retain=False)
        # A robot cannot ask another, nor answer in another's name.
        publish(robot, "robotconf/robots/tb3-02/restart", b"robot to robot", retain=False)
        publish(other, f"{base}/logs", b"forged log", retain=False)
        deadline = time.monotonic() + WAIT
        while time.monotonic() < deadline and not users["operator"].messages:
            time.sleep(0.05)
        time.sleep(1.0)
        got = sorted(p for _, p in robot.messages)
        assert got == [b"logs from operator", b"restart from operator", b"restart from reconciler"]
        assert [p for _, p in users["operator"].messages] == [b"the log"]
        assert users["viewer"].messages == [] and other.messages == []
    finally:
        for session in sessions:
            session.close()


@pytest.mark.parametrize(
    "command", [["status", "--repo", str(ROOT)], ["logs", "tb3-01"], ["restart", "tb3-01"]]
)
def test_a_refused_login_is_said_once_and_at_once(
    broker: Secured, tmp_path: Path, command: list[str]
) -> None:
    wrong = tmp_path / "wrong.password"
    wrong.write_text("not the password\n")
    wrong.chmod(0o600)
    done = subprocess.run(
        [
            ROBOTCONF, *command, "--broker", broker.service_url,
            "--username", "operator", "--password-file", str(wrong),
            "--ca-file", str(broker.pki.ca_cert), "--wait", "600",
        ],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "refused the connection" in lines[0], done.stderr
    assert "is it running" not in done.stderr and "not the password" not in done.stderr


def test_a_robot_writes_only_its_own_interfaces_and_every_reader_reads_them(
    broker: Secured,
) -> None:
    """The interfaces topic (agent.yaml `interfaces`): retained, written by its robot alone."""
    topic = "robotconf/robots/tb3-04/interfaces"
    own = connect(broker.connection("tb3-04"), "tb3-04")
    other = connect(broker.connection("tb3-05"), "tb3-05")
    try:
        publish(own, topic, b'{"topics": [], "source": "ros2"}')
        # Acknowledged, and dropped by the ACL: the retained message stays the robot's own.
        publish(other, topic, b'{"topics": [], "source": "forged"}')
        publish(other, "robotconf/robots/tb3-05/interfaces", b'{"source": "tb3-05 own"}')
    finally:
        own.close()
        other.close()
    for reader in ("viewer", "reconciler", "operator"):
        session = connect(broker.connection(reader), reader)
        try:
            session.client.subscribe([(topic, 1), ("robotconf/robots/tb3-05/interfaces", 1)])
            deadline = time.monotonic() + WAIT
            while time.monotonic() < deadline and len(session.messages) < 2:
                time.sleep(0.05)
            assert sorted(session.messages) == [
                ("robotconf/robots/tb3-04/interfaces", b'{"topics": [], "source": "ros2"}'),
                ("robotconf/robots/tb3-05/interfaces", b'{"source": "tb3-05 own"}'),
            ], reader
        finally:
            session.close()
