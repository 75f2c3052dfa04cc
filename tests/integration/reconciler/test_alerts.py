"""Alerts and metrics: a real reconciler tells real local HTTP receivers, and a real scrape.

Events once per transition across resyncs; a receiver that hangs or fails delays neither
reconciling nor the other receivers; the metrics a Prometheus scrape sees.
"""

from __future__ import annotations

import json
import socket
import threading
import urllib.request
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

import pytest
import yaml
from prometheus_client.parser import text_string_to_metric_families

from robotconf.contract.mqtt import Connection
from robotconf.contract.wire import (
    AgentState,
    AgentStatus,
    ReconcilerReason,
    ReconcilerStatus,
    Topics,
)
from robotconf.readmodel.events import Event, Kind
from robotconf.readmodel.verdicts import Verdict
from robotconf.reconciler.decide import state_of
from robotconf.reconciler.notify import QUEUE, Notifier, Sender, parse_receiver
from robotconf.reconciler.source import LocalBranch
from robotconf.reconciler.telemetry import Telemetry
from tests.integration.reconciler.conftest import Fleet
from tests.support.agents import publish
from tests.support.fleet import GitLab, Running, refused_reconcile, start_reconciler
from tests.support.mosquitto import Mosquitto
from tests.support.private import write_private
from tests.support.watch import FleetWatch, wait_for

FLEET = "configs/fleet.yaml"


class Receiver:
    """An HTTP server on 127.0.0.1 that records every POST; it answers 200, 500, or hangs
    (holds the request unanswered until closed)."""

    def __init__(self, mode: str = "ok") -> None:
        self.mode = mode
        self.bodies: list[Any] = []
        self.lock = threading.Lock()
        self.release = threading.Event()
        receiver = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                length = int(self.headers.get("Content-Length", "0"))
                body = json.loads(self.rfile.read(length))
                with receiver.lock:
                    receiver.bodies.append(body)
                if receiver.mode == "hang":
                    receiver.release.wait()
                    return
                self.send_response(500 if receiver.mode == "500" else 200)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    @property
    def url(self) -> str:
        return f"{self.base}/hook"

    @property
    def base(self) -> str:
        """The URL as logs and metrics name it: without its path."""
        return f"http://127.0.0.1:{self.server.server_address[1]}"

    def got(self) -> list[Any]:
        with self.lock:
            return list(self.bodies)

    def events(self, kind: str, **match: Any) -> list[dict[str, Any]]:
        return [
            b
            for b in self.got()
            if b.get("event") == kind and all(b.get(k) == v for k, v in match.items())
        ]

    def close(self) -> None:
        self.release.set()
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def receivers() -> Iterator[dict[str, Receiver]]:
    made = {
        name: Receiver(mode)
        for name, mode in [("hang", "hang"), ("500", "500"), ("ok", "ok"), ("slack", "ok")]
    }
    try:
        yield made
    finally:
        for receiver in made.values():
            receiver.close()


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def scrape(port: int) -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
    """GET /metrics, parsed by the Prometheus client's own parser: (name, labels) -> value."""
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=10) as answer:
        text = answer.read().decode()
    return {
        (sample.name, tuple(sorted(sample.labels.items()))): sample.value
        for family in text_string_to_metric_families(text)
        for sample in family.samples
    }


def value(
    metrics: dict[tuple[str, tuple[tuple[str, str], ...]], float], name: str, **labels: str
) -> float | None:
    return metrics.get((name, tuple(sorted(labels.items()))))


def resyncs(watch: FleetWatch, count: int) -> None:
    """Waits for `count` more heartbeats of the reconciler: that many resyncs went by."""
    for _ in range(count):
        status = watch.reconciler()
        seen = status.heartbeat if status is not None and status.heartbeat else 0.0
        watch.wait_reconciler(lambda s, seen=seen: (s.heartbeat or 0.0) > seen, "a resync")


