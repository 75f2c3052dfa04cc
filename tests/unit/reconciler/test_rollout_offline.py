"""`rollout.offline`: a robot off since before its wave was published is skipped (the default),
waited for or failed; one that goes dark after it was seen has failed whatever the policy says."""

from __future__ import annotations

import pytest

from robotconf.configurator.plan import format_plan_text, make_plan, plan_as_json
from robotconf.configurator.render import FleetRender
from robotconf.configurator.types import RolloutPolicy
from robotconf.contract.wire import AgentState, AgentStatus
from robotconf.readmodel.verdicts import rollout_line
from robotconf.reconciler.rollout import DARK_GRACE, RolloutInput, RolloutStep, roll_out
from tests.support.lab import Lab
from tests.unit.reconciler.test_rollout import CANARY, ROBOTS, T0, fleet, held, published, running
from tests.unit.reconciler.test_rollout_memory import offline, state

HALF = ["tb3-01", "tb3-02", "tb3-03"]  # the canary and the 60% wave after it


def two(lab: Lab, policy: str) -> tuple[FleetRender, FleetRender]:
    return fleet(lab, "a", offline=policy), fleet(lab, "b", offline=policy)


def test_skip_is_the_default() -> None:
    policy = RolloutPolicy.model_validate({"waves": [{"name": "all"}]})
    assert policy.offline == "skip"


def test_skip_moves_on_at_once_without_a_robot_off_since_before_its_wave(lab: Lab) -> None:
    stable, head = two(lab, "skip")
    off = {**running(stable, ROBOTS[1:]), **offline(CANARY, T0 - 3600)}
    first = step(head, stable, held(stable), off)
    # The canary wave has nobody to wait for: the next wave is published in the same step,
    # not at the canary wave's timeout.
    assert state(first) == "Progressing" and first.status is not None
    assert first.status.wave == 1 and published(first, head) == HALF
    assert first.status.offline == CANARY and first.status.counts["offline"] == 1
    assert first.status.failed == [] and first.status.pending == HALF[1:]
    # The others become healthy: complete, the canary still listed as offline (to get it).
    on = {**running(head, ROBOTS[1:]), **offline(CANARY, T0 - 3600)}
    done = step(head, stable, held(head), on, first, T0 + 10)
    assert state(done) == "Complete" and done.status is not None
    assert done.status.offline == CANARY and published(done, head) == ROBOTS


def test_wait_waits_for_it_until_the_wave_timeout(lab: Lab) -> None:
    stable, head = two(lab, "wait")
    off = {**running(stable, ROBOTS[1:]), **offline(CANARY, T0 - 3600)}
    first = step(head, stable, held(stable), off)
    assert first.status is not None and first.status.wave == 0
    assert first.status.pending == CANARY and first.recheck_at == T0 + 100


def test_fail_counts_it_failed_at_once(lab: Lab) -> None:
    stable, head = two(lab, "fail")
    off = {**running(stable, ROBOTS[1:]), **offline(CANARY, T0 - 3600)}
    first = step(head, stable, held(stable), off)
    assert state(first) == "RolledBack" and first.status is not None
    assert first.status.failed == CANARY


@pytest.mark.parametrize("policy", ["skip", "wait", "fail"])
def test_a_robot_online_as_its_wave_was_published_then_dark_has_failed(
    lab: Lab, policy: str
) -> None:
    stable, head = two(lab, policy)
    first = step(head, stable, held(stable), running(stable, ROBOTS))
    launches = {**held(stable), **held(head, CANARY)}
    dark = {**running(stable, ROBOTS[1:]), **offline(CANARY, T0 - 3600)}
    # Its Will says it has been off for an hour: it was online as the wave was published.
    result = step(head, stable, launches, dark, first, T0 + 1, dark_since={"tb3-01": T0 + 1})
    assert state(result) == "Progressing"  # dark a moment: not judged yet
    gone = step(head, stable, launches, dark, result, T0 + 1 + DARK_GRACE, {"tb3-01": T0 + 1})
    assert state(gone) == "RolledBack" and gone.status is not None
    assert gone.status.failed == CANARY and gone.status.offline == []


