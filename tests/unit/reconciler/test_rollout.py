"""Rollouts, pure: waves published in order, gated by health judged on the new digest only,
stopped by failures (rollback or halt), paused, resumed from what the broker holds."""

from __future__ import annotations

from collections.abc import Mapping

import pytest

from robotconf.configurator.render import FleetRender, render_fleet
from robotconf.contract.wire import AgentState, AgentStatus, RolloutStatus
from robotconf.readmodel.verdicts import rollout_line
from robotconf.reconciler.rollout import RolloutInput, RolloutStep, roll_out
from tests.support.lab import Lab

ROBOTS = ["tb3-01", "tb3-02", "tb3-03", "tb3-04", "tb3-05"]
CANARY = ["tb3-01"]
SCENARIOS = ["delivery-gazebo", "guide-gazebo", "delivery-bluetooth-gazebo", "patrol-real"]
POLICY = """\
rollout:
  waves: [{name: canary, selector: {ring: canary}}, {name: half, percent: 60}, {name: all}]
  healthy_after: 10
  max_failures: 0
  wave_timeout: 100
  on_failure: %s
  paused: %s
  offline: %s
"""
T0 = 1_000_000.0


def fleet(
    lab: Lab,
    version: str,
    on_failure: str = "rollback",
    paused: bool = False,
    offline: str = "wait",  # these tests judge robots the reconciler waits for
) -> FleetRender:
    robots = "".join(
        f"  {robot}: {{scenario: {SCENARIOS[i % 4]}, name: bot {version}, "
        f"namespace: {robot.replace('-', '_')}"
        + (", labels: {ring: canary}" if robot in CANARY else "")
        + "}\n"
        for i, robot in enumerate(ROBOTS)
    )
    text = "robots:\n" + robots + POLICY % (on_failure, "true" if paused else "false", offline)
    lab.write("configs/fleet.yaml", text)
    checked = lab.check()
    assert checked.ok, checked.errors
    rendered = render_fleet(checked.repo)
    rendered.revision = version * 40
    return rendered


def held(fleet_: FleetRender, robots: list[str] = ROBOTS) -> dict[str, str | None]:
    return {robot: fleet_.requests[robot].digest for robot in robots}


def running(
    fleet_: FleetRender,
    robots: list[str],
    state: AgentState = AgentState.RUNNING,
    since: float = T0,
) -> dict[str, AgentStatus]:
    return {
        r: AgentStatus(robot_id=r, state=state, digest=fleet_.requests[r].digest, since=since)
        for r in robots
    }


def step(
    head: FleetRender,
    stable: FleetRender | None,
    launches: Mapping[str, str | None],
    statuses: Mapping[str, AgentStatus] | None = None,
    previous: RolloutStep | RolloutStatus | None = None,
    now: float = T0,
    since: Mapping[str, float] | None = None,
    watching_since: float = 0.0,
) -> RolloutStep:
    """One step after `previous`: a step of the same reconciler (its status and what its wave
    established) or a retained status alone."""
    statuses = {} if statuses is None else statuses
    if since is None:  # every robot running the head's digest was first seen running at T0
        since = {
            r: T0
            for r, s in statuses.items()
            if s.state is AgentState.RUNNING and s.digest == head.requests[r].digest
        }
    record = previous.record if isinstance(previous, RolloutStep) else None
    status = previous.status if isinstance(previous, RolloutStep) else previous
    return roll_out(
        RolloutInput(head, stable, status, launches, statuses, since, now, record, watching_since)
    )


def published(result: RolloutStep, head: FleetRender) -> list[str]:
    """Robots the step asks to hold the head's request (not merely kept)."""
    return sorted(
        r
        for r, req in result.requests.items()
        if req.digest == head.requests[r].digest and r not in result.keep
    )


@pytest.fixture
def two(lab: Lab) -> tuple[FleetRender, FleetRender]:
    return fleet(lab, "a"), fleet(lab, "b")


def test_the_first_step_publishes_the_first_wave_only(two: tuple[FleetRender, FleetRender]) -> None:
    stable, head = two
    result = step(head, stable, held(stable))
    assert published(result, head) == CANARY
    assert result.keep == set(ROBOTS) - set(CANARY)  # the others are not touched
    assert result.status is not None and result.status.state == "Progressing"
    assert (result.status.wave, result.status.wave_name, result.status.wave_started_at) == (
        0,
        "canary",
        T0,
    )
    assert result.status.pending == CANARY and result.recheck_at == T0 + 100


def test_a_status_about_the_previous_digest_never_counts(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable))
    launches = {**held(stable), **held(head, CANARY)}
    later = step(head, stable, launches, running(stable, ROBOTS), first, now=T0 + 50)
    assert later.status is not None and later.status.pending == CANARY
    assert published(later, head) == CANARY


