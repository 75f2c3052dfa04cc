"""The outcome ledger with a real Mosquitto, a real reconciler process and real SQLite.

OutcomeRecords are published straight to the broker, as an agent publishes them: a kill of
the reconciler mid-batch loses nothing committed nor anything the broker still holds, and
leaves no corrupt file; a corrupt ledger is a clear line and a fresh start; records that lie
are refused; a robot's failing streak is told once and its recovery once, across restarts.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import paho.mqtt.client as paho
import pytest
from prometheus_client import CollectorRegistry

from robotconf.contract.goals import OutcomeRecord, OutcomeState
from robotconf.contract.mqtt import Connection, make_client
from robotconf.contract.wire import Topics
from robotconf.readmodel.events import Event, Kind
from robotconf.readmodel.ledger import Ledger, ledger_path
from robotconf.reconciler.ledger_feed import LedgerFeed, LedgerSettings
from robotconf.reconciler.metrics import Metrics
from tests.support.fleet import GitLab, Proc, robotconf_argv, start_reconciler
from tests.support.mosquitto import Mosquitto
from tests.support.watch import wait_for

PREFIX = "robotconf"
REVISION = "1f" * 20
TOPICS = Topics(PREFIX)


@pytest.fixture
def broker(tmp_path: Path) -> Iterator[Mosquitto]:
    # What broker-config sets for a fleet: the queue holds what arrives while the reconciler
    # is away (Mosquitto's default of 1,000 would drop the rest).
    found = Mosquitto(tmp_path / "broker", extra_config=["max_queued_messages 100000"])
    found.start()
    yield found
    found.stop()


def record(
    seq: int,
    robot: str = "tb3-01",
    outcome: OutcomeState = OutcomeState.SUCCEEDED,
    revision: str = REVISION,
    task: str = "Delivery",
) -> OutcomeRecord:
    return OutcomeRecord(
        robot_id=robot,
        revision=revision,
        digest="sha256:" + "0" * 64,
        scenario="delivery-gazebo",
        run="run-1",
        seq=seq,
        goal=f"g{seq}",
        task=task,
        outcome=outcome,
        code="NAV2_TIMEOUT" if outcome is OutcomeState.FAILED else None,
        message="blocked\x1b[31m" if outcome is OutcomeState.FAILED else None,
        started_at=time.time() - 2,
        ended_at=time.time(),
        duration=2.0,
    )


class Publisher:
    """An agent's side of the stream, QoS 1, on one connection."""

    def __init__(self, broker: Mosquitto) -> None:
        self.client = make_client(Connection(broker.url), f"test-agent-{id(self)}")
        self.client.max_inflight_messages_set(0)
        self.client.connect(broker.host, broker.port)
        self.client.loop_start()

    def send(self, found: OutcomeRecord, topic_robot: str | None = None) -> paho.MQTTMessageInfo:
        topic = TOPICS.goal_outcomes(topic_robot or found.robot_id)
        return self.raw(topic, found.model_dump_json().encode())

    def raw(self, topic: str, payload: bytes) -> paho.MQTTMessageInfo:
        return self.client.publish(topic, payload, qos=1)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def kept(path: Path) -> int:
    """Outcomes the ledger holds, read as `history` reads it (0 while it does not exist)."""
    if not path.exists():
        return 0
    try:
        with Ledger.open(path, read_only=True, check=False) as ledger:
            return ledger.count()
    except Exception:
        return 0


def wait_kept(path: Path, count: int, timeout: float = 30.0) -> int:
    return wait_for(lambda: (n := kept(path)) >= count and n, f"{count} outcomes kept", timeout)


def wait_subscribed(publisher: Publisher, path: Path) -> None:
    """Record 0, sent until the reconciler keeps it: its session exists from then on."""

    def probe() -> int:
        publisher.send(record(0)).wait_for_publish(10)
        time.sleep(0.2)
        return kept(path)

    wait_for(probe, "the reconciler's session", timeout=60)


