"""The relay's rules without a socket or a broker: lines and times in, summaries and records out."""

from __future__ import annotations

import json
from typing import Any

from robotconf.agent.brain_socket import _Connection, split_lines
from robotconf.agent.relay import GoalsRelay, Limits, Now, Signal, TokenBucket, safe_text
from robotconf.contract.goals import (
    MAX_LINE_BYTES,
    MAX_TASKS_KEPT,
    MAX_TEXT,
    MAX_VITALS,
    OTHER_TASK,
    OutcomeState,
)

DIGEST = "sha256:" + "a" * 64
OTHER = "sha256:" + "b" * 64


def at(t: float) -> Now:
    return Now(mono=t, wall=1_000_000.0 + t)


def raw(**fields: Any) -> bytes:
    return json.dumps(fields).encode()


def goal(id: str, state: str, task: str = "Delivery", **more: Any) -> bytes:
    return raw(type="goal", id=id, task=task, state=state, **more)


def relay(**limits: Any) -> GoalsRelay:
    r = GoalsRelay("tb3-01", Limits(**limits))
    r.request(DIGEST, "rev-1", "delivery", at(0))
    r.brain_started("run-1", at(0))
    return r


def test_hello_and_ready_are_signals_and_make_it_reporting() -> None:
    r = relay()
    assert not r.summary(at(0)).reporting and r.summary(at(0)).ready is None
    assert r.lines([raw(type="hello", digest=DIGEST)], at(1)) == [Signal.HELLO]
    assert r.summary(at(1)).reporting and r.summary(at(1)).ready is False
    assert r.lines([raw(type="ready")], at(2)) == [Signal.READY]
    assert r.summary(at(2)).ready is True
    assert not r.summary(at(2)).events  # the digest it said is the agent's


def test_a_goal_counted_per_task_and_recorded_with_the_agents_request() -> None:
    r = relay()
    r.lines(
        [goal("g1", "started"), goal("g1", "progress", fraction=0.5, eta=7, note="half")], at(1)
    )
    summary = r.summary(at(1))
    assert summary.underway == 1 and summary.current is not None
    assert (summary.current.goal, summary.current.fraction, summary.current.eta) == ("g1", 0.5, 7)
    r.lines([goal("g1", "failed", code="NAV2_TIMEOUT", message="stuck")], at(4))
    summary = r.summary(at(4))
    assert (summary.failed, summary.underway, summary.current) == (1, 0, None)
    assert summary.tasks["Delivery"].failed == 1
    assert summary.last is not None and summary.last.code == "NAV2_TIMEOUT"
    assert summary.last.duration == 3.0
    out = r.publishes(at(4), connected=True)
    [record] = out.records
    assert (record.run, record.seq, record.digest, record.revision, record.scenario) == (
        "run-1",
        0,
        DIGEST,
        "rev-1",
        "delivery",
    )
    assert record.outcome is OutcomeState.FAILED and record.duration == 3.0


def test_a_code_is_kept_only_for_a_failure() -> None:
    r = relay()
    r.lines([goal("g", "succeeded", code="E_WHATEVER")], at(1))
    assert r.summary(at(1)).last is not None and r.summary(at(1)).last.code is None  # type: ignore[union-attr]


def test_a_lying_hello_is_a_warning_and_changes_nothing() -> None:
    r = relay()
    r.lines([raw(type="hello", digest=OTHER), goal("g", "succeeded")], at(1))
    summary = r.summary(at(1))
    assert summary.digest == DIGEST and summary.reporting
    [event] = summary.events
    assert event.severity.value == "warning" and "sha256:bbbbbbbbbbbb" in event.message
    assert r.publishes(at(1), True).records[0].digest == DIGEST


