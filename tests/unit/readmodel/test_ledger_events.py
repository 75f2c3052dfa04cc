"""The timeline's SQLite edge with real SQLite files: events kept in one transaction and read
back newest first, narrowed by robot, kind and time; bounded by age and by count; a ledger of
schema 1 brought to schema 2 by a writer and read as holding no events by a reader."""

from __future__ import annotations

import sqlite3
from pathlib import Path

from robotconf.readmodel.events import Event, Kind
from robotconf.readmodel.ledger import SCHEMA_VERSION, Ledger, ledger_path
from robotconf.readmodel.timeline import EventQuery

A, B = "a1" * 20, "b2" * 20


def event(kind: Kind, at: float, robot: str | None = None, message: str = "") -> Event:
    return Event(kind, message or f"{kind.value} at {at}", at, "main", A, robot)


def sample() -> list[Event]:
    return [
        event(Kind.COMMIT_APPLIED, 100.0),
        event(Kind.ROBOT_OFFLINE, 200.0, "tb3-01"),
        Event(Kind.COMMIT_REFUSED, "refused", 300.0, "main", A, subject="Break fleet.yaml"),
        Event(Kind.ROBOT_RESTARTED, "tb3-02 restarted by alice", 400.0, robot="tb3-02", by="alice"),
        event(Kind.ROBOT_IN_SYNC, 500.0, "tb3-01"),
    ]


def test_events_are_read_back_newest_first_and_narrowed(tmp_path: Path) -> None:
    with Ledger.open_or_start(ledger_path(tmp_path)) as ledger:
        assert ledger.add_events(sample()) == 5
    with Ledger.open(ledger_path(tmp_path), read_only=True) as reader:
        every = reader.events()
        assert [e.at for e in every] == [500.0, 400.0, 300.0, 200.0, 100.0]
        assert [e.subject for e in every if e.subject] == ["Break fleet.yaml"]  # kept too
        assert [e.kind for e in reader.events(EventQuery(robot="tb3-01"))] == [
            "robot_in_sync",
            "robot_offline",
        ]
        restarts = reader.events(EventQuery(kind="robot_restarted"))
        assert [(e.robot, e.by) for e in restarts] == [("tb3-02", "alice")]
        assert [e.at for e in reader.events(EventQuery(since=300.0))] == [500.0, 400.0, 300.0]
        assert [e.at for e in reader.events(EventQuery(limit=2))] == [500.0, 400.0]
        assert reader.events(EventQuery(robot="tb3-01", kind="commit_refused")) == []


def test_the_same_instant_keeps_the_order_told(tmp_path: Path) -> None:
    with Ledger.open_or_start(ledger_path(tmp_path)) as ledger:
        ledger.add_events([event(Kind.COMMIT_RECOVERED, 9.0), event(Kind.COMMIT_APPLIED, 9.0)])
        assert [e.kind for e in ledger.events()] == ["commit_applied", "commit_recovered"]


def test_events_past_their_age_or_count_are_pruned_oldest_first(tmp_path: Path) -> None:
    with Ledger.open_or_start(ledger_path(tmp_path)) as ledger:
        ledger.add_events(sample())
        assert ledger.prune_events(max_age=250.0, max_events=100, now=600.0) == 3
        assert [e.at for e in ledger.events()] == [500.0, 400.0]
        ledger.add_events([event(Kind.ROBOT_DRIFTED, 600.0 + i, "tb3-03") for i in range(10)])
        assert ledger.prune_events(max_age=1e9, max_events=4, now=700.0) == 8
        assert [e.at for e in ledger.events()] == [609.0, 608.0, 607.0, 606.0]
        assert ledger.prune_events(max_age=1e9, max_events=4, now=700.0) == 0


def test_events_survive_reopening(tmp_path: Path) -> None:
    with Ledger.open_or_start(ledger_path(tmp_path)) as ledger:
        ledger.add_events(sample())
    with Ledger.open_or_start(ledger_path(tmp_path)) as ledger:
        assert len(ledger.events()) == 5


def schema_one(path: Path) -> None:
    """A ledger as robotconf wrote it before the timeline: no events table, user_version 1."""
    Ledger.open_or_start(path).close()
    db = sqlite3.connect(path, isolation_level=None)  # each statement its own transaction
    db.execute("DROP TABLE events")
    db.execute("PRAGMA user_version=1")
    db.close()


def test_a_schema_one_ledger_reads_as_no_events_and_a_writer_brings_it_up(tmp_path: Path) -> None:
    path = ledger_path(tmp_path)
    schema_one(path)
    with Ledger.open(path, read_only=True) as reader:
        assert reader.events() == []
    with Ledger.open_or_start(path) as writer:
        writer.add_events(sample()[:1])
    db = sqlite3.connect(path)
    assert db.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION == 2
    db.close()
    with Ledger.open(path, read_only=True) as reader:
        assert [e.kind for e in reader.events()] == ["commit_applied"]
