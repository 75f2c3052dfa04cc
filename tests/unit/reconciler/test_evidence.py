"""Wave evidence, pure: which outcomes count (the wave's robots on the new digest, the stable
robots on theirs, inside the window), counted once, and the verdicts they give."""

from __future__ import annotations

import pytest

from robotconf.configurator.types import Verify
from robotconf.readmodel.outcomes import Row
from robotconf.reconciler.evidence import (
    Counts,
    EvidenceKey,
    Roles,
    WaveEvidence,
    judge,
    new_evidence,
)

T0 = 1_000_000.0
KEY = EvidenceKey("a" * 40, 1, T0)
ROLES = Roles(new={"n1": "new-1", "n2": "new-2"}, stable={"s1": "old-1", "s2": "old-2"})


def evidence(verify: Verify) -> WaveEvidence:
    return new_evidence(KEY, ROLES, verify)


class Rows:
    """Ledger rows with growing ids."""

    def __init__(self) -> None:
        self.next = 0

    def __call__(
        self,
        robot: str,
        digest: str | None,
        outcome: str,
        n: int = 1,
        code: str | None = None,
        at: float = T0 + 1,
        scenario: str = "delivery",
    ) -> list[Row]:
        rows = []
        for _ in range(n):
            self.next += 1
            rows.append(Row(self.next, robot, digest, scenario, outcome, code, at))
        return rows


@pytest.fixture
def rows() -> Rows:
    return Rows()


def test_only_the_waves_robots_on_the_new_digest_count_as_its_evidence(rows: Rows) -> None:
    found = evidence(Verify(min_goals=2))
    found.add(rows("n1", "new-1", "succeeded"))
    found.add(rows("n1", "old-1", "failed"))  # its previous request: not the wave's
    found.add(rows("n2", "new-1", "failed"))  # another robot's digest
    found.add(rows("x9", "new-1", "failed"))  # not a robot of the wave
    found.add(rows("s1", "old-1", "failed"))  # a stable robot: the comparison side
    found.add(rows("n2", None, "failed"))
    assert found.new == {"delivery": Counts(1, 0, 0)}
    assert found.stable == {"delivery": Counts(0, 1, 0)}
    assert found.reporting == {"n1"}


def test_outcomes_outside_the_window_do_not_count(rows: Rows) -> None:
    verify = Verify(timeout="1m")
    found = evidence(verify)
    found.add(rows("n1", "new-1", "succeeded", at=T0 - 1))  # before the wave was published
    found.add(rows("n1", "new-1", "succeeded", at=T0 + 61))  # after its deadline
    found.add(rows("n1", "new-1", "failed", at=T0 + 60))
    assert found.new == {"delivery": Counts(0, 1, 0)}


def test_a_row_is_counted_once_however_often_it_is_read(rows: Rows) -> None:
    found = evidence(Verify())
    batch = rows("n1", "new-1", "succeeded", n=3)
    found.add(batch)
    found.add(batch)
    found.add(batch[1:])
    assert found.new["delivery"].succeeded == 3 and found.last_id == batch[-1].id


def test_no_verdict_while_too_few_goals_ended_then_inconclusive_at_the_deadline(
    rows: Rows,
) -> None:
    verify = Verify(min_goals=5, success_rate=0.8, timeout=100)
    found = evidence(verify)
    found.add(rows("n1", "new-1", "succeeded", n=3))
    found.add(rows("n1", "new-1", "canceled", n=5))  # called off: says nothing of the work
    gathering = judge(verify, found, T0 + 50)
    assert gathering.verdict is None and gathering.goals == 3 and gathering.canceled == 5
    assert gathering.message.startswith("3 of 5 goals")
    late = judge(verify, found, T0 + 100)
    assert late.verdict == "Inconclusive"


def test_a_rate_below_the_threshold_fails_and_above_passes(rows: Rows) -> None:
    verify = Verify(min_goals=10, success_rate=0.9)
    good, bad = evidence(verify), evidence(verify)
    good.add(rows("n1", "new-1", "succeeded", n=9) + rows("n2", "new-2", "failed", n=1))
    bad.add(rows("n1", "new-1", "succeeded", n=8) + rows("n2", "new-2", "failed", n=2))
    passed, failed = judge(verify, good, T0 + 1), judge(verify, bad, T0 + 1)
    assert passed.verdict == "Successful" and passed.rate == pytest.approx(0.9)
    assert "90% ≥ 90%" in passed.message and passed.robots == 2
    assert failed.verdict == "Failed" and "80% < 90%" in failed.message


