"""`robotconf ui` over HTTP, on a real fleet (Mosquitto, a reconciler, agents): its pages, its
server-sent events of what changed, a refused commit's diagnostics, hostile statuses that change
only their own row, broker and reconciler restarts shown then recovered, and bad requests answered
4xx, never a traceback."""

from __future__ import annotations

import json
import re
import socket
import subprocess
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path

import paho.mqtt.client as paho
import pytest

from robotconf.contract.safejson import MAX_PAYLOAD_BYTES
from robotconf.contract.wire import Topics
from robotconf.workstation.ui.server import CSP
from tests.integration.reconciler.conftest import Fleet
from tests.support.fleet import GitLab, refused_reconcile, robotconf_argv
from tests.support.mosquitto import Mosquitto, free_port
from tests.support.tlsutil import make_pki
from tests.support.ui import UiProc, events
from tests.support.watch import wait_for


@pytest.fixture
def ui(fleet: Fleet, tmp_path: Path) -> Iterator[UiProc]:
    proc = UiProc(fleet.lab.root, fleet.broker.url, tmp_path / "ui.log")
    try:
        yield proc
    finally:
        proc.stop()


def row_of(page: str, robot_id: str) -> str:
    found = re.search(rf'<tr data-robot="{re.escape(robot_id)}".*?</tr>', page)
    assert found is not None, f"no row of {robot_id}"
    return found.group()


def without_goals(row: str) -> str:
    """A robot's row less its goals cell and rank: its stand-in brain ends a goal every few
    seconds (robotconf.brain), which changes that cell and nothing else of the row."""
    row = re.sub(r'<td class="goals"[^>]*>.*?</td>', "", row)
    return re.sub(r' data-rank="[^"]*"', "", row)


def verdicts(page: str) -> dict[str, str]:
    return dict(re.findall(r'<tr data-robot="([^"]+)" data-verdict="([^"]+)"', page))


def all_in_sync(fleet: Fleet) -> Callable[[str], bool]:
    robots = set(fleet.requests())
    return lambda page: all(verdicts(page).get(r) == "InSync" for r in robots)


def publish(url: str, messages: dict[str, bytes]) -> None:
    """Retained messages published as a robot (or anyone) on the broker might."""
    port = int(url.rsplit(":", 1)[1])
    client = paho.Client(paho.CallbackAPIVersion.VERSION2, client_id="hostile")
    client.connect("127.0.0.1", port)
    client.loop_start()
    try:
        for topic, payload in messages.items():
            client.publish(topic, payload, qos=1, retain=True).wait_for_publish(10)
    finally:
        client.disconnect()
        client.loop_stop()


def test_the_pages_of_a_converged_fleet(fleet: Fleet, ui: UiProc) -> None:
    page = ui.wait_page("/", all_in_sync(fleet), "every robot InSync on the fleet page")
    answer = ui.get("/")
    assert answer.headers["Content-Security-Policy"] == CSP
    assert 'data-reconciler-state="Ready"' in page
    assert ">InSync<" in row_of(page, "tb3-01")
    labelled = ui.get("/?selector=ring%3Dcanary")
    assert set(verdicts(labelled.body)) == {"tb3-01", "tb3-03"}
    robot = ui.get("/robots/tb3-01")
    assert robot.code == 200 and robot.headers["Content-Security-Policy"] == CSP
    assert 'data-robot-page="tb3-01"' in robot.body and "<pre data-log-tail" in robot.body
    tree = re.search(r'<section data-launch>.*?<ul class="tree".*?</section>', robot.body)
    assert tree is not None
    for part in ("Tasks", "Delivery", "Actions and their logics", "logic ", "Mappings", "cmd_vel"):
        assert part in tree.group()
    assert "data-history" in robot.body and "running" in robot.body
    for path in ("/healthz", "/static/ui.js", "/static/ui.css"):
        found = ui.get(path)
        assert found.code == 200 and found.headers["Content-Security-Policy"] == CSP
    assert ui.get("/healthz").body == "ok\n"


BAD = [
    ("/?q=" + "a" * 5000, 414),
    ("/?selector=ring", 400),
    ("/?selector=%3Cscript%3E%3Dx", 400),
    ("/?verdict=Fine", 400),
    ("/?" + "x=1&" * 100, 400),
    ("/events?selector=ring", 400),
    ("/events?robot=%3Cscript%3E", 400),
    ("/robots/%3Cscript%3E", 400),
    ("/robots/%ff%fe", 400),
    ("/robots/no-such-robot", 404),
    ("/robots/tb3-01/../../etc/passwd", 404),
    ("/static/../server.py", 404),
    ("/static/nothing.js", 404),
    ("/nowhere", 404),
]