def test_garbage_is_counted_never_raised() -> None:
    r = relay()
    lines = [
        b"nope",
        b"{",
        b"[]",
        b'{"type": "goal"}',
        b'{"type": "ready", "extra": 1}',
        b'{"type": "vitals", "values": {"a": NaN}}',
        b'{"a": 1, "a": 2}',
        b"[" * 3000,
        b"\xff\xfe",
        b'{"type": "goal", "id": "g", "task": "T", "state": "progress", "fraction": 2}',
        b'{"type": "event", "severity": "fatal", "message": "x"}',
    ]
    assert r.lines(lines, at(1)) == []
    assert r.summary(at(1)).dropped == len(lines)


def test_text_is_escaped_and_cut() -> None:
    r = relay()
    hostile = "\x1b[2J\u202e" + "y" * 700
    r.lines(
        [goal("g", "started", note=hostile), raw(type="event", severity="error", message=hostile)],
        at(1),
    )
    summary = r.summary(at(1))
    for text in (summary.current.note if summary.current else "", summary.events[0].message):
        assert text is not None and len(text) == MAX_TEXT and text.endswith("…")
        assert text.startswith("\\x1b[2J\\u202e")
    assert safe_text("ok") == "ok"


def test_the_line_bucket_refuses_a_flood_and_refills() -> None:
    r = relay(lines_per_second=10, line_burst=20)
    flood = [raw(type="vitals", values={"n": i}) for i in range(100)]
    r.lines(flood, at(1))
    assert r.summary(at(1)).dropped == 80 and r.summary(at(1)).vitals == {"n": 19}
    r.lines([raw(type="vitals", values={"n": -1})], at(3))  # 2 s later: 20 tokens again
    assert r.summary(at(3)).vitals == {"n": -1} and r.summary(at(3)).dropped == 80


def test_records_beyond_their_bucket_are_counted_not_sent() -> None:
    r = relay(records_per_second=1, record_burst=2, lines_per_second=1000, line_burst=1000)
    r.lines([goal(f"g{i}", "succeeded") for i in range(5)], at(1))
    assert len(r.publishes(at(1), True).records) == 2
    summary = r.summary(at(1))
    assert summary.completed == 5 and summary.dropped == 3


def test_the_summary_is_coalesced_to_its_interval() -> None:
    r = relay(summary_interval=1.0)
    assert r.publishes(at(0), True).summary is not None
    r.lines([goal("g", "started")], at(0.1))
    r.lines([goal("g", "progress", fraction=0.1)], at(0.2))
    assert r.publishes(at(0.3), True).summary is None
    assert r.due(connected=True) == 1.0
    later = r.publishes(at(1.0), True).summary
    assert later is not None and later.current is not None and later.current.fraction == 0.1
    assert r.publishes(at(2.5), True).summary is None  # nothing changed
    r.connected()
    assert r.publishes(at(2.6), True).summary is not None  # a new connection: at once


def test_nothing_is_sent_while_disconnected_and_records_wait() -> None:
    r = relay()
    r.lines([goal("g", "succeeded")], at(1))
    assert r.publishes(at(1), False).records == []
    assert r.due(connected=False) is None  # nothing to wake up for: no busy loop
    assert len(r.publishes(at(2), True).records) == 1


def test_a_goal_without_progress_goes_stale_once_and_may_end_later() -> None:
    r = relay(stale_after=10)
    r.lines([goal("g", "started")], at(0))
    assert r.due(connected=True) == 0.0  # the summary
    assert r.due(connected=False) == 10.0  # the goal's stale deadline alone
    r.tick(at(9))
    assert r.summary(at(9)).stale == 0
    r.tick(at(10))
    r.tick(at(30))
    summary = r.summary(at(30))
    assert (summary.stale, summary.underway) == (1, 0) and summary.current is not None
    assert summary.current.stale
    records = r.publishes(at(30), True).records
    assert [x.outcome for x in records] == [OutcomeState.STALE]
    r.lines([goal("g", "progress", fraction=0.9)], at(31))
    assert (r.summary(at(31)).stale, r.summary(at(31)).underway) == (0, 1)
    r.lines([goal("g", "succeeded")], at(32))
    assert r.summary(at(32)).completed == 1
    assert [x.outcome for x in r.publishes(at(32), True).records] == [OutcomeState.SUCCEEDED]