def break_fleet(lab: GitLab) -> str:
    lab.write(FLEET, lab.read(FLEET).replace("robots:", "robots:\n  BAD ID!: {scenario: x}", 1))
    return lab.commit("a robot id the rules refuse")


def assert_refusals_scraped(port: int, fixed: str, receivers: dict[str, Receiver]) -> None:
    """The scrape after refused, recovered (at `fixed`), refused again: the errors, the steps,
    not ready, and what each receiver was told."""
    told = "robotconf_notifications_total"
    ok = f"#3 {receivers['ok'].base}"
    # The receiver has the third event once its POST arrived; the reconciler counts it "sent"
    # only once the answer is back: scrape until it has (a loaded run scraped in between).
    metrics = wait_for(
        lambda: m if value(m := scrape(port), told, receiver=ok, outcome="sent") == 3.0 else None,
        "the third event counted sent",
    )
    assert value(metrics, "robotconf_applied_revision_info", revision=fixed) == 1.0
    assert (value(metrics, "robotconf_reconcile_errors_total", reason="BuildFailed") or 0) >= 3
    assert (value(metrics, "robotconf_reconcile_duration_seconds_count") or 0) >= 5
    assert value(metrics, "robotconf_ready") == 0.0
    # refused, recovered, refused again
    assert value(metrics, told, receiver=ok, outcome="sent") == 3.0
    failed = value(metrics, told, receiver=f"#2 {receivers['500'].base}", outcome="failed")
    assert failed is not None and failed >= 1


def test_a_refused_commit_is_told_once_and_failing_receivers_delay_nothing(
    lab: GitLab,
    mosquitto: Mosquitto,
    watch: FleetWatch,
    receivers: dict[str, Receiver],
    tmp_path: Any,
) -> None:
    port = free_port()
    reconciler = start_reconciler(
        lab, mosquitto.url, tmp_path / "reconciler.log", "--interval", "1",
        "--notify", receivers["hang"].url, "--notify", receivers["500"].url,
        "--notify", receivers["ok"].url, "--notify", "slack:" + receivers["slack"].url,
        "--metrics", f"127.0.0.1:{port}",
    )  # fmt: skip
    ok = receivers["ok"]
    try:
        good = lab.head()
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == good, "applied")
        bad = break_fleet(lab)
        wait_for(lambda: ok.events("commit_refused", revision=bad), "the refusal told")
        resyncs(watch, 3)
        refused = ok.events("commit_refused")
        assert len(refused) == 1, refused
        assert refused[0]["reason"] == "BuildFailed" and refused[0]["branch"] == "main"
        assert refused[0]["robot"] is None and bad[:12] in refused[0]["message"]
        texts = wait_for(lambda: receivers["slack"].got(), "the Slack receiver told")
        # The commit's subject follows, named as the commit's (the message names two).
        subject = f' (commit {bad[:12]}: "{refused[0]["subject"]}")'
        assert refused[0]["subject"] == lab.git("log", "-1", "--format=%s", bad).strip()
        assert texts == [{"text": f"robotconf commit refused: {refused[0]['message']}{subject}"}]
        # The failing receiver was tried again (bounded); the hanging one holds the first POST.
        wait_for(lambda: len(receivers["500"].got()) >= 3, "three attempts at the 500")
        assert receivers["hang"].got()[0]["revision"] == bad

        # Neither delays the next commit nor the good receivers' next event.
        lab.write(FLEET, lab.read(FLEET).replace("  BAD ID!: {scenario: x}\n", ""))
        fixed = lab.commit("fix it")
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == fixed, "fixed")
        # The branch's recovery is told once: not at start-up (nothing was refused then), not
        # at every heartbeat.
        wait_for(lambda: ok.events("commit_recovered"), "the recovery told")
        resyncs(watch, 2)
        (recovered,) = ok.events("commit_recovered")
        assert (recovered["revision"], recovered["refused_revision"]) == (fixed, bad)
        assert recovered["reason"] == "Applied" and recovered["branch"] == "main"
        worse = break_fleet(lab)
        wait_for(lambda: ok.events("commit_refused", revision=worse), "the second refusal")
        # refused, recovered, refused again
        slack = wait_for(lambda: receivers["slack"].got()[2:], "the Slack receiver told again")
        assert receivers["slack"].got()[1]["text"].startswith("robotconf commit recovered: ")
        assert len(slack) == 1, slack
        assert len(ok.events("commit_refused")) == 2

        assert_refusals_scraped(port, fixed, receivers)
    finally:
        assert reconciler.stop() == 0, reconciler.output()[-3000:]
    assert "/hook" not in reconciler.output()  # receivers are named without their path