def test_a_robot_dark_a_moment_is_not_skipped_before_the_grace(lab: Lab) -> None:
    stable, head = two(lab, "skip")
    off = {**running(stable, ROBOTS[1:]), **offline(CANARY, T0)}
    first = step(head, stable, held(stable), off, dark_since={"tb3-01": T0})
    assert first.status is not None and first.status.wave == 0
    assert first.status.pending == CANARY and first.recheck_at == T0 + DARK_GRACE
    later = step(head, stable, held(stable), off, first, T0 + DARK_GRACE, {"tb3-01": T0})
    assert later.status is not None and later.status.wave == 1


def test_skipped_then_back_in_its_wave_is_judged_like_any_robot(lab: Lab) -> None:
    stable, head = two(lab, "skip")
    off = {**running(stable, ROBOTS[1:]), **offline(["tb3-02"], T0 - 3600)}
    # The canary is healthy; wave 1 goes out while tb3-02 is off: skipped, tb3-03 pending.
    first = step(head, stable, held(stable), {**off, **running(stable, CANARY)})
    launches = {**held(stable), **held(head, CANARY)}
    second = step(head, stable, launches, {**off, **running(head, CANARY)}, first, T0 + 10)
    assert second.status is not None and second.status.wave == 1
    assert second.status.offline == ["tb3-02"] and second.status.pending == ["tb3-03"]
    assert "tb3-02" in published(second, head)  # held retained for it: it gets it when back
    # Back, it runs the new request and crashes: its wave has failed.
    launches = held(head, HALF) | held(stable, ["tb3-04", "tb3-05"])
    back = {**off, **running(head, CANARY), "tb3-02": running(head, ["tb3-02"])["tb3-02"]}
    seen = step(head, stable, launches, back, second, T0 + 12)
    assert seen.status is not None and seen.status.offline == []
    crashed = {**back, **offline(["tb3-02"], T0 + 13)}
    dead = step(head, stable, launches, crashed, seen, T0 + 13 + DARK_GRACE, {"tb3-02": T0 + 13})
    assert state(dead) == "RolledBack" and dead.status is not None
    assert dead.status.failed == ["tb3-02"]


def test_a_restarted_reconciler_keeps_a_skipped_robot_skipped_and_a_seen_one_doubted(
    lab: Lab,
) -> None:
    stable, head = two(lab, "skip")
    off = {**running(stable, ROBOTS[2:]), **offline(["tb3-01", "tb3-02"], T0 - 3600)}
    # The canary is off as its wave is published: skipped; wave 1 begins with tb3-03 online.
    first = step(head, stable, held(stable), off)
    assert first.status is not None and first.status.wave == 1
    launches = held(head, HALF) | held(stable, ["tb3-04", "tb3-05"])
    # tb3-03 goes dark; the reconciler restarts (statuses learned anew at T0 + 50).
    dark = {**off, **offline(["tb3-03"], T0 + 40)}
    again = step(head, stable, launches, dark, first, T0 + 60, watching_since=T0 + 50)
    assert again.status is not None and again.status.wave == 1
    assert again.status.offline == ["tb3-01", "tb3-02"]  # tb3-02: off before its wave
    assert again.status.pending == ["tb3-03"]  # doubted until the deadline, not skipped


def step(  # the memory tests' step, with the robots' dark times
    head: FleetRender,
    stable: FleetRender,
    launches: dict[str, str | None],
    statuses: dict[str, AgentStatus],
    previous: RolloutStep | None = None,
    now: float = T0,
    dark_since: dict[str, float] | None = None,
    watching_since: float = 0.0,
    lost: str | None = None,
) -> RolloutStep:
    since = {r: T0 for r, s in statuses.items() if s.digest == head.requests[r].digest}
    return roll_out(
        RolloutInput(
            head,
            stable,
            previous.status if previous else None,
            launches,
            statuses,
            since,
            now,
            previous.record if previous else None,
            watching_since,
            dark_since or {},
            statuses_lost=lost,
        )
    )


LOST = "its sync marker was dropped after 1,000 retained message(s)"


