"""A revision's page, pure: what the ledger kept of it beside the revision before (per scenario
and task, per robot, the rate's change), what its robots report now, and what is said when the
ledger holds nothing or cannot be read. The ledger's answers are made directly here."""

from __future__ import annotations

import pytest

from reconciler.robot_goals import RobotGoals, bounded
from tests.support.goals_summaries import AT, REV1, REV2, summary
from tests.unit.ui.fleets import fleet, row, snapshot
from tests.unit.ui.test_pages import assert_no_inline_code, tags
from workstation.ui.auth import ANONYMOUS
from workstation.ui.revision_page import revision_page
from workstation.ui.revisions import (
    CachedHistory,
    Comparison,
    HistoryError,
    RevisionResult,
    Tally,
    rate_change,
)

HOSTILE = "<script>alert(1)</script>"


def kept() -> Comparison:
    now = RevisionResult(
        REV2,
        tasks={
            ("delivery-gazebo", "Delivery"): Tally(
                6, 4, 1, 0, 41.5, (("NAV2_TIMEOUT", 3), (HOSTILE, 1))
            ),
            ("guide-gazebo", "Guide"): Tally(5, 0),
        },
        robots={"tb3-01": Tally(1, 4), "tb3-02": Tally(10, 0), HOSTILE: Tally(0, 0, 1)},
        first_at=AT - 3600,
        last_at=AT,
    )
    before = RevisionResult(
        REV1,
        tasks={("delivery-gazebo", "Delivery"): Tally(9, 1), ("patrol", "Patrol"): Tally(3, 0)},
    )
    return Comparison(now, before)


def test_a_revision_beside_the_one_before_per_scenario_and_task_and_robot() -> None:
    snap = snapshot(
        fleet([row("tb3-01", goals=RobotGoals.of(bounded(summary("tb3-01", revision=REV2))))])
    )
    page = revision_page(snap, REV2, ANONYMOUS, kept())
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


def test_a_revision_the_ledger_does_not_hold_or_cannot_read() -> None:
    snap = snapshot(fleet([row("tb3-01")]))
    empty = revision_page(snap, REV1, ANONYMOUS, None)
    assert 'data-ledger="empty"' in empty and "No robot reports goals" in empty
    broken = revision_page(snap, REV1, ANONYMOUS, None, f"the file is {HOSTILE}")
    assert 'data-ledger="unavailable"' in broken and "&lt;script&gt;" in broken
    alone = revision_page(snap, REV2, ANONYMOUS, Comparison(kept().revision))
    assert "no revision before it" in alone and 'data-rate-change="-"' in alone


def test_rate_changes_read_in_points() -> None:
    assert [rate_change(a, b) for a, b in ((0.6, 0.9), (0.5, 0.5), (0.91, 0.9), (None, 0.5))] == [
        "-30 pts",
        "±0 pts",
        "+1 pts",
        "-",
    ]


class Counting:
    """A ledger that counts the questions asked of it."""

    def __init__(self, answer: Comparison | HistoryError | None) -> None:
        self.answer = answer
        self.asked = 0

    def compare(self, revision: str) -> Comparison | None:
        self.asked += 1
        if isinstance(self.answer, HistoryError):
            raise self.answer
        return self.answer


def test_the_ledger_is_asked_once_per_revision_a_while() -> None:
    clock = [0.0]
    ledger = Counting(kept())
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