def test_healthy_waves_advance_in_order_until_complete(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable))
    launches = {**held(stable), **held(head, CANARY)}
    # Running the new digest, but not yet for healthy_after: still pending, look again then.
    early = step(head, stable, launches, running(head, CANARY), first, now=T0 + 5)
    assert early.status is not None and early.status.wave == 0 and early.recheck_at == T0 + 10
    # Healthy: the next wave is published in the same step (60% of 5 is 3: two more robots).
    second = step(head, stable, launches, running(head, CANARY), first, now=T0 + 10)
    assert second.status is not None and second.status.wave == 1
    assert second.status.wave_started_at == T0 + 10
    assert published(second, head) == ["tb3-01", "tb3-02", "tb3-03"]
    launches = held(head, ["tb3-01", "tb3-02", "tb3-03"]) | held(stable, ["tb3-04", "tb3-05"])
    wave2 = running(head, ["tb3-01", "tb3-02", "tb3-03"])
    third = step(head, stable, launches, wave2, second, now=T0 + 20)
    assert third.status is not None and third.status.wave_name == "all"
    assert published(third, head) == ROBOTS
    done = step(head, stable, held(head), running(head, ROBOTS), third, now=T0 + 40)
    assert done.complete and done.status is not None and done.status.state == "Complete"
    # Rolled out: the head is the stable revision now (`stable -` or the old one was a lie).
    assert (done.status.revision, done.status.stable_revision) == ("b" * 40, "b" * 40)
    assert rollout_line(done.status).startswith(
        f"rollout: {'b' * 12} Complete, wave 3/3 (all): 0 healthy, 0 failed, 0 pending; "
        f"stable {'b' * 12}"
    )


@pytest.mark.parametrize("state", [AgentState.FAILED, AgentState.BACKOFF, AgentState.EXITED])
def test_a_failed_canary_rolls_back(
    two: tuple[FleetRender, FleetRender], state: AgentState
) -> None:
    stable, head = two
    first = step(head, stable, held(stable))
    launches = {**held(stable), **held(head, CANARY)}
    failed = step(head, stable, launches, running(head, CANARY, state), first, T0 + 1)
    assert failed.serve_stable and failed.status is not None
    assert failed.status.state == "RolledBack" and failed.status.failed == CANARY
    assert "over max_failures 0" in failed.status.message
    # The same revision is not tried again: the next step still serves the stable one.
    again = step(head, stable, held(stable), {}, failed, T0 + 500)
    assert again.serve_stable and again.status is not None and again.status.state == "RolledBack"


def test_halt_leaves_the_moved_robots_and_publishes_no_later_wave(lab: Lab) -> None:
    stable, head = fleet(lab, "a"), fleet(lab, "b", on_failure="halt")
    first = step(head, stable, held(stable))
    launches = {**held(stable), **held(head, CANARY)}
    rejected = {"tb3-01": AgentStatus(robot_id="tb3-01", state=AgentState.REJECTED, since=T0 + 1)}
    halted = step(head, stable, launches, rejected, first, T0 + 2)
    assert not halted.serve_stable and halted.status is not None
    assert halted.status.state == "Halted" and published(halted, head) == CANARY
    assert halted.keep == set(ROBOTS) - set(CANARY)


def test_offline_before_delivery_is_pending_and_waited_for_only_until_the_timeout(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    offline = {"tb3-01": AgentStatus(robot_id="tb3-01", state=AgentState.OFFLINE, since=T0 - 5)}
    first = step(head, stable, held(stable), offline)
    launches = {**held(stable), **held(head, CANARY)}
    waiting = step(head, stable, launches, offline, first, T0 + 50)
    assert waiting.status is not None and waiting.status.wave == 0
    assert waiting.status.counts == {"healthy": 0, "failed": 0, "pending": 1}
    moved_on = step(head, stable, launches, offline, first, T0 + 100)
    assert moved_on.status is not None and moved_on.status.wave == 1  # not failed
    # Its Will says it went offline after the wave began: still never seen with the request,
    # so not failed (the robot's clock is not the reconciler's).
    will = {"tb3-01": AgentStatus(robot_id="tb3-01", state=AgentState.OFFLINE, since=T0 + 3)}
    still = step(head, stable, launches, will, waiting, T0 + 60)
    assert still.status is not None and still.status.state == "Progressing"
    assert still.status.counts["failed"] == 0


def test_a_robot_not_healthy_by_the_wave_timeout_has_failed(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable))
    launches = {**held(stable), **held(head, CANARY)}
    starting = running(head, CANARY, AgentState.STARTING)
    late = step(head, stable, launches, starting, first, T0 + 100)
    assert late.status is not None and late.status.state == "RolledBack"