def test_a_robot_whose_status_the_broker_dropped_is_waited_for_not_offline(lab: Lab) -> None:
    """The statuses' read is known to lack messages (a queue limit): a robot without any
    status may be one of them, so it is neither skipped as offline nor failed as dark; it is
    waited for until the wave's timeout, like any robot not heard from."""
    stable, head = two(lab, "skip")
    unread = running(stable, ROBOTS[1:])  # the canary's status is not in the read
    before = step(head, stable, held(stable), unread)
    assert before.status is not None and before.status.offline == CANARY  # not known lossy
    first = step(head, stable, held(stable), unread, lost=LOST)
    assert first.status is not None and first.status.wave == 0
    assert first.status.offline == [] and first.status.pending == CANARY
    assert "1 robot(s) without a status (tb3-01) waited for, not offline" in first.status.message
    assert "the broker dropped status messages" in first.status.message
    assert first.recheck_at == T0 + 100  # the wave's timeout
    # Its status read again (or republished): judged like any robot.
    back = {**running(stable, ROBOTS[1:]), **running(head, CANARY)}
    later = step(
        head, stable, {**held(stable), **held(head, CANARY)}, back, first, T0 + 10, lost=LOST
    )
    assert later.status is not None and later.status.wave == 1 and later.status.failed == []


def test_a_seen_robot_whose_status_is_missing_from_a_lossy_read_is_not_failed_as_dark(
    lab: Lab,
) -> None:
    stable, head = two(lab, "skip")
    first = step(head, stable, held(stable), running(stable, ROBOTS))
    launches = {**held(stable), **held(head, CANARY)}
    unread = running(stable, ROBOTS[1:])
    late = T0 + 1 + DARK_GRACE
    gone = step(head, stable, launches, unread, first, late, {"tb3-01": T0 + 1})
    assert state(gone) == "RolledBack"  # known complete: its status gone is darkness
    kept = step(head, stable, launches, unread, first, late, {"tb3-01": T0 + 1}, lost=LOST)
    assert state(kept) == "Progressing" and kept.status is not None
    assert kept.status.failed == [] and kept.status.pending == CANARY


def test_status_and_plan_show_the_skipped_robots_and_the_policy(lab: Lab) -> None:
    stable, head = two(lab, "skip")
    off = {**running(stable, ROBOTS[1:]), **offline(CANARY, T0 - 3600)}
    first = step(head, stable, held(stable), off)
    assert first.status is not None
    line = rollout_line(first.status)
    assert "0 healthy, 0 failed, 2 pending, 1 offline;" in line
    assert line.endswith("; offline (get it when back): tb3-01")
    assert first.status.model_dump(mode="json")["offline"] == ["tb3-01"]
    assert head.rollout is not None
    plan = make_plan(stable, head, head.rollout)
    assert plan_as_json(plan)["offline"] == "skip"
    assert format_plan_text(plan).splitlines()[1] == (
        "rollout in waves: canary, half, all; robots that are off are skipped, and get it when"
        " they reconnect"
    )


def test_a_bad_offline_value_is_one_error_at_its_line(lab: Lab) -> None:
    fleet(lab, "a", offline="skip")
    lab.replace("configs/fleet.yaml", "offline: skip", "offline: ignore")
    d = lab.only("RC103")
    assert d.line == lab.line_of("configs/fleet.yaml", "offline: ignore")
    assert "'skip'" in d.message and "'wait'" in d.message and "'fail'" in d.message


def test_a_share_of_failures_counts_only_the_robots_that_were_on(lab: Lab) -> None:
    stable, head = two(lab, "skip")
    assert head.rollout is not None
    head.rollout = head.rollout.model_copy(update={"max_failures": "50%"})
    off = {**running(stable, ROBOTS[2:]), **offline(["tb3-02"], T0 - 3600)}
    first = step(head, stable, held(stable), {**off, **running(stable, CANARY)})
    launches = {**held(stable), **held(head, CANARY)}
    second = step(head, stable, launches, {**off, **running(head, CANARY)}, first, T0 + 10)
    assert second.status is not None and second.status.wave == 1
    # Of the wave's two robots one is off: 50% of the one that was on tolerates no failure.
    crashed = {**off, **running(head, CANARY), **running(head, ["tb3-03"], AgentState.BACKOFF)}
    launches = held(head, HALF) | held(stable, ["tb3-04", "tb3-05"])
    result = step(head, stable, launches, crashed, second, T0 + 11)
    assert state(result) == "RolledBack" and result.status is not None
    assert result.status.failed == ["tb3-03"] and result.status.offline == ["tb3-02"]
