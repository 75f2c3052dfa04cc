"""A revision's page, pure: what the ledger kept of it beside the revision before (per scenario
and task, per robot, the rate's change), what its robots report now, and what is said when the
ledger holds nothing or cannot be read. The ledger is a real SQLite file, written as the
reconciler's feed writes it and read through the page's own adapter (LedgerHistory)."""

from __future__ import annotations

from pathlib import Path

import pytest

from robotconf.contract.goals import OutcomeRecord, OutcomeState
from robotconf.readmodel.ledger import Ledger, ledger_path
from robotconf.readmodel.outcomes import History
from robotconf.readmodel.robot_goals import RobotGoals, bounded
from robotconf.workstation.ui.auth import ANONYMOUS
from robotconf.workstation.ui.revision_page import revision_page
from robotconf.workstation.ui.revisions import (
    CachedHistory,
    HistoryError,
    LedgerHistory,
    rate_change,
)
from tests.support.goals_summaries import AT, REV1, REV2, summary
from tests.unit.ui.fleets import fleet, row, snapshot
from tests.unit.ui.test_pages import assert_no_inline_code, tags

HOSTILE = "<script>alert(1)</script>"


def outcome(
    seq: int,
    revision: str,
    scenario: str,
    task: str,
    state: OutcomeState,
    robot: str = "tb3-09",
    code: str | None = None,
    duration: float | None = None,
) -> OutcomeRecord:
    return OutcomeRecord(
        robot_id=robot,
        revision=revision,
        digest=None,
        scenario=scenario,
        run=f"run-{revision[:4]}",
        seq=seq,
        goal=f"g{seq}",
        task=task,
        outcome=state,
        code=code,
        ended_at=AT - 100 + seq,
        duration=duration,
    )


def keep(path: Path) -> LedgerHistory:
    """A real ledger file: REV1 first (Delivery 9 of 10, Patrol 3 of 3), then REV2 (Delivery 6
    of 10 with failure codes and a canceled goal, Guide 5 of 5); robots tb3-01 (1 of 5),
    tb3-02 (10 of 10) and a hostile id's one canceled goal."""
    S, F, X = OutcomeState.SUCCEEDED, OutcomeState.FAILED, OutcomeState.CANCELED
    before = [outcome(i, REV1, "delivery-gazebo", "Delivery", S if i < 9 else F) for i in range(10)]
    before += [outcome(10 + i, REV1, "patrol", "Patrol", S) for i in range(3)]
    now = [
        outcome(100 + i, REV2, "delivery-gazebo", "Delivery", F, "tb3-01", "NAV2_TIMEOUT")
        for i in range(3)
    ]
    now += [outcome(103, REV2, "delivery-gazebo", "Delivery", F, "tb3-01", "E_BLOCKED")]
    now += [outcome(104, REV2, "delivery-gazebo", "Delivery", S, "tb3-01", duration=41.5)]
    now += [
        outcome(105 + i, REV2, "delivery-gazebo", "Delivery", S, "tb3-02", duration=41.5)
        for i in range(5)
    ]
    now += [outcome(110 + i, REV2, "guide-gazebo", "Guide", S, "tb3-02") for i in range(5)]
    # The feed refuses such an id (readmodel/outcomes.py); the page escapes it all the same.
    now += [outcome(120, REV2, "delivery-gazebo", "Delivery", X, HOSTILE)]
    with Ledger.open_or_start(ledger_path(path)) as ledger:
        ledger.add(before, received_at=AT - 50)
        ledger.add(now, received_at=AT)
    return LedgerHistory(ledger_path(path))


def kept(path: Path) -> History:
    found = keep(path).compare(REV2[:8])
    assert found is not None
    return found