def test_a_restarted_reconciler_tells_the_recovery_of_the_refusal_it_finds(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch, tmp_path: Any
) -> None:
    """The status a reconciler that died while refused left (Stalled, before any Last Will):
    its successor, finding the branch fixed, tells the recovery once and not the refusal."""
    bad, fixed = "b" * 40, lab.head()
    found = ReconcilerStatus(
        state="Stalled", ready=False, reason="BuildFailed", branch="main",
        last_applied_revision=lab.first, last_attempted_revision=bad, failed_revision=bad,
        message="configs/fleet.yaml:3: error RC101 …",
    )  # fmt: skip
    publish(mosquitto.url, Topics("robotconf").reconciler_status, found.model_dump_json().encode())
    ok = Receiver()
    reconciler = start_reconciler(
        lab, mosquitto.url, tmp_path / "reconciler.log", "--interval", "1", "--notify", ok.url
    )
    try:
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == fixed, "applied")
        wait_for(lambda: ok.events("commit_recovered"), "the recovery told")
        resyncs(watch, 2)
        told = [(b["event"], b["revision"], b["refused_revision"]) for b in ok.got()]
        assert told == [("commit_recovered", fixed, bad)]
    finally:
        ok.close()
        assert reconciler.stop() == 0, reconciler.output()[-3000:]


def test_a_hanging_receiver_holds_neither_the_loop_nor_the_others(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch, receivers: dict[str, Receiver]
) -> None:
    """In process, with a timeout longer than any wait here: were anything serial, the good
    receiver and the next commit would wait for the hanging one."""
    hang, ok = receivers["hang"], receivers["ok"]
    notifier = Notifier([parse_receiver(hang.url, 1), parse_receiver(ok.url, 2)], timeout=600)
    telemetry = Telemetry(Connection(mosquitto.url), "robotconf", notifier=notifier)
    telemetry.start()
    running = Running(LocalBranch(lab.root, "main"), mosquitto.url, on_step=telemetry.on_step)
    try:
        good = lab.head()
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == good, "applied")
        bad = break_fleet(lab)
        wait_for(lambda: hang.events("commit_refused", revision=bad), "the hanging one told")
        wait_for(lambda: ok.events("commit_refused", revision=bad), "the good one told")
        lab.write(FLEET, lab.read(FLEET).replace("  BAD ID!: {scenario: x}\n", ""))
        fixed = lab.commit("fix it")
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == fixed, "fixed")
        worse = break_fleet(lab)
        wait_for(lambda: ok.events("commit_refused", revision=worse), "the good one told again")
        assert len(hang.got()) == 1  # still on its first event
    finally:
        running.stop()
        telemetry.stop()


def test_a_full_queue_drops_the_oldest_event(receivers: dict[str, Receiver]) -> None:
    hang = receivers["hang"]
    counted: list[tuple[str, str]] = []
    sender = Sender(parse_receiver(hang.url), lambda r, o: counted.append((r, o)), timeout=600)
    sender.start()
    try:
        events = [Event(Kind.COMMIT_REFUSED, f"event {n}", float(n)) for n in range(QUEUE + 3)]
        sender.put(events[0])
        wait_for(lambda: hang.got(), "the first event in flight")
        for event in events[1:]:
            sender.put(event)  # never blocks, though the receiver does
        assert sender.dropped == 2
        assert counted == [(f"#1 {hang.base}", "dropped")] * 2
    finally:
        sender.stop()