def test_a_killed_reconciler_loses_nothing_committed_nor_what_the_broker_holds(
    tmp_path: Path, broker: Mosquitto
) -> None:
    lab = GitLab(tmp_path / "lab")
    state = tmp_path / "state"
    path = ledger_path(state)
    reconciler = start_reconciler(lab, broker.url, tmp_path / "r1.log", "--state-dir", str(state))
    publisher = Publisher(broker)
    try:
        wait_subscribed(publisher, path)  # from now on the broker holds what it does not take
        total = 6000
        sending = threading.Thread(target=_send_many, args=(publisher, 1, total), daemon=True)
        sending.start()
        before = wait_kept(path, 1500)  # mid-stream: batches are being committed
        reconciler.kill()  # SIGKILL, whatever it was doing
        assert not reconciler.alive()
        with Ledger.open(path, read_only=True) as ledger:  # quick_check: not corrupt
            after_kill = ledger.count()
        assert after_kill >= before, "a committed outcome was lost"
        assert after_kill < total, "the kill came too late to be mid-stream"
        sending.join(60)
        # Everything published while it was down is held by the broker for its session.
        reconciler = start_reconciler(
            lab, broker.url, tmp_path / "r2.log", "--state-dir", str(state)
        )
        wait_kept(path, total, timeout=60)
        time.sleep(1.0)  # any redelivery of what was committed but not acknowledged
        with Ledger.open(path, read_only=True) as ledger:
            assert ledger.count() == total  # each once
        db = sqlite3.connect(f"{path.as_uri()}?mode=ro", uri=True)
        try:
            assert db.execute("PRAGMA integrity_check").fetchone() == ("ok",)
            seqs = {row[0] for row in db.execute("SELECT seq FROM outcomes")}
        finally:
            db.close()
        assert seqs == set(range(total))
        assert "Traceback" not in reconciler.output()
        shown = subprocess.run(
            robotconf_argv("history", "--state-dir", str(state), "--json"),
            capture_output=True, text=True, timeout=60, cwd=lab.root,
        )  # fmt: skip
        assert shown.returncode == 0, shown.stderr
        report = json.loads(shown.stdout)["revision"]
        assert report["revision"] == REVISION and report["total"] == total
        assert report["failed"] == len(range(5, total, 5))  # every fifth, as sent
        tasks = report["scenarios"]["delivery-gazebo"]["tasks"]
        assert set(tasks) == {"Delivery", "Guide"}
    finally:
        publisher.close()
        reconciler.stop()


def _send_many(publisher: Publisher, first: int, total: int) -> None:
    """Records first..total-1, about 1,500 a second, of 50 robots: every fifth failed."""
    sent = []
    for seq in range(first, total):
        outcome = OutcomeState.FAILED if seq % 5 == 0 else OutcomeState.SUCCEEDED
        robot = f"tb3-{seq % 50:02d}"
        task = "Guide" if seq % 2 else "Delivery"
        sent.append(publisher.send(record(seq, robot, outcome, task=task)))
        if seq % 150 == 0:
            time.sleep(0.1)
    for info in sent:
        info.wait_for_publish(30)