def test_a_run_that_ends_leaves_its_open_goals_stale() -> None:
    r = relay()
    r.lines([raw(type="hello"), raw(type="ready"), goal("g", "started")], at(1))
    r.brain_exited(at(2))
    summary = r.summary(at(2))
    assert (summary.stale, summary.underway, summary.reporting, summary.ready) == (
        1,
        0,
        False,
        None,
    )
    [record] = r.publishes(at(2), True).records
    assert record.outcome is OutcomeState.STALE and record.run == "run-1"


def test_a_restart_keeps_the_counts_a_new_request_starts_new_ones() -> None:
    r = relay()
    r.lines([goal("g", "succeeded")], at(1))
    since = r.summary(at(1)).since
    r.brain_exited(at(2))
    r.brain_started("run-2", at(3))
    r.request(DIGEST, "rev-1", "delivery", at(3))
    r.lines([goal("g", "succeeded")], at(4))
    summary = r.summary(at(4))
    assert (summary.completed, summary.run, summary.since) == (2, "run-2", since)
    assert [x.seq for x in r.publishes(at(4), True).records] == [0, 0]  # one per run
    r.lines([goal("h", "started")], at(5))
    r.request(OTHER, "rev-2", "delivery", at(6))
    summary = r.summary(at(6))
    assert (summary.completed, summary.underway, summary.digest) == (0, 0, OTHER)
    r.lines([goal("h", "succeeded")], at(7))
    assert r.summary(at(7)).completed == 0  # started under the request before
    [record] = r.publishes(at(7), True).records
    assert record.digest == DIGEST and record.revision == "rev-1"


def test_tasks_open_goals_and_vitals_are_bounded() -> None:
    r = relay(lines_per_second=10_000, line_burst=10_000)
    r.lines([goal(f"g{i}", "succeeded", task=f"T{i}") for i in range(MAX_TASKS_KEPT + 5)], at(1))
    summary = r.summary(at(1))
    assert len(summary.tasks) == MAX_TASKS_KEPT + 1 and summary.tasks[OTHER_TASK].completed == 5
    r.lines([goal(f"o{i}", "started") for i in range(100)], at(2))
    assert r.summary(at(2)).underway < 100 and r.summary(at(2)).dropped > 0
    values = {f"v{i}": i for i in range(MAX_VITALS)}
    r.lines([raw(type="vitals", values=values), raw(type="vitals", values={"extra": 1})], at(3))
    assert len(r.summary(at(3)).vitals) == MAX_VITALS and "extra" not in r.summary(at(3)).vitals


def test_lines_without_a_running_brain_are_ignored() -> None:
    r = GoalsRelay("tb3-01", Limits())
    assert r.lines([raw(type="hello")], at(1)) == []
    assert not r.summary(at(1)).reporting


def test_the_token_bucket() -> None:
    bucket = TokenBucket(rate=2, burst=4)
    assert bucket.take(0, 10) == 4 and bucket.take(0) == 0
    assert bucket.ready_at(0) == 0.5
    assert bucket.take(1, 10) == 2


def test_lines_are_split_across_reads_and_long_ones_skipped() -> None:
    import socket

    a, b = socket.socketpair()
    try:
        connection = _Connection(a, 1)
        out: list[bytes] = []
        assert split_lines(connection, b'{"a"', out) == 0 and out == []
        assert split_lines(connection, b': 1}\r\n\n{"b": 2}\n{"c"', out) == 0
        assert out == [b'{"a": 1}', b'{"b": 2}']
        out.clear()
        assert split_lines(connection, b"x" * (MAX_LINE_BYTES + 10), out) == 1
        assert split_lines(connection, b"y" * 100, out) == 0  # still the long line
        assert split_lines(connection, b'zz\n{"d": 4}\n', out) == 0
        assert out == [b'{"d": 4}']
        assert split_lines(connection, b"q" * (MAX_LINE_BYTES + 1) + b"\nok\n", out) == 1
        assert out == [b'{"d": 4}', b"ok"]
    finally:
        a.close()
        b.close()
