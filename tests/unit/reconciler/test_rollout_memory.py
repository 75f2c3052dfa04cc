"""Rollouts judge only what the reconciler saw, and remember it: a robot that goes dark after
its wave was published has failed whatever its Will says; a restarted reconciler neither rolls
back a healthy wave nor counts a robot healthy it has not seen so."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from robotconf.configurator.render import FleetRender
from robotconf.contract.wire import AgentState, AgentStatus
from robotconf.reconciler.rollout import DARK_GRACE, RolloutInput, RolloutStep, roll_out
from robotconf.reconciler.wave_memory import WaveMemory, memory_of
from tests.support.lab import Lab
from tests.unit.reconciler.test_rollout import (
    CANARY,
    ROBOTS,
    T0,
    fleet,
    held,
    published,
    running,
    step,
)

HALF = ["tb3-01", "tb3-02", "tb3-03"]  # the canary and the 60% wave after it


@pytest.fixture
def two(lab: Lab) -> tuple[FleetRender, FleetRender]:
    return fleet(lab, "a"), fleet(lab, "b")


def offline(robots: list[str], since: float) -> dict[str, AgentStatus]:
    return {r: AgentStatus(robot_id=r, state=AgentState.OFFLINE, since=since) for r in robots}


def state(result: RolloutStep) -> str:
    assert result.status is not None
    return result.status.state


@pytest.mark.parametrize("will_since", [T0 - 3600, T0 + 1, T0 + 10**9])
def test_a_canary_dark_right_after_its_wave_was_published_has_failed(
    two: tuple[FleetRender, FleetRender], will_since: float
) -> None:
    stable, head = two
    # Online (running the stable request) as its wave is published...
    first = step(head, stable, held(stable), running(stable, ROBOTS))
    launches = {**held(stable), **held(head, CANARY)}
    # ... and the next thing the reconciler sees is its Last Will, dated whatever it is.
    dark = {**running(stable, ROBOTS), **offline(CANARY, will_since)}
    result = step(head, stable, launches, dark, first, T0 + 1)
    assert state(result) == "RolledBack" and result.status is not None
    assert result.status.failed == CANARY


def test_a_robot_whose_status_disappears_after_it_was_seen_has_failed(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable), running(stable, ROBOTS))
    launches = {**held(stable), **held(head, CANARY)}
    seen = step(head, stable, launches, running(stable, ROBOTS), first, T0 + 1)
    assert state(seen) == "Progressing"
    gone = running(stable, ROBOTS[1:])  # no status at all for the canary
    assert state(step(head, stable, launches, gone, seen, T0 + 2)) == "RolledBack"


def test_a_robot_offline_before_its_wave_is_absent_until_it_comes_back(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    off = {**running(stable, ROBOTS[1:]), **offline(CANARY, T0 + 50)}
    first = step(head, stable, held(stable), off)
    launches = {**held(stable), **held(head, CANARY)}
    waiting = step(head, stable, launches, off, first, T0 + 5)
    assert state(waiting) == "Progressing" and waiting.status is not None
    assert waiting.status.pending == CANARY
    # It comes back, gets its request (held retained), and dies of it: failed.
    back = step(head, stable, launches, running(stable, ROBOTS), waiting, T0 + 6)
    assert state(back) == "Progressing"
    assert state(step(head, stable, launches, off, back, T0 + 7)) == "RolledBack"


def test_a_failure_stays_a_failure_for_the_wave(two: tuple[FleetRender, FleetRender]) -> None:
    stable, head = two
    assert head.rollout is not None
    head.rollout = head.rollout.model_copy(update={"max_failures": 1})
    first = step(head, stable, held(stable), running(stable, ROBOTS))
    launches = {**held(stable), **held(head, CANARY)}
    second = step(head, stable, launches, running(head, CANARY), first, T0 + 10)
    assert second.status is not None and second.status.wave == 1
    launches = held(head, HALF) | held(stable, ["tb3-04", "tb3-05"])
    crashed = {**running(head, CANARY), **running(head, ["tb3-02"], AgentState.BACKOFF)}
    within = step(head, stable, launches, crashed, second, T0 + 11)
    assert within.status is not None and within.status.failed == ["tb3-02"]
    # It runs again, long enough to be healthy: it failed this wave all the same.
    again = step(head, stable, launches, running(head, HALF[:2]), within, T0 + 40, {"tb3-02": T0})
    assert again.status is not None and again.status.wave == 1
    assert again.status.failed == ["tb3-02"] and again.status.pending == ["tb3-03"]


def test_a_restarted_reconciler_keeps_what_the_wave_established(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable), running(stable, ROBOTS))
    launches = {**held(stable), **held(head, CANARY)}
    healthy = step(head, stable, launches, running(head, CANARY), first, T0 + 10)
    assert healthy.status is not None and healthy.status.wave == 1  # canary healthy: wave 2
    launches = held(head, HALF) | held(stable, ["tb3-04", "tb3-05"])
    wave = {**running(head, HALF), **running(stable, ["tb3-04", "tb3-05"])}
    since = {"tb3-01": T0, "tb3-02": T0 + 11, "tb3-03": T0 + 15}
    half = step(head, stable, launches, wave, healthy, T0 + 21, since)
    assert half.status is not None and half.status.wave == 1
    assert half.status.healthy == ["tb3-02"] and half.status.pending == ["tb3-03"]
    # Killed, restarted long after the wave's timeout (T0 + 10 + 100): a new process has seen
    # nobody running, and learns the statuses at T0 + 500. Its status is the Last Will, which
    # names the wave; the wave's record names what the wave established.
    restarted = {"watching_since": T0 + 500}
    resumed = step(head, stable, launches, wave, half, T0 + 500, {}, **restarted)
    assert state(resumed) == "Progressing" and resumed.status is not None
    assert resumed.status.wave == 1 and resumed.status.healthy == ["tb3-02"]
    assert resumed.status.pending == ["tb3-03"]  # not seen healthy by anyone yet
    seen = {"tb3-03": T0 + 500}
    done = step(head, stable, launches, wave, resumed, T0 + 510, seen, **restarted)
    assert done.status is not None and done.status.wave == 2


def test_a_restarted_reconciler_waits_healthy_after_for_robots_it_has_not_seen_healthy(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable), running(stable, ROBOTS))
    launches = {**held(stable), **held(head, CANARY)}
    early = step(head, stable, launches, running(head, CANARY), first, T0 + 5, {"tb3-01": T0 + 1})
    assert early.status is not None and early.status.pending == CANARY
    # Restarted after the wave's timeout: the canary has run all along, but this process first
    # sees it running at T0 + 300. It is neither failed (the clock counts from when the
    # reconciler watches again) nor healthy before healthy_after of being seen.
    restarted = {"since": {"tb3-01": T0 + 300}, "watching_since": T0 + 300}
    resumed = step(head, stable, launches, running(head, CANARY), early, T0 + 300, **restarted)
    assert state(resumed) == "Progressing" and resumed.status is not None
    assert resumed.status.pending == CANARY and resumed.recheck_at == T0 + 310
    later = step(head, stable, launches, running(head, CANARY), resumed, T0 + 310, **restarted)
    assert later.status is not None and later.status.wave == 1
    # Without a record (a broker that lost it), the retained status alone is as cautious.
    bare = early.status
    alone = step(head, stable, launches, running(head, CANARY), bare, T0 + 300, **restarted)
    assert alone.status is not None and alone.status.pending == CANARY


def test_a_wave_never_timed_out_while_the_reconciler_was_not_watching(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable), running(stable, ROBOTS))
    launches = {**held(stable), **held(head, CANARY)}
    starting = running(head, CANARY, AgentState.STARTING)
    resumed = step(head, stable, launches, starting, first, T0 + 150, {}, T0 + 150)
    assert state(resumed) == "Progressing" and resumed.recheck_at == T0 + 250
    late = step(head, stable, launches, starting, resumed, T0 + 250, {}, T0 + 150)
    assert state(late) == "RolledBack"  # a whole wave_timeout watched: failed


def test_statuses_learned_anew_forget_no_robot_but_do_not_blame_silence(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable), running(stable, ROBOTS))
    launches = {**held(stable), **held(head, CANARY)}
    # A broker restarted without its retained messages: no status for anyone yet.
    quiet = step(head, stable, launches, {}, first, T0 + 2, {}, T0 + 2)
    assert state(quiet) == "Progressing"
    assert quiet.status is not None and quiet.status.counts["failed"] == 0
    # The canary reconnects, runs the new request; then dies: failed again.
    back = step(head, stable, launches, running(head, CANARY), quiet, T0 + 3, {}, T0 + 2)
    assert state(back) == "Progressing"
    died = step(head, stable, launches, offline(CANARY, T0), back, T0 + 4, {}, T0 + 2)
    assert state(died) == "RolledBack"


def test_a_rejection_from_before_the_wave_is_not_its_failure(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    before = {"tb3-01": AgentStatus(robot_id="tb3-01", state=AgentState.REJECTED, since=T0 + 99)}
    first = step(head, stable, held(stable), before)
    launches = {**held(stable), **held(head, CANARY)}
    same = step(head, stable, launches, before, first, T0 + 1)
    assert state(same) == "Progressing"  # its `since` is later: not read, a robot's clock
    accepted = step(
        head, stable, launches, running(head, CANARY, AgentState.STARTING), same, T0 + 2
    )
    assert state(accepted) == "Progressing"
    old = {"tb3-01": AgentStatus(robot_id="tb3-01", state=AgentState.REJECTED, since=T0 - 99)}
    assert state(step(head, stable, launches, old, accepted, T0 + 3)) == "RolledBack"


def test_no_wave_is_published_before_the_statuses_are_known(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    blind = roll_out(RolloutInput(head, stable, None, held(stable), None, {}, T0))
    assert published(blind, head) == [] and blind.status is not None
    assert blind.status.state == "Progressing" and blind.status.wave_started_at is None
    assert "waiting for the robots' statuses" in blind.status.message
    seen = step(head, stable, held(stable), running(stable, ROBOTS), blind.status, T0 + 1)
    assert published(seen, head) == CANARY


def test_a_record_of_another_wave_or_garbled_is_not_trusted(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable), running(stable, ROBOTS))
    record = first.record
    assert record is not None
    assert memory_of(record, head.revision, 0, T0, CANARY) is not None
    assert memory_of(record, head.revision, 1, T0, CANARY) is None
    assert memory_of(record, head.revision, 0, T0 + 1, CANARY) is None
    assert memory_of(record, stable.revision, 0, T0, CANARY) is None
    assert memory_of(record, head.revision, 0, T0, ["tb3-02"]) is None
    for garbled in ("!!!", "AAAA", "A"):
        bad = record.model_copy(update={"seen": garbled})
        assert memory_of(bad, head.revision, 0, T0, CANARY) is None


@given(
    st.lists(st.from_regex(r"[a-z0-9][a-z0-9._-]{0,8}", fullmatch=True), unique=True),
    st.data(),
)
def test_sets_survive_their_record(robots: list[str], data: st.DataObject) -> None:
    members = sorted(robots)
    pick = st.sets(st.sampled_from(members)) if members else st.just(set[str]())
    memory = WaveMemory("r" * 40, 2, T0, members, T0, *(data.draw(pick) for _ in range(4)))
    back = memory_of(memory.record(), "r" * 40, 2, T0, members)
    assert back is not None
    assert (back.seen, back.healthy, back.failed, back.rejecting) == (
        memory.seen,
        memory.healthy,
        memory.failed,
        memory.rejecting,
    )


def test_dark_counts_once_it_has_lasted_while_the_reconciler_watched(
    two: tuple[FleetRender, FleetRender],
) -> None:
    """A broker that shuts down publishes every Last Will just before it drops the reconciler:
    a robot is gone only once it has stayed dark for DARK_GRACE, watched."""
    stable, head = two
    first = step(head, stable, held(stable), running(stable, ROBOTS))
    launches = {**held(stable), **held(head, CANARY)}
    will = {**running(stable, ROBOTS[1:]), **offline(CANARY, T0)}
    dark = {"tb3-01": T0 + 1}
    moment = roll(head, stable, launches, will, first, T0 + 1.5, dark)
    assert state(moment) == "Progressing" and moment.recheck_at == T0 + 1 + DARK_GRACE
    gone = roll(head, stable, launches, will, moment, T0 + 1 + DARK_GRACE, dark)
    assert state(gone) == "RolledBack"


def test_a_robot_dark_when_statuses_are_learned_anew_has_until_the_deadline(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable), running(stable, ROBOTS))
    launches = {**held(stable), **held(head, CANARY)}
    seen = step(head, stable, launches, running(head, CANARY), first, T0 + 1)
    # The broker restarted: every Will it published as it stopped is what it holds now.
    wills = offline(ROBOTS, T0)
    again = {"watching_since": T0 + 5, "dark_since": dict.fromkeys(ROBOTS, T0 + 5)}
    doubt = roll(head, stable, launches, wills, seen, T0 + 50, **again)
    assert state(doubt) == "Progressing" and doubt.recheck_at == T0 + 105
    # Back: judged as ever.
    back = roll(head, stable, launches, running(head, CANARY), doubt, T0 + 51, **again)
    assert state(back) == "Progressing" and back.status is not None
    assert back.status.counts["failed"] == 0
    # Never back: failed at the wave's deadline, counted from when it was watched again.
    assert state(roll(head, stable, launches, wills, doubt, T0 + 104, **again)) == "Progressing"
    assert state(roll(head, stable, launches, wills, doubt, T0 + 105, **again)) == "RolledBack"


def roll(
    head: FleetRender,
    stable: FleetRender,
    launches: dict[str, str | None],
    statuses: dict[str, AgentStatus],
    previous: RolloutStep,
    now: float,
    dark_since: dict[str, float] | None = None,
    watching_since: float = 0.0,
) -> RolloutStep:
    """A step with the reconciler's own dark clocks."""
    return roll_out(
        RolloutInput(
            head,
            stable,
            previous.status,
            launches,
            statuses,
            {},
            now,
            previous.record,
            watching_since,
            dark_since or {},
        )
    )