def test_a_corrupt_ledger_is_a_clear_line_and_a_fresh_start(
    tmp_path: Path, broker: Mosquitto
) -> None:
    lab = GitLab(tmp_path / "lab")
    state = tmp_path / "state"
    state.mkdir()
    path = ledger_path(state)
    garbage = b"this was a ledger once\n" + os.urandom(8192)
    path.write_bytes(garbage)
    # Reading it is a one-line error, never a traceback.
    shown = subprocess.run(
        robotconf_argv("history", "--state-dir", str(state)),
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert shown.returncode == 2
    assert shown.stderr.count("\n") == 1 and "Traceback" not in shown.stderr
    assert "not a readable ledger" in shown.stderr
    reconciler = start_reconciler(lab, broker.url, tmp_path / "r.log", "--state-dir", str(state))
    publisher = Publisher(broker)
    try:
        wait_subscribed(publisher, path)
        aside = [p for p in state.iterdir() if p.name.startswith("ledger.sqlite3.unreadable-")]
        assert len(aside) == 1 and aside[0].read_bytes() == garbage  # kept for a look
        said = [line for line in reconciler.output().splitlines() if "kept aside as" in line]
        assert len(said) == 1 and "not a readable ledger" in said[0], reconciler.output()
        assert "Traceback" not in reconciler.output()
        assert reconciler.alive()
    finally:
        publisher.close()
        reconciler.stop()


def test_a_state_folder_that_cannot_be_made_is_one_line(tmp_path: Path, broker: Mosquitto) -> None:
    lab = GitLab(tmp_path / "lab")
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    proc = Proc(
        robotconf_argv(
            "reconcile", "--repo", str(lab.root), "--branch", "main", "--broker", broker.url,
            "--state-dir", str(blocker / "state"),
        ),
        tmp_path / "r.log",
    )  # fmt: skip
    assert proc.popen.wait(60) == 2
    lines = [line for line in proc.output().splitlines() if "--state-dir" in line]
    assert lines and "cannot make the state folder" in lines[0]
    assert "Traceback" not in proc.output()


F = OutcomeState.FAILED


def test_records_are_checked_counted_and_streaks_told_once(
    tmp_path: Path, broker: Mosquitto
) -> None:
    told: list[Event] = []
    metrics = Metrics()
    settings = LedgerSettings(tmp_path / "state", streak=3)
    connection = Connection(broker.url)

    def started() -> LedgerFeed:
        feed = LedgerFeed(connection, PREFIX, settings, metrics=metrics, tell=told.extend)
        feed.start()
        return feed

    feed = started()
    publisher = Publisher(broker)
    try:
        wait_for(lambda: _sent(publisher, record(0)) and feed.kept == 1, "record 0 kept")
        # Lies and garbage: another robot's record on tb3-01's topic, not JSON, too large,
        # a task of the wrong shape. None is kept; the feed goes on.
        publisher.send(record(1, robot="tb3-02"), topic_robot="tb3-01")
        publisher.raw(TOPICS.goal_outcomes("tb3-01"), b"{not json")
        publisher.raw(TOPICS.goal_outcomes("tb3-01"), b"{" + b" " * 20000 + b"}")
        bad_task = record(2).model_dump()
        bad_task["task"] = "no spaces allowed"
        publisher.raw(TOPICS.goal_outcomes("tb3-01"), json.dumps(bad_task).encode())
        wait_for(lambda: feed.refused == 4, "four records refused")
        # tb3-01 fails three in a row (a canceled or stale one neither breaks nor lengthens it).
        for seq, outcome in enumerate(
            [F, OutcomeState.CANCELED, F, OutcomeState.STALE, F],
            start=10,
        ):
            publisher.send(record(seq, outcome=outcome)).wait_for_publish(10)
        wait_for(lambda: feed.kept == 6, "six kept")
        failing = [e for e in told if e.kind is Kind.ROBOT_GOALS_FAILING]
        assert len(failing) == 1 and failing[0].robot == "tb3-01"
        assert "3 goals in a row" in failing[0].message
        # Once: a fourth failure tells nothing, nor does a redelivered record.
        publisher.send(record(15, outcome=F)).wait_for_publish(10)
        publisher.send(record(15, outcome=F)).wait_for_publish(10)
        wait_for(lambda: feed.kept == 7 and feed.duplicates >= 1, "the copy seen")
        assert len(told) == 1
        # A restart remembers that tb3-01 was told failing: its success is its recovery.
        feed.stop()
        feed = started()
        publisher.send(record(16)).wait_for_publish(10)
        wait_for(lambda: feed.kept == 1, "kept after the restart")
        assert [e.kind for e in told] == [Kind.ROBOT_GOALS_FAILING, Kind.ROBOT_GOALS_RECOVERED]
        assert told[1].as_json()["robot"] == "tb3-01"
    finally:
        publisher.close()
        feed.stop()
    _check_counted(metrics, settings)


def test_the_feed_keeps_the_ledger_in_its_bounds(tmp_path: Path, broker: Mosquitto) -> None:
    settings = LedgerSettings(tmp_path / "state", max_records=1000)
    feed = LedgerFeed(Connection(broker.url), PREFIX, settings)
    feed.start()
    publisher = Publisher(broker)
    try:
        wait_for(lambda: _sent(publisher, record(0)) and feed.kept == 1, "record 0 kept")
        for info in [publisher.send(record(seq)) for seq in range(1, 1500)]:
            info.wait_for_publish(10)
        wait_for(lambda: feed.kept == 1500, "1,500 kept")
        feed.stop()
        # Pruned at the next start (and every minute while it runs), oldest first.
        feed = LedgerFeed(Connection(broker.url), PREFIX, settings)
        feed.start()
        wait_for(lambda: kept(settings.path) == 1000, "pruned to 1,000")
        with Ledger.open(settings.path, read_only=True) as ledger:
            assert ledger.report(REVISION).tally.total == 1000  # the tallies follow
    finally:
        publisher.close()
        feed.stop()


def _check_counted(metrics: Metrics, settings: LedgerSettings) -> None:
    """What the metrics and the ledger say of test_records_are_checked_counted_and_streaks."""
    counted = _samples(metrics.registry, "robotconf_goal_outcomes_total")
    assert counted[("delivery-gazebo", "Delivery", "failed")] == 4
    assert counted[("delivery-gazebo", "Delivery", "succeeded")] == 2
    assert counted[("delivery-gazebo", "Delivery", "stale")] == 1
    results = _samples(metrics.registry, "robotconf_ledger_records_total")
    # Record 0 was sent until kept (more than once, maybe); record 15 twice.
    assert results[("kept",)] == 8 and results[("refused",)] == 4
    assert results[("duplicate",)] >= 1
    with Ledger.open(settings.path, read_only=True) as ledger:
        history = ledger.history()
    assert history.report.tally.failed == 4 and history.report.codes == {"NAV2_TIMEOUT": 4}
    messages = [r for r in _messages(settings.path) if r]
    assert messages and all("\x1b" not in m for m in messages)  # escaped before it was kept


def _sent(publisher: Publisher, found: OutcomeRecord) -> bool:
    publisher.send(found).wait_for_publish(10)
    time.sleep(0.1)
    return True


def _samples(registry: CollectorRegistry, name: str) -> dict[tuple[str, ...], float]:
    found: dict[tuple[str, ...], float] = {}
    for family in registry.collect():
        for sample in family.samples:
            if sample.name == name:
                found[tuple(sample.labels.values())] = sample.value
    return found


def _messages(path: Path) -> list[str]:
    db = sqlite3.connect(f"{path.as_uri()}?mode=ro", uri=True)
    try:
        return [row[0] for row in db.execute("SELECT message FROM outcomes")]
    finally:
        db.close()


WRITER = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from robotconf.contract.goals import OutcomeRecord
    from robotconf.readmodel.ledger import Ledger
    ledger = Ledger.open_or_start(Path(sys.argv[1]))
    seq = 0
    while True:
        batch = [
            OutcomeRecord(robot_id="r1", revision="a" * 40, digest=None, run="k", seq=seq + i,
                          goal="g", task="Deliver", outcome="succeeded", ended_at=time.time())
            for i in range(500)
        ]
        ledger.add(batch)
        seq += 500
        print(seq, flush=True)
    """
)


def test_a_writer_killed_mid_transaction_leaves_whole_batches_and_a_sound_file(
    tmp_path: Path,
) -> None:
    path = ledger_path(tmp_path)
    writer = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(path)],
        stdout=subprocess.PIPE,
        text=True,
        cwd=Path(__file__).resolve().parents[3],
    )
    try:
        assert writer.stdout is not None
        committed = 0
        deadline = time.monotonic() + 60
        while committed < 20_000 and time.monotonic() < deadline:
            committed = int(writer.stdout.readline())
        writer.send_signal(signal.SIGKILL)  # wherever it is: most likely inside a batch
    finally:
        writer.kill()
        writer.wait()
    with Ledger.open(path, read_only=True) as ledger:  # quick_check passes
        count = ledger.count()
    assert count >= committed and count % 500 == 0
    with Ledger.open_or_start(path) as ledger:  # and a writer goes on from there
        assert len(ledger.add([record(10**6)]).kept) == 1