def test_a_revision_beside_the_one_before_per_scenario_and_task_and_robot(tmp_path: Path) -> None:
    snap = snapshot(
        fleet([row("tb3-01", goals=RobotGoals.of(bounded(summary("tb3-01", revision=REV2))))])
    )
    page = revision_page(snap, REV2, ANONYMOUS, kept(tmp_path))
    found = {
        (a["data-scenario"], a["data-task"]): a["data-rate-change"]
        for tag, a in tags(page)
        if tag == "tr" and "data-task" in a and "data-rate-change" in a
    }
    # Delivery: 60 % now, 90 % before; Guide new; Patrol ran only before.
    assert found == {
        ("delivery-gazebo", "Delivery"): "-30 pts",
        ("guide-gazebo", "Guide"): "-",
        ("patrol", "Patrol"): "-",
    }
    assert 'data-total-rate="73%"' in page  # 11 of 15
    assert "NAV2_TIMEOUT ×3" in page and "42 s" in page
    assert f'href="/revisions/{REV1}"' in page
    robots = [
        a["data-robot-result"] for tag, a in tags(page) if tag == "tr" and "data-robot-result" in a
    ]
    assert robots == ["tb3-01", "tb3-02", HOSTILE]  # the worst first; no rate last
    # The live part: its robots' summaries now.
    assert f'data-revision="{REV2}" data-rate="75%"' in page
    assert "<script>alert" not in page
    assert_no_inline_code(page)


def test_a_revision_the_ledger_does_not_hold_or_cannot_read(tmp_path: Path) -> None:
    snap = snapshot(fleet([row("tb3-01")]))
    empty = revision_page(snap, REV1, ANONYMOUS, None)
    assert 'data-ledger="empty"' in empty and "No robot reports goals" in empty
    broken = revision_page(snap, REV1, ANONYMOUS, None, f"the file is {HOSTILE}")
    assert 'data-ledger="unavailable"' in broken and "&lt;script&gt;" in broken
    alone = revision_page(snap, REV2, ANONYMOUS, History(kept(tmp_path).report, None))
    assert "no revision before it" in alone and 'data-rate-change="-"' in alone


def test_the_ledger_file_answers_the_page_or_says_why_not(tmp_path: Path) -> None:
    history = keep(tmp_path / "state")
    assert history.compare("abcd") is None  # a revision it holds nothing of
    found = history.compare(REV1)
    assert found is not None and found.before is None and found.report.tally.succeeded == 12
    with pytest.raises(HistoryError, match="no ledger at"):
        LedgerHistory(tmp_path / "nowhere" / "ledger.sqlite3").compare(REV1)
    garbage = tmp_path / "garbage.sqlite3"
    garbage.write_bytes(b"not a database at all" * 100)
    with pytest.raises(HistoryError):
        LedgerHistory(garbage).compare(REV1)
    assert garbage.read_bytes().startswith(b"not a database")  # a reader never sets it aside


def test_rate_changes_read_in_points() -> None:
    assert [rate_change(a, b) for a, b in ((0.6, 0.9), (0.5, 0.5), (0.91, 0.9), (None, 0.5))] == [
        "-30 pts",
        "±0 pts",
        "+1 pts",
        "-",
    ]


class Counting:
    """A ledger that counts the questions asked of it."""

    def __init__(self, answer: History | HistoryError | None) -> None:
        self.answer = answer
        self.asked = 0

    def compare(self, revision: str) -> History | None:
        self.asked += 1
        if isinstance(self.answer, HistoryError):
            raise self.answer
        return self.answer


def test_the_ledger_is_asked_once_per_revision_a_while(tmp_path: Path) -> None:
    clock = [0.0]
    ledger = Counting(kept(tmp_path))
    cached = CachedHistory(ledger, ttl=10.0, size=2, clock=lambda: clock[0])
    assert cached.compare(REV2) is ledger.answer
    cached.compare(REV2)
    assert ledger.asked == 1
    clock[0] = 11.0
    cached.compare(REV2)
    assert ledger.asked == 2
    for rev in ("aaaa", "bbbb", REV2):  # only `size` revisions are kept
        cached.compare(rev)
    assert ledger.asked == 5
    refusing = CachedHistory(Counting(HistoryError("locked")), clock=lambda: 0.0)
    for _ in range(2):
        with pytest.raises(HistoryError, match="locked"):
            refusing.compare(REV1)