def test_failures_that_put_the_threshold_out_of_reach_fail_before_min_goals(rows: Rows) -> None:
    verify = Verify(min_goals=20, success_rate=0.9)
    found = evidence(verify)
    found.add(rows("n1", "new-1", "failed", n=2))
    assert judge(verify, found, T0 + 1).verdict is None  # 18 of 20 would still make 90%
    found.add(rows("n1", "new-1", "failed"))
    assert judge(verify, found, T0 + 1).verdict == "Failed"


def test_a_critical_code_fails_the_wave_at_once_whatever_the_sample(rows: Rows) -> None:
    verify = Verify(min_goals=100, critical=["COLLISION"])
    found = evidence(verify)
    found.add(rows("s1", "old-1", "failed", code="COLLISION"))  # a stable robot's: not this
    found.add(rows("n1", "new-1", "failed", code="NAV_TIMEOUT"))
    assert judge(verify, found, T0 + 1).verdict is None
    found.add(rows("n2", "new-2", "failed", code="COLLISION"))
    verdict = judge(verify, found, T0 + 1)
    assert verdict.verdict == "Failed" and verdict.critical == ["COLLISION"]
    assert "COLLISION" in verdict.message


def test_compared_with_the_stable_robots_over_the_same_window(rows: Rows) -> None:
    verify = Verify(min_goals=4, compare="stable", max_drop=0.2)
    found = evidence(verify)
    found.add(rows("s1", "old-1", "succeeded", n=10))  # the stable side: 100%
    found.add(rows("n1", "new-1", "succeeded", n=3) + rows("n2", "new-2", "failed", n=1))
    dropped = judge(verify, found, T0 + 1)  # 75%: 25 points below
    assert dropped.verdict == "Failed" and dropped.stable_rate == 1.0
    assert "delivery: 75% is 25% below the stable revision's 100%" in dropped.message
    found.add(rows("n1", "new-1", "succeeded", n=4))  # 7 of 8: 12.5 points below
    assert judge(verify, found, T0 + 1).verdict == "Successful"


def test_scenarios_are_compared_like_with_like(rows: Rows) -> None:
    verify = Verify(min_goals=2, compare="stable", max_drop=0.1)
    found = evidence(verify)
    found.add(rows("s1", "old-1", "succeeded", n=5, scenario="patrol"))
    found.add(rows("s2", "old-2", "failed", n=5, scenario="delivery"))
    found.add(rows("n1", "new-1", "failed", n=2, scenario="delivery"))  # as bad as its stable
    found.add(rows("n2", "new-2", "succeeded", n=2, scenario="patrol"))
    assert judge(verify, found, T0 + 1).verdict == "Successful"


def test_without_stable_robots_left_the_stable_revisions_own_counts_are_the_baseline(
    rows: Rows,
) -> None:
    verify = Verify(min_goals=2, compare="stable")
    found = evidence(verify)
    found.add(rows("n1", "new-1", "failed", n=2))
    assert judge(verify, found, T0 + 1).verdict == "Successful"  # nothing to compare with
    baseline = {"delivery": Counts(succeeded=50, failed=0)}
    verdict = judge(verify, found, T0 + 1, baseline)
    assert verdict.verdict == "Failed" and verdict.stable_goals == 50


def test_no_evidence_never_passes_unless_the_policy_says_so(rows: Rows) -> None:
    strict, lenient = Verify(timeout=10), Verify(min_goals=0, timeout=10)
    assert judge(strict, evidence(strict), T0 + 5).verdict is None
    assert judge(strict, evidence(strict), T0 + 10).verdict == "Inconclusive"
    assert judge(lenient, evidence(lenient), T0 + 1).verdict == "Successful"


def test_a_dry_run_says_so_in_its_words(rows: Rows) -> None:
    verify = Verify(min_goals=1, success_rate=1.0, dry_run=True)
    found = evidence(verify)
    found.add(rows("n1", "new-1", "failed"))
    verdict = judge(verify, found, T0 + 1)
    assert verdict.verdict == "Failed" and verdict.dry_run
    assert verdict.message.endswith("[dry run: not gating]")


@pytest.mark.parametrize(
    ("given", "problem"),
    [
        ({"max_drop": 0.2}, "max_drop needs compare"),
        ({"timeout": "soon"}, "a duration such as 30m"),
        ({"timeout": "3651d"}, "at most 3650d"),
        ({"timeout": 1e300}, "at most 3650d"),
        ({"timeout": 0}, "a duration such as 30m"),
        ({"success_rate": 1.5}, "less than or equal to 1"),
        ({"critical": ["bad code!"]}, "should match pattern"),
        ({"inconclusive": "wait"}, "'pause', 'fail' or 'pass'"),
    ],
)
def test_a_policy_that_cannot_be_judged_is_refused(given: dict[str, object], problem: str) -> None:
    with pytest.raises(ValueError, match=problem):
        Verify.model_validate(given)