def scraped_robots(
    port: int, verdict: str, count: int, what: str
) -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
    """The first scrape that counts `count` robots of `verdict`."""
    return wait_for(
        lambda: (
            (m := scrape_or_none(port))
            and value(m, "robotconf_robots", verdict=verdict) == count
            and m
        ),
        what,
    )


def test_robot_transitions_are_told_once_and_scraped(
    fleet: Fleet, receivers: dict[str, Receiver]
) -> None:
    ok = receivers["ok"]
    port = free_port()
    assert fleet.reconciler is not None
    fleet.reconciler.stop()
    fleet.start_reconciler("--interval", "1", "--notify", ok.url, "--metrics", f":{port}")
    head = fleet.lab.head()
    in_sync = scraped_robots(port, "InSync", 7, "seven robots in sync, scraped")
    assert value(in_sync, "robotconf_applied_revision_info", revision=head) == 1.0
    assert value(in_sync, "robotconf_ready") == 1.0
    assert value(in_sync, "robotconf_robots", verdict="Degraded") == 0.0

    # tb3-01 and tb3-06 run this scenario: their brain crashes, again and again.
    scenario = "configs/scenarios/delivery-gazebo.yaml"
    fleet.lab.replace(
        scenario,
        'knowledge: {TARGET: {GOAL_ID: "2"}}',
        'knowledge: {TARGET: {GOAL_ID: "2"}, STANDIN_CRASH: 3}',
    )
    crash = fleet.lab.commit("a brain that crashes")
    for robot in ("tb3-01", "tb3-06"):
        wait_for(lambda robot=robot: ok.events("robot_degraded", robot=robot), f"{robot} told")
    # One more crash: degraded, started again, degraded again -- told once all the same.
    first = fleet.watch.status("tb3-01")
    assert first is not None
    fleet.watch.wait_for(
        "tb3-01",
        lambda s: (
            s.restarts > first.restarts and s.state in (AgentState.BACKOFF, AgentState.FAILED)
        ),
        "crashed again",
    )
    resyncs(fleet.watch, 2)
    degraded = ok.events("robot_degraded")
    assert sorted(e["robot"] for e in degraded) == ["tb3-01", "tb3-06"], ok.got()
    assert all(e["reason"] in ("failed", "backoff") and e["revision"] == crash for e in degraded)
    metrics = scraped_robots(port, "Degraded", 2, "two robots degraded, scraped")
    assert (value(metrics, "robotconf_publishes_total", action="publish") or 0) >= 2

    fleet.lab.replace(scenario, ", STANDIN_CRASH: 3}", "}")
    fixed = fleet.lab.commit("the brain is fixed")
    for robot in ("tb3-01", "tb3-06"):
        wait_for(lambda robot=robot: ok.events("robot_in_sync", robot=robot), f"{robot} back")
    resyncs(fleet.watch, 2)
    back = ok.events("robot_in_sync")
    assert sorted(e["robot"] for e in back) == ["tb3-01", "tb3-06"], back
    assert all(e["revision"] == fixed for e in back)
    assert len(ok.events("robot_degraded")) == 2 and not ok.events("robot_offline")


