"""`rollout.offline` with real agents on a real Mosquitto: robots powered off before a commit
never cost it a wave_timeout (skip, the default), get the revision their wave reached when they
are back, and a robot killed after its wave was published fails it even under skip."""

from __future__ import annotations

import json

import pytest

from robotconf.contract.wire import ReconcilerStatus
from tests.integration.reconciler.conftest import Fleet
from tests.integration.reconciler.test_rollout import (
    CANARY,
    complete,
    rename_all,
    running_digest,
    with_policy,
)
from tests.integration.reconciler.test_rollout_deaths import (
    kill_robot,
    never_rolled_back,
    rolled_back,
    wait_published,
)
from tests.support.fleet import start_agent
from tests.support.watch import TIMEOUT, wait_for

# These tests kill, stop and start single robots: each has an agent process of its own.
pytestmark = pytest.mark.agents_apart

# wave_timeout far beyond the watcher's TIMEOUT: a rollout that waited it out fails the test.
WAVE_TIMEOUT = 300
assert WAVE_TIMEOUT > 2 * TIMEOUT


def policy(healthy_after: float, offline: str | None) -> str:
    return (
        "rollout:\n  waves: [{name: canary, selector: {ring: canary}}, {name: all}]\n"
        f"  healthy_after: {healthy_after}\n  max_failures: 0\n"
        f"  wave_timeout: {WAVE_TIMEOUT}\n  on_failure: rollback\n"
        + (f"  offline: {offline}\n" if offline else "")
    )


def back_on(fleet: Fleet, robot: str) -> None:
    fleet.agents[robot] = start_agent(fleet.lab, robot, fleet.broker.url, fleet.folder / "agents")


def offline_robots(status: ReconcilerStatus) -> list[str]:
    return status.rollout.offline if status.rollout is not None else []


def test_robots_off_before_a_commit_do_not_hold_it_up(fleet: Fleet) -> None:
    stable = with_policy(fleet, policy(0.5, None))  # skip: the default
    fleet.watch.live_launches.clear()
    off = [CANARY, "tb3-02", "tb3-03", "tb3-04"]
    for robot in off:
        kill_robot(fleet, robot)
    head = rename_all(fleet, "v2")
    status = fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
    on = {r: q for r, q in fleet.requests(head).items() if r not in off}
    fleet.watch.wait_running(on)
    assert offline_robots(status) == off  # counted, and shown
    assert status.rollout is not None and status.rollout.counts["offline"] == len(off)
    never_rolled_back(fleet, fleet.requests(stable))
    text = fleet.status_cli().stdout
    assert f"{len(off)} offline" in text and "offline (get it when back): tb3-01" in text
    report = json.loads(fleet.status_cli("--json").stdout)
    assert report["reconciler"]["rollout"]["offline"] == off
    # Back on: the canary gets the revision its wave reached, retained for it.
    back_on(fleet, CANARY)
    new = fleet.requests(head)
    wait_for(lambda: running_digest(fleet, CANARY, new[CANARY]), "the canary back, on the head")


def test_wait_still_waits_for_a_robot_that_is_off(fleet: Fleet) -> None:
    with_policy(fleet, policy(0.5, "wait"))
    kill_robot(fleet, CANARY)
    head = rename_all(fleet, "v2")
    status = fleet.watch.wait_reconciler(
        lambda s: s.rollout is not None and s.rollout.revision == head, "the rollout begun"
    )
    assert status.rollout is not None and status.rollout.pending == [CANARY]
    assert status.rollout.wave_name == "canary" and status.rollout.offline == []


def test_fail_fails_the_wave_of_a_robot_that_is_off(fleet: Fleet) -> None:
    with_policy(fleet, policy(0.5, "fail"))
    kill_robot(fleet, CANARY)
    head = rename_all(fleet, "v2")
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, head), "the rollback")
    assert status.rollout is not None and status.rollout.failed == [CANARY]


def test_a_robot_killed_after_its_wave_was_published_fails_it_even_under_skip(
    fleet: Fleet,
) -> None:
    with_policy(fleet, policy(1, "skip"))
    head = rename_all(fleet, "v2")
    new = fleet.requests(head)
    wait_published(fleet, CANARY, new[CANARY])
    kill_robot(fleet, CANARY)
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, head), "the rollback")
    assert status.rollout is not None and status.rollout.failed == [CANARY]
    assert offline_robots(status) == []


def test_a_robot_back_mid_rollout_gets_the_revision_its_wave_reached(fleet: Fleet) -> None:
    stable = fleet.requests(with_policy(fleet, policy(8, None)))
    kill_robot(fleet, "tb3-06")  # in the last wave
    head = rename_all(fleet, "v2")
    new = fleet.requests(head)
    wait_for(lambda: running_digest(fleet, CANARY, new[CANARY]), "the canary running")
    # Back while the canary is on probation: its wave has not begun, it keeps the stable one.
    status = fleet.watch.wait_reconciler(
        lambda s: s.rollout is not None and s.rollout.revision == head, "the canary wave"
    )
    assert status.rollout is not None and status.rollout.wave_name == "canary"
    back_on(fleet, "tb3-06")
    wait_for(lambda: running_digest(fleet, "tb3-06", stable["tb3-06"]), "tb3-06 on the stable")
    # The canary healthy, the last wave reaches it and waits for it, health-gated like any.
    done = fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
    assert offline_robots(done) == []
    fleet.watch.wait_running(new)


def test_a_skipped_robot_back_while_its_wave_runs_is_judged_with_it(fleet: Fleet) -> None:
    """Health-gated: back while its wave is still on probation, it is one of the wave's robots
    again; dying on the new request fails the wave."""
    with_policy(fleet, policy(20, None))
    kill_robot(fleet, "tb3-05")  # in the last wave
    head = rename_all(fleet, "v2")
    new = fleet.requests(head)
    wait_published(fleet, "tb3-02", new["tb3-02"])  # the last wave is out, tb3-05 skipped
    skipped = fleet.watch.wait_reconciler(
        lambda s: (
            offline_robots(s) == ["tb3-05"]
            and s.rollout is not None
            and s.rollout.wave_name == "all"
        ),
        "tb3-05 skipped",
    )
    assert skipped.rollout is not None and skipped.rollout.state == "Progressing"
    back_on(fleet, "tb3-05")
    wait_for(lambda: running_digest(fleet, "tb3-05", new["tb3-05"]), "tb3-05 back, on the head")
    kill_robot(fleet, "tb3-05")
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, head), "the rollback")
    assert status.rollout is not None and status.rollout.failed == ["tb3-05"]