def test_bad_requests_are_answered_4xx_with_the_csp(fleet: Fleet, ui: UiProc) -> None:
    ui.wait_page("/", all_in_sync(fleet), "every robot InSync")
    for path, code in BAD:
        answer = ui.get(path)
        assert answer.code == code, (path, answer.body[:300])
        assert answer.headers["Content-Security-Policy"] == CSP
        assert "Traceback" not in answer.body
    assert ui.get("/", method="DELETE").code == 405
    # A name pointed at 127.0.0.1 by someone else (DNS rebinding) reads nothing.
    assert ui.get("/", headers={"Host": "evil.example"}).code == 421
    assert ui.get("/", headers={"Host": f"localhost:{ui.port}"}).code == 200
    assert raw(ui.port, b"\x00\xff garbage\r\n\r\n").startswith(b"HTTP/1.1 400")
    huge = b"GET / HTTP/1.1\r\nX: " + b"a" * 40_000 + b"\r\n\r\n"
    assert raw(ui.port, huge).startswith(b"HTTP/1.1 431")
    assert raw(ui.port, b"GET http://evil/ HTTP/1.1\r\n\r\n").startswith(b"HTTP/1.1 400")
    assert ui.get("/healthz").code == 200


def raw(port: int, request: bytes) -> bytes:
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.sendall(request)
        got = b""
        while data := sock.recv(65536):
            got += data
        return got


def test_a_commit_is_seen_progressing_then_in_sync_on_the_events(fleet: Fleet, ui: UiProc) -> None:
    ui.wait_page("/", all_in_sync(fleet), "every robot InSync")
    with events(ui.port) as stream:
        stream.wait(lambda seen: bool(seen) and seen[0]["reset"], "the first event, a reset")
        fleet.lab.replace(
            "configs/scenarios/delivery-gazebo.yaml", "move_speed: 0.1", "move_speed: 0.12"
        )
        fleet.lab.commit("slower delivery")

        def progressed_then_synced(robot_id: str) -> bool:
            sent = [re.search(r'data-verdict="(\w+)"', html) for html in stream.rows(robot_id)]
            said = [m.group(1) for m in sent if m]
            return "Progressing" in said and said[-1] == "InSync" and said.index("Progressing") > 0

        stream.wait(lambda _: progressed_then_synced("tb3-01"), "tb3-01 Progressing, then InSync")
        # The rows the UI updated one robot at a time are those `status` reads whole.
        page = ui.wait_page("/", all_in_sync(fleet), "every robot InSync again")
        report = json.loads(fleet.status_cli("--json").stdout)
        assert verdicts(page) == {r["robot_id"]: r["verdict"] for r in report["robots"]}
        # Only what changed: robots whose request is the same were sent nothing new but their
        # goals (their brains go on ending goals meanwhile).
        assert len({without_goals(row) for row in stream.rows("tb3-02")}) == 1
        assert all(not m["reset"] for m in stream.seen()[1:])


def test_a_refused_commit_shows_its_diagnostics(fleet: Fleet, ui: UiProc) -> None:
    ui.wait_page("/", all_in_sync(fleet), "every robot InSync")
    with events(ui.port) as stream:
        fleet.lab.replace(
            "configs/scenarios/delivery-gazebo.yaml",
            "capability: turtlebot3-camera",
            "capability: nope",
        )
        bad = fleet.lab.commit("typo")
        page = ui.wait_page("/", lambda p: "data-diagnostics" in p, "the diagnostics shown")
        assert 'data-reconciler-state="Stalled"' in page and bad[:12] in page
        listed = re.search(r"<ul data-diagnostics>(.*?)</ul>", page)
        assert listed is not None
        items = [re.sub(r"<[^>]+>", "", li) for li in re.findall(r"<li>(.*?)</li>", listed[1])]
        assert any(
            re.fullmatch(r"configs/scenarios/delivery-gazebo\.yaml:\d+:\d+ RC\d+ .*nope.*", item)
            for item in items
        ), items
        stream.wait(
            lambda seen: any("data-diagnostics" in m["boxes"].get("reconciler", "") for m in seen),
            "the reconciler box with the diagnostics on the events",
        )


def test_hostile_statuses_change_only_their_own_rows(fleet: Fleet, ui: UiProc) -> None:
    page = ui.wait_page("/", all_in_sync(fleet), "every robot InSync")
    topics = Topics()
    deep = b"[" * 100_000 + b"]" * 100_000
    lying = (
        b'{"robot_id": "tb3-01", "state": "running", "digest": "sha256:'
        + b"0" * 64
        + b'", "message": "<script>alert(1)</script>'
        + b"x" * 50_000
        + b'", "restarts": -5,'
        b' "warnings": ["<img src=x onerror=alert(1)>"]}'
    )
    hostile = {
        topics.status("evil-huge"): b"{" + b" " * (MAX_PAYLOAD_BYTES + 10) + b"}",
        topics.status("evil-deep"): deep,
        topics.status("evil-binary"): bytes(range(256)) * 10,
        topics.status("evil-liar"): lying,
        topics.status("<script>"): b'{"robot_id": "x", "state": "running"}',
    }
    with events(ui.port) as stream:
        stream.wait(lambda seen: bool(seen), "the first event")
        publish(fleet.broker.url, hostile)
        stream.wait(
            lambda _: all(
                stream.rows(r) for r in ("evil-huge", "evil-deep", "evil-binary", "evil-liar")
            ),
            "a row for each hostile robot",
        )
        # The five statuses are read in steps of their own: the page shows the last one's
        # text (escaped) once the UI has read it too, which a loaded machine may take a step for.
        ui.wait_page("/", lambda p: "&lt;script&gt;" in p, "the hostile text shown escaped")
        after = ui.get("/")
        assert after.code == 200
        robots = set(fleet.requests())
        changed = {
            rid
            for m in stream.seen()[1:]
            for rid, _, html in m["rows"]
            if rid in robots and without_goals(html) != without_goals(row_of(page, rid))
        }
        assert not changed, "a hostile status changed another robot's row"
        for robot_id in robots:
            assert without_goals(row_of(after.body, robot_id)) == without_goals(
                row_of(page, robot_id)
            )
        assert "<script>alert" not in after.body and "<img" not in after.body
        assert "&lt;script&gt;" in after.body
        liar = ui.get("/robots/evil-liar")
        assert liar.code == 200 and "<script>alert" not in liar.body and "<img" not in liar.body
        assert len(liar.body) < 200_000
    publish(fleet.broker.url, dict.fromkeys(hostile, b""))  # retained messages cleared