def test_a_fresh_reconciler_scrapes_every_known_series_at_zero(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch, tmp_path: Any
) -> None:
    """Before anything went wrong, each labelled family has its known series: every reason that
    stalls the reconciler, each receiver's outcomes, each git server's, every verdict, every
    kind of interfaces report, both publish actions. An alert on `increase()` sees the first."""
    ok, port, hook = Receiver(), free_port(), free_port()
    secret = tmp_path / "webhook.secret"
    write_private(secret, "s3cret\n")
    reconciler = start_reconciler(
        lab, mosquitto.url, tmp_path / "reconciler.log", "--interval", "1",
        "--notify", ok.url, "--metrics", f"127.0.0.1:{port}",
        "--webhook", f"127.0.0.1:{hook}", "--webhook-secret-file", str(secret),
    )  # fmt: skip
    try:
        watch.wait_reconciler(lambda s: s.ready, "applied")
        metrics = scrape(port)
    finally:
        ok.close()
        assert reconciler.stop() == 0, reconciler.output()[-3000:]
    stalled = [r.value for r in ReconcilerReason if state_of(r) == "Stalled"]
    assert {"BuildFailed", "BrokerUnavailable", "SourceUnavailable"} <= set(stalled)
    for reason in stalled:
        assert value(metrics, "robotconf_reconcile_errors_total", reason=reason) == 0.0, reason
    for outcome in ("sent", "failed", "dropped"):
        told = value(
            metrics, "robotconf_notifications_total", receiver=f"#1 {ok.base}", outcome=outcome
        )
        assert told == 0.0, outcome
    for server in ("github", "gitlab", "gitea", "forgejo"):
        for outcome in ("fetch", "ignored", "refused"):
            assert value(metrics, "robotconf_webhooks_total", server=server, outcome=outcome) == 0.0
    assert value(metrics, "robotconf_webhooks_total", server="unknown", outcome="refused") == 0.0
    for verdict in Verdict:
        assert value(metrics, "robotconf_robots", verdict=verdict.value) is not None, verdict
    for kind in ("reported", "unknown", "error"):
        assert value(metrics, "robotconf_robot_interfaces", interfaces=kind) is not None, kind
    for action in ("publish", "clear"):
        assert value(metrics, "robotconf_publishes_total", action=action) is not None, action
    for wave_verdict in ("Successful", "Failed", "Inconclusive"):
        for dry_run in ("false", "true"):
            counted = value(
                metrics, "robotconf_rollout_verifications_total", verdict=wave_verdict,
                dry_run=dry_run,
            )  # fmt: skip
            assert counted == 0.0, (wave_verdict, dry_run)
    assert value(metrics, "robotconf_rollout_paused") == 0.0
    assert not any(name.startswith("robotconf_rollout_wave_") for name, _ in metrics)  # no rollout


def scrape_or_none(port: int) -> dict[tuple[str, tuple[tuple[str, str], ...]], float] | None:
    try:
        return scrape(port)
    except OSError:  # not listening yet
        return None


@pytest.mark.parametrize(
    ("options", "said"),
    [
        (["--notify", "ftp://user:hunter2@host/x"], "--notify #1 must be an http:// or https://"),
        (["--notify", "http://ok.example/", "--notify", "nohost"], "--notify #2 must be"),
        (["--metrics", "9108"], "must be HOST:PORT"),
        (["--metrics", "256.256.256.256:9108"], "cannot listen"),
    ],
)
def test_bad_notify_and_metrics_options_are_one_line_errors(
    lab: GitLab, mosquitto: Mosquitto, options: list[str], said: str
) -> None:
    said_back = refused_reconcile(lab, mosquitto.url, options)
    assert said in said_back and "hunter2" not in said_back


def test_a_metrics_port_in_use_is_a_one_line_error(lab: GitLab, mosquitto: Mosquitto) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        said = refused_reconcile(lab, mosquitto.url, ["--metrics", f"127.0.0.1:{port}"])
    assert "cannot listen" in said