def test_paused_publishes_nothing_before_the_first_wave_and_holds_a_started_one(
    lab: Lab,
) -> None:
    stable, paused = fleet(lab, "a"), fleet(lab, "b", paused=True)
    held_back = step(paused, stable, held(stable))
    assert published(held_back, paused) == [] and held_back.status is not None
    assert held_back.status.state == "Paused"
    # A wave started before the pause stays published, and the healthy canary does not
    # move the rollout on.
    moving = fleet(lab, "b")
    first = step(moving, stable, held(stable))
    launches = {**held(stable), **held(paused, CANARY)}
    hold = step(paused, stable, launches, running(paused, CANARY), first, T0 + 50)
    assert hold.status is not None and hold.status.state == "Paused" and hold.status.wave == 0
    assert published(hold, paused) == CANARY


def test_a_restarted_reconciler_resumes_the_same_wave(two: tuple[FleetRender, FleetRender]) -> None:
    stable, head = two
    first = step(head, stable, held(stable))
    launches = {**held(stable), **held(head, CANARY)}
    # A new process: nobody seen running yet; the retained status names the wave.
    resumed = step(head, stable, launches, running(head, CANARY), first, T0 + 60, {})
    assert resumed.status is not None and resumed.status.wave == 0
    assert resumed.status.wave_started_at == T0
    assert published(resumed, head) == CANARY and resumed.keep == set(ROBOTS) - set(CANARY)


def test_a_robot_that_holds_nothing_readable_gets_the_stable_request_until_its_wave(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    launches = {**held(stable), "tb3-05": None}
    result = step(head, stable, launches)
    assert result.requests["tb3-05"].digest == stable.requests["tb3-05"].digest
    assert "tb3-05" not in result.keep


def test_the_first_rollout_without_a_stable_revision_halts_rather_than_clearing(
    lab: Lab,
) -> None:
    head = fleet(lab, "b")
    first = step(head, None, {})
    assert published(first, head) == CANARY and first.keep == set()
    assert sorted(first.requests) == CANARY  # nothing to keep the later waves on
    broken = running(head, CANARY, AgentState.FAILED)
    failed = step(head, None, held(head, CANARY), broken, first, T0 + 1)
    assert failed.status is not None and failed.status.state == "Halted"
    assert "no revision ever fully rolled out" in failed.status.message


def test_a_commit_that_changes_no_request_is_complete_even_when_paused(lab: Lab) -> None:
    stable = fleet(lab, "a")
    same = fleet(lab, "a", paused=True)
    result = step(same, stable, held(stable))
    assert result.complete and result.status is not None and result.status.state == "Complete"


def test_a_wave_read_back_out_of_range_is_brought_into_range(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable))
    assert first.status is not None
    forged = first.status.model_copy(update={"wave": 99})
    result = step(head, stable, held(head), running(head, ROBOTS), forged, T0 + 50)
    assert result.complete  # the last wave, healthy: done, and no endless walk past it
    below = first.status.model_copy(update={"wave": -5})
    again = step(head, stable, held(stable), {}, below, T0 + 1)
    assert again.status is not None and again.status.wave == 0


def test_a_deferred_robot_is_pending_past_the_timeout_then_has_it_again_to_settle(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable))
    launches = {**held(stable), **held(head, CANARY)}
    # Its brain holds off the new request: it runs the old one, deferred.
    busy = running(stable, CANARY, AgentState.DEFERRED)
    waiting = step(head, stable, launches, busy, first, T0 + 50)
    later = step(head, stable, launches, busy, waiting, T0 + 150)  # past wave_timeout (100)
    assert later.status is not None and later.status.state == "Progressing"
    assert later.status.pending == CANARY and later.status.counts["failed"] == 0
    assert later.recheck_at == T0 + 250
    # Released at T0 + 200: starting the new request, it has wave_timeout again to settle.
    starting = running(head, CANARY, AgentState.STARTING)
    going = step(head, stable, launches, starting, later, T0 + 200)
    assert going.status is not None and going.status.state == "Progressing"
    healthy = step(
        head, stable, launches, running(head, CANARY), going, T0 + 290, {"tb3-01": T0 + 210}
    )
    assert healthy.status is not None and healthy.status.wave == 1
    # Not healthy by then after all: failed, as any robot is at its timeout.
    stuck = step(head, stable, launches, starting, going, T0 + 300)
    assert stuck.status is not None and stuck.status.state == "RolledBack"


def test_a_deferred_robot_that_goes_dark_has_failed(
    two: tuple[FleetRender, FleetRender],
) -> None:
    stable, head = two
    first = step(head, stable, held(stable))
    launches = {**held(stable), **held(head, CANARY)}
    busy = step(head, stable, launches, running(stable, CANARY, AgentState.DEFERRED), first, T0 + 5)
    will = running(stable, CANARY, AgentState.OFFLINE)
    dark = step(head, stable, launches, will, busy, T0 + 10)
    gone = step(head, stable, launches, will, dark, T0 + 10 + 3)
    assert gone.status is not None and gone.status.state == "RolledBack"
