"""The ledger's SQLite edge with real SQLite files: a record kept once, revisions in the order
they were seen, queries narrowed by robot and time, bounds, unreadable files set aside, a
ledger of a newer robotconf left alone. (A writer killed mid-transaction: tests/integration/
reconciler/test_ledger.py.)"""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from robotconf.contract.goals import OutcomeRecord, OutcomeState
from robotconf.readmodel.ledger import (
    KEEP_ASIDE,
    SCHEMA_VERSION,
    Ledger,
    LedgerError,
    find_ledger,
    ledger_path,
)

A, B, C = "a1" * 20, "b2" * 20, "c3" * 20


def record(
    seq: int,
    revision: str | None = A,
    robot: str = "r1",
    outcome: OutcomeState = OutcomeState.SUCCEEDED,
    ended_at: float = 1000.0,
) -> OutcomeRecord:
    return OutcomeRecord(  # a failed one has a code
        code="E_BLOCKED" if outcome is OutcomeState.FAILED else None,
        robot_id=robot,
        revision=revision,
        digest=None,
        scenario="delivery",
        run="run-1",
        seq=seq,
        goal=f"g{seq}",
        task="Deliver",
        outcome=outcome,
        ended_at=ended_at,
        duration=4.0,
    )


@pytest.fixture
def ledger(tmp_path: Path) -> Ledger:
    return Ledger.open_or_start(ledger_path(tmp_path))


def test_a_record_delivered_twice_is_kept_once(ledger: Ledger) -> None:
    first = ledger.add([record(0), record(1)], received_at=1000.0)
    again = ledger.add([record(1), record(2), record(2)], received_at=1001.0)
    assert len(first.kept) == 2 and len(again.kept) == 1 and again.duplicates == 2
    assert ledger.count() == 3
    # Another run of the same robot, and another robot, are other records.
    other = record(1).model_copy(update={"run": "run-2"})
    assert len(ledger.add([other, record(1, robot="r2")]).kept) == 2


def test_revisions_in_the_order_they_were_seen_and_the_one_before(ledger: Ledger) -> None:
    ledger.add([record(0, A)], received_at=100.0)
    ledger.add([record(1, B)], received_at=200.0)
    ledger.add([record(2, A), record(3, None)], received_at=300.0)  # A again: still first
    assert [seen.revision for seen in ledger.revisions()] == ["(none)", B, A]
    assert ledger.before(B) == A and ledger.before(A) is None
    assert ledger.resolve("b2b2").revision == B
    with pytest.raises(LedgerError, match="at least 4"):
        ledger.resolve("b2")
    with pytest.raises(LedgerError, match="no outcomes"):
        ledger.resolve("dead")
    history = ledger.history("b2b2b2")
    assert history.report.revision == B and history.before is not None
    assert history.before.revision == A and history.before.tally.total == 2
    assert ledger.history().report.revision == "(none)"  # the newest


def test_an_ambiguous_revision_is_refused(ledger: Ledger) -> None:
    ledger.add([record(0, "abcd" + "1" * 36), record(1, "abcd" + "2" * 36)])
    with pytest.raises(LedgerError, match="several revisions"):
        ledger.resolve("abcd")


def test_reports_narrowed_by_robot_and_time(ledger: Ledger) -> None:
    ledger.add(
        [
            record(0, robot="r1", ended_at=100.0),
            record(1, robot="r1", ended_at=200.0, outcome=OutcomeState.FAILED),
            record(2, robot="r2", ended_at=300.0),
        ],
        received_at=400.0,
    )
    assert ledger.report(A).tally.total == 3
    assert ledger.report(A, robot="r1").tally.failed == 1
    assert ledger.report(A, robot="r1").robots.keys() == {"r1"}
    assert ledger.report(A, since=150.0).tally.total == 2
    assert ledger.report(A, robot="r2", since=301.0).tally.total == 0