def test_a_broker_restart_is_shown_then_recovered(fleet: Fleet, ui: UiProc) -> None:
    ui.wait_page("/", all_in_sync(fleet), "every robot InSync")
    with events(ui.port) as stream:
        stream.wait(lambda seen: bool(seen), "the first event")
        fleet.broker.stop()
        page = ui.wait_page("/", lambda p: 'data-banner="broker"' in p, "the broker lost, said")
        assert "Broker disconnected" in page and "tb3-01" in page  # the last state still shown
        stream.wait(
            lambda seen: any('data-banner="broker"' in m["boxes"].get("banner", "") for m in seen),
            "the banner on the events",
        )
        fleet.broker.start()
        ui.wait_page(
            "/",
            lambda p: 'data-banner="broker"' not in p and all_in_sync(fleet)(p),
            "the broker back, every robot InSync again",
        )
    assert ui.get("/healthz").code == 200


def test_a_reconciler_restart_is_shown_then_recovered(fleet: Fleet, ui: UiProc) -> None:
    ui.wait_page("/", all_in_sync(fleet), "every robot InSync")
    assert fleet.reconciler is not None
    fleet.reconciler.stop()
    page = ui.wait_page(
        "/", lambda p: 'data-reconciler-state="Offline"' in p, "the reconciler offline, said"
    )
    assert 'data-banner="reconciler"' in page
    # Back with a page of its own (`reconcile --ui`): both show it ready again.
    port = free_port()
    fleet.start_reconciler("--interval", "5", "--ui", f"127.0.0.1:{port}")
    ui.wait_page(
        "/",
        lambda p: 'data-reconciler-state="Ready"' in p and 'data-banner="reconciler"' not in p,
        "the reconciler ready again",
    )
    synced = all_in_sync(fleet)
    wait_for(lambda: _page(port, synced), "reconcile --ui serving the fleet, every robot InSync")


def _page(port: int, wanted: Callable[[str], bool]) -> bool | None:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10) as answer:
            body: str = answer.read().decode()
            csp = answer.headers["Content-Security-Policy"]
    except OSError:
        return None
    return (csp == CSP and 'data-reconciler-state="Ready"' in body and wanted(body)) or None


@pytest.mark.parametrize(
    ("options", "said"),
    [
        (["--listen", "0.0.0.0:8765"], "--operator-token-file"),
        (["--listen", "127.0.0.1"], "HOST:PORT"),
        (["--listen", "127.0.0.1:8765", "--tls-cert", "c.pem"], "go together"),
        (
            ["--listen", "127.0.0.1:8765", "--tls-cert", "nowhere.pem", "--tls-key", "k"],
            "cannot use",
        ),
    ],
)
def test_options_that_cannot_serve_are_refused_in_one_line(
    tmp_path: Path, options: list[str], said: str
) -> None:
    done = subprocess.run(
        robotconf_argv("ui", "--repo", str(tmp_path), *options),
        capture_output=True, text=True, timeout=60, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert said in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_reconcile_refuses_a_ui_for_other_machines(lab: GitLab, mosquitto: Mosquitto) -> None:
    said = refused_reconcile(lab, mosquitto.url, ["--ui", "0.0.0.0:8765"])
    assert "loopback only" in said


def test_the_ui_over_tls(lab: GitLab, mosquitto: Mosquitto, tmp_path: Path) -> None:
    pki = make_pki(tmp_path / "pki")
    ui = UiProc(
        lab.root, mosquitto.url, tmp_path / "ui.log",
        "--tls-cert", str(pki.server_cert), "--tls-key", str(pki.server_key), tls=pki.ca_cert,
    )  # fmt: skip
    try:
        answer = ui.get("/")
        assert answer.code == 200 and answer.headers["Content-Security-Policy"] == CSP
        with pytest.raises(OSError):  # plain HTTP is not answered as a page
            urllib.request.urlopen(f"http://127.0.0.1:{ui.port}/healthz", timeout=10).read()
    finally:
        ui.stop()
