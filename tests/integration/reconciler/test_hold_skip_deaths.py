"""The reconciler killed (SIGKILL, a real process on a real Mosquitto) while it holds a robot
back for drift (`drift: hold`), and while a wave goes on without a robot that is off
(`offline: skip`). Started again it holds the same robot (never publishing what it held
back), releases it when it fits, and keeps the skipped robot skipped — no rollback, nothing
lost, the robot served when it is back."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robotconf.contract.wire import ReconcilerStatus
from tests.integration.reconciler.conftest import Fleet
from tests.integration.reconciler.test_drift_reconciler import FLEET, NAV2, ODOM
from tests.integration.reconciler.test_rollout import complete, rename_all, running_digest
from tests.integration.reconciler.test_rollout_deaths import (
    kill_reconciler,
    kill_robot,
    live_digests,
    never_rolled_back,
    start,
    wait_published,
)
from tests.integration.reconciler.test_rollout_offline import back_on, offline_robots
from tests.support.fleet import GitLab, Proc, start_reconciler
from tests.support.interfaces import publish_interfaces, report
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

HELD = "tb3-04"  # patrol-real: navigate_with_nav2 needs /navigate_to_pose


def offline(status: ReconcilerStatus) -> bool:
    return status.state == "Offline"  # its Last Will


def published_to(watch: FleetWatch, robot: str, digest: str) -> bool:
    topic = watch.topics.launch(robot)
    return any(
        t == topic and p and json.loads(p)["digest"] == digest for t, p, _ in watch.live_launches
    )


def test_a_reconciler_killed_while_it_holds_a_robot_for_drift_holds_it_when_back(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch, tmp_path: Path
) -> None:
    lab.write(FLEET, lab.read(FLEET) + "drift: hold\n")
    lab.commit("hold on drift")
    started: list[Proc] = []

    def reconciler() -> Proc:
        started.append(start_reconciler(lab, mosquitto.url, tmp_path / f"r{len(started)}.log"))
        return started[-1]

    try:
        first = reconciler()
        head = lab.head()
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == head, "applied")
        old = lab.requests()[HELD].digest
        publish_interfaces(mosquitto.url, HELD, report(ODOM))  # no Nav2
        lab.replace(FLEET, "name: Lab patrol,", "name: Lab patrol 2,")
        second = lab.commit("a new request for the patrol robot")
        new = lab.requests()[HELD].digest
        watch.wait_reconciler(
            lambda s: s.last_applied_revision == second and bool(s.held), f"{HELD} held"
        )
        watch.live_launches.clear()
        first.kill()
        watch.wait_reconciler(offline, "the reconciler's Last Will")
        # Back: it waits for the robots' interfaces before it publishes anything, and holds
        # the same robot again.
        again = reconciler()
        status = watch.wait_reconciler(
            lambda s: not offline(s) and s.last_applied_revision == second and bool(s.held),
            f"{HELD} held again",
        )
        assert [h.robot for h in status.held] == [HELD]
        assert watch.digest(HELD) == old and not published_to(watch, HELD, new)
        # Killed again; the robot fits while no reconciler runs: the next one releases it.
        again.kill()
        watch.wait_reconciler(offline, "the reconciler's Last Will")
        publish_interfaces(mosquitto.url, HELD, report(ODOM, actions=(NAV2,)))
        reconciler()
        wait_for(lambda: watch.digest(HELD) == new, f"{HELD} released once it fits")
        watch.wait_reconciler(lambda s: not offline(s) and not s.held and s.ready, "none held")
    finally:
        for proc in started:
            proc.kill()


@pytest.mark.agents_apart  # a robot is killed
def test_a_reconciler_killed_while_a_wave_skips_an_offline_robot_keeps_it_skipped(
    fleet: Fleet,
) -> None:
    off = "tb3-05"  # in the last wave
    stable = start(fleet, healthy_after=20, wave_timeout=300)
    kill_robot(fleet, off)
    head = rename_all(fleet, "v2")
    new = fleet.requests(head)
    wait_published(fleet, "tb3-02", new["tb3-02"])  # the last wave is out, tb3-05 skipped
    fleet.watch.wait_reconciler(
        lambda s: offline_robots(s) == [off] and s.rollout is not None and s.rollout.wave == 1,
        f"{off} skipped in the last wave",
    )
    kill_reconciler(fleet)
    fleet.watch.wait_reconciler(offline, "the reconciler's Last Will")
    fleet.start_reconciler("--interval", "5")
    # Back: the skipped robot stays skipped (not failed, no rollback), the wave completes.
    done = fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
    assert offline_robots(done) == [off] and done.rollout is not None
    assert done.rollout.failed == []
    never_rolled_back(fleet, {r: q for r, q in stable.items() if r != off})
    assert fleet.watch.digest(off) == new[off].digest  # retained for it: its wave was published
    assert live_digests(fleet, off).count(new[off].digest) == 1  # published once, not again
    back_on(fleet, off)
    wait_for(lambda: running_digest(fleet, off, new[off]), f"{off} back, on the head")