def test_a_robot_clock_ahead_is_not_the_future(ledger: Ledger) -> None:
    ledger.add([record(0, ended_at=10**10)], received_at=1000.0)
    assert ledger.report(A, since=999.0).tally.total == 1
    assert ledger.report(A, since=1001.0).tally.total == 0


def test_the_ledger_is_bounded_by_size_and_age(ledger: Ledger) -> None:
    ledger.add([record(i, A) for i in range(3000)], received_at=100.0)
    ledger.add([record(i, B) for i in range(3000, 5000)], received_at=200.0)
    assert ledger.prune(max_age=10**9, max_records=4000, now=300.0) == 1000
    assert ledger.count() == 4000
    assert ledger.prune(max_age=150.0, max_records=10**6, now=300.0) == 2000  # A's, older
    assert ledger.count() == 2000
    assert [seen.revision for seen in ledger.revisions()] == [B]  # A has no outcomes left
    assert ledger.prune(max_age=150.0, max_records=10**6, now=300.0) == 0


def test_a_missing_ledger_is_a_clear_error_for_a_reader(tmp_path: Path) -> None:
    with pytest.raises(LedgerError, match="no ledger at"):
        Ledger.open(ledger_path(tmp_path), read_only=True)


@pytest.mark.parametrize("kind", ["garbage", "truncated", "another database"])
def test_an_unreadable_ledger_is_set_aside_and_a_new_one_started(tmp_path: Path, kind: str) -> None:
    path = ledger_path(tmp_path)
    if kind == "garbage":
        path.write_bytes(b"\x00garbage" * 2000)
    elif kind == "truncated":
        with Ledger.open_or_start(path) as full:
            for start in range(0, 20_000, 1000):
                full.add([record(i) for i in range(start, start + 1000)])
            full.checkpoint()
        data = path.read_bytes()
        path.with_name(path.name + "-wal").unlink(missing_ok=True)
        path.write_bytes(data[: len(data) // 3])
    else:
        db = sqlite3.connect(path)
        with db:  # committed
            db.execute("CREATE TABLE notes (text)")
        db.close()
    with pytest.raises(LedgerError) as refused:
        Ledger.open(path, read_only=True)
    assert refused.value.unreadable and "\n" not in str(refused.value)
    said: list[str] = []
    with Ledger.open_or_start(path, said.append) as fresh:
        assert fresh.count() == 0
        fresh.add([record(0)])
    assert len(said) == 1 and "kept aside as ledger.sqlite3.unreadable-" in said[0]
    aside = [p for p in tmp_path.glob("ledger.sqlite3.unreadable-*") if "-wal" not in p.name]
    assert len([p for p in aside if not p.name.endswith("-shm")]) == 1


def test_a_ledger_of_a_newer_robotconf_is_left_alone(tmp_path: Path) -> None:
    path = ledger_path(tmp_path)
    with Ledger.open_or_start(path) as ledger:
        ledger.add([record(0)])
    db = sqlite3.connect(path)
    db.execute(f"PRAGMA user_version={SCHEMA_VERSION + 1}")
    db.close()
    with pytest.raises(LedgerError, match="newer robotconf") as refused:
        Ledger.open_or_start(path)
    assert not refused.value.unreadable
    assert path.exists() and not list(tmp_path.glob("*.unreadable-*"))


def test_only_the_newest_unreadable_ledgers_are_kept(tmp_path: Path) -> None:
    path = ledger_path(tmp_path)
    for n in range(KEEP_ASIDE + 2):
        path.write_bytes(b"not a ledger %d" % n * 1000)
        Ledger.open_or_start(path, lambda line: None).close()
    assert len(list(tmp_path.glob("ledger.sqlite3.unreadable-*"))) == KEEP_ASIDE


def test_where_history_looks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    repo = tmp_path / "repo"
    assert find_ledger(repo, "lab/one", tmp_path / "given") == tmp_path / "given/ledger.sqlite3"
    default = find_ledger(repo, "lab/one")
    assert default == tmp_path / "xdg/robotconf/reconciler/lab_one/ledger.sqlite3"
    up = repo / ".robotconf/up/state/ledger.sqlite3"
    up.parent.mkdir(parents=True)
    up.touch()
    assert find_ledger(repo, "lab/one") == up


def test_the_tallies_kept_beside_agree_with_the_outcomes(ledger: Ledger) -> None:
    """A report reads the tallies; one narrowed by time (since=0: everything) reads the rows."""
    states = list(OutcomeState)
    ledger.add(
        [record(i, A, f"r{i % 7}", states[i % 4], ended_at=100.0 + i) for i in range(3000)],
        received_at=100.0,
    )
    ledger.add([record(i, A, "r1", OutcomeState.FAILED) for i in range(2990, 3100)])  # some again
    ledger.add([record(i, B, "r2") for i in range(3100, 5000)], received_at=200.0)
    for _ in range(2):
        for revision in (A, B):
            assert ledger.report(revision) == ledger.report(revision, since=0.0)
            assert ledger.report(revision, robot="r1") == ledger.report(
                revision, robot="r1", since=0.0
            )
        ledger.prune(max_age=10**9, max_records=3000, now=300.0)  # and after pruning
    assert ledger.report(A).tally.total == 1100 and ledger.report(B).tally.total == 1900


def test_a_stale_goal_that_ends_after_all_is_counted_by_its_end(ledger: Ledger) -> None:
    # The agent calls goal g0 stale (seq 0), then the brain ends it (seq 5, same run and goal):
    # one goal, counted once, as it ended; in one batch or across two.
    stale = record(0, outcome=OutcomeState.STALE)
    ended = record(5, outcome=OutcomeState.FAILED).model_copy(update={"goal": "g0"})
    ledger.add([stale], received_at=1000.0)
    assert ledger.report(A).tally.stale == 1
    ledger.add([ended], received_at=1001.0)
    tally = ledger.report(A).tally
    assert (tally.stale, tally.failed, tally.total) == (0, 1, 1)
    assert ledger.count() == 1
    # Both in one batch, with another goal that only went stale (it stays stale).
    other_stale = record(7, outcome=OutcomeState.STALE).model_copy(update={"run": "run-2"})
    only_stale = record(8, outcome=OutcomeState.STALE).model_copy(update={"run": "run-2"})
    other_end = record(9).model_copy(update={"run": "run-2", "goal": "g7"})
    added = ledger.add([other_stale, only_stale, other_end], received_at=1002.0)
    assert added.duplicates == 0
    tally = ledger.report(A).tally
    assert (tally.stale, tally.failed, tally.succeeded, tally.total) == (1, 1, 1, 3)
    assert ledger.count() == 3
    # The tallies agree with the rows.
    assert ledger.report(A, since=0.0).tally == tally


def test_a_new_state_folder_is_the_reconciler_s_alone(tmp_path: Path) -> None:
    state = tmp_path / "made" / "state"
    Ledger.open_or_start(ledger_path(state)).close()
    assert state.stat().st_mode & 0o777 == 0o700


def test_the_stable_revisions_own_counts_per_scenario_come_from_its_report(
    tmp_path: Path,
) -> None:
    """compare: stable's fallback baseline, read by the loop's evidence counter from the
    ledger's tallies (the same ones `history` reports)."""
    from robotconf.configurator.render import FleetRender
    from robotconf.reconciler.evidence import Counts
    from robotconf.reconciler.evidence_feed import EvidenceCounter

    path = ledger_path(tmp_path)
    with Ledger.open_or_start(path) as writer:
        writer.add(
            [record(i) for i in range(3)]
            + [record(3, outcome=OutcomeState.FAILED), record(4, revision=B)]
        )
    counter = EvidenceCounter(path)
    try:
        ledger = counter._open()
        assert ledger is not None
        found = counter._stable_counts(ledger, FleetRender(A))
        assert found == {"delivery": Counts(succeeded=3, failed=1)}
    finally:
        counter.close()