def test_a_rolled_back_rollout_is_told_once(fleet: Fleet, receivers: dict[str, Receiver]) -> None:
    ok = receivers["ok"]
    assert fleet.reconciler is not None
    fleet.reconciler.stop()
    fleet.start_reconciler("--interval", "1", "--notify", ok.url)
    robots = yaml.safe_load(fleet.lab.read(FLEET))["robots"]
    for robot_id, assignment in robots.items():
        assignment["labels"] = {"ring": "canary"} if robot_id == "tb3-01" else {}
    fleet.lab.write(
        FLEET,
        yaml.safe_dump({"robots": robots}, sort_keys=True)
        + "rollout:\n  waves: [{name: canary, selector: {ring: canary}}, {name: all}]\n"
        # The canary's brain crashes as it starts: healthy_after outlasts that start on a loaded
        # machine (at 1 s a slow start let the canary pass, and tb3-06 got the commit too).
        "  healthy_after: 10\n  max_failures: 0\n  wave_timeout: 60\n  on_failure: rollback\n",
    )
    stable = fleet.lab.commit("roll out in waves")
    fleet.watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == stable, "policy")
    fleet.lab.replace(
        "configs/scenarios/delivery-gazebo.yaml",
        'knowledge: {TARGET: {GOAL_ID: "2"}}',
        'knowledge: {TARGET: {GOAL_ID: "2"}, STANDIN_CRASH: 3}',
    )
    bad = fleet.lab.commit("a commit whose brain crashes")
    fleet.watch.wait_reconciler(lambda s: s.reason == "RolledBack", "the rollback")
    wait_for(lambda: ok.events("rollout_rolled_back", revision=bad), "the rollback told")
    # The canary is rolled back to the stable request: back in sync, told once.
    wait_for(lambda: ok.events("robot_in_sync", robot="tb3-01"), "the canary back in sync")
    resyncs(fleet.watch, 2)
    assert len(ok.events("rollout_rolled_back")) == 1
    assert [e["robot"] for e in ok.events("robot_degraded")] == ["tb3-01"]
    assert [e["revision"] for e in ok.events("robot_in_sync")] == [stable]
    assert not ok.events("rollout_halted") and not ok.events("commit_refused")


FORGED = "\nERROR forged line\r\x1b[2J<!channel> <@U024BE7LH> @here"


def test_a_robot_can_neither_forge_a_log_line_nor_ping_a_channel(
    lab: GitLab,
    mosquitto: Mosquitto,
    watch: FleetWatch,
    receivers: dict[str, Receiver],
    tmp_path: Any,
) -> None:
    """A status published by hand (no agent) for an assigned robot, its message made to
    forge a line of the reconciler's log, clear its terminal and ping a chat channel."""
    ok, slack = receivers["ok"], receivers["slack"]
    reconciler = start_reconciler(
        lab, mosquitto.url, tmp_path / "reconciler.log", "--interval", "1",
        "--notify", ok.url, "--notify", "slack:" + slack.url,
    )  # fmt: skip
    try:
        head = lab.head()
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == head, "applied")
        robot = lab.robots()[0]
        status = AgentStatus(robot_id=robot, state=AgentState.FAILED, revision=head, message=FORGED)
        publish(mosquitto.url, Topics("robotconf").status(robot), status.model_dump_json().encode())
        told = wait_for(lambda: ok.events("robot_degraded", robot=robot), "the robot told")
        texts = wait_for(lambda: slack.got(), "the chat told")
        wait_for(lambda: "event robot_degraded" in reconciler.output(), "the event logged")
    finally:
        assert reconciler.stop() == 0, reconciler.output()[-3000:]
    # JSON carries what the robot said as data, exactly.
    assert told[0]["message"] == f"{robot} is failed: {FORGED}"
    # The chat gets inert text: no command, no mention, one line.
    (text,) = (body["text"] for body in texts)
    for command in ("<!channel>", "<@U024BE7LH>", "@here", "\n", "\r", "\x1b"):
        assert command not in text
    assert "&lt;!channel&gt; &lt;@\u2060U024BE7LH&gt; @\u2060here" in text
    # The reconciler's log: the message stays inside its line, escaped; no escape sequence.
    raw = reconciler.log.read_bytes()
    assert b"\x1b" not in raw and b"\r" not in raw
    lines = raw.decode("utf-8").split("\n")
    assert not [line for line in lines if line.startswith("ERROR forged")]
    (logged,) = (line for line in lines if "event robot_degraded" in line)
    assert logged.endswith(
        f"event robot_degraded: {robot} is failed: \\nERROR forged line\\r\\x1b[2J"
        "<!channel> <@U024BE7LH> @here"
    )
