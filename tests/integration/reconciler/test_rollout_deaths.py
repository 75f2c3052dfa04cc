"""Rollouts against real deaths: robots (agent and brain, SIGKILL) and the reconciler killed at
each step of a wave — before its publish, right after it, during `healthy_after`, at the gate
to the next wave — on a real Mosquitto. A robot that dies of its new request fails its wave; a
restarted reconciler resumes, never rolling back a healthy wave."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import time
from pathlib import Path

import pytest

from robotconf.agent.process import read_pidfile
from robotconf.agent.workdir import PID_FILE
from robotconf.configurator.rendered import RenderedRequest
from robotconf.contract.wire import AgentState, ReconcilerStatus
from tests.integration.reconciler.conftest import Fleet, fleet_on
from tests.integration.reconciler.test_rollout import (
    CANARY,
    complete,
    rename_all,
    running_digest,
    with_policy,
)
from tests.support.fleet import start_agent
from tests.support.mosquitto import Mosquitto
from tests.support.watch import wait_for

# These tests kill, stop and start single robots: each has an agent process of its own.
pytestmark = pytest.mark.agents_apart

LAST = "tb3-06"  # in the last wave, with the canary's scenario


def policy(healthy_after: float, wave_timeout: float, offline: str = "skip") -> str:
    return (
        "rollout:\n  waves: [{name: canary, selector: {ring: canary}}, {name: all}]\n"
        f"  healthy_after: {healthy_after}\n  max_failures: 0\n"
        f"  wave_timeout: {wave_timeout}\n  on_failure: rollback\n  offline: {offline}\n"
    )


def live_digests(fleet: Fleet, robot: str) -> list[str]:
    """The digests of the requests published to `robot` live (not retained), in order."""
    topic = fleet.watch.topics.launch(robot)
    return [
        json.loads(payload)["digest"]
        for t, payload, _ in list(fleet.watch.live_launches)
        if t == topic and payload
    ]


def wait_published(fleet: Fleet, robot: str, request: RenderedRequest) -> None:
    fleet.watch.wait(
        lambda: request.digest in live_digests(fleet, robot), f"{robot}'s new request published"
    )


def kill_robot(fleet: Fleet, robot: str) -> None:
    """The robot loses power: its agent and its brain, SIGKILL, nothing said but the Will."""
    status = fleet.watch.status(robot)
    agent = fleet.agents[robot]
    agent.kill()
    # The brain it ran: the one its status named, and the one its pid file names (a brain
    # started just before the kill, its status never sent, lived on for hours otherwise).
    pids = {status.pid} if status is not None and status.pid is not None else set()
    record = read_pidfile(agent.log.parent / PID_FILE)
    if record is not None and record.is_running():
        pids.add(record.pid)
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    fleet.watch.wait_for(robot, lambda s: s.state is AgentState.OFFLINE, "its Last Will")


def kill_reconciler(fleet: Fleet) -> None:
    assert fleet.reconciler is not None
    fleet.reconciler.kill()


def rolled_back(status: ReconcilerStatus, revision: str) -> bool:
    return (
        status.reason == "RolledBack"
        and status.rollout is not None
        and status.rollout.revision == revision
    )


def never_rolled_back(fleet: Fleet, stable: dict[str, RenderedRequest]) -> None:
    """No robot was sent its stable request again after the rollout began."""
    for robot, request in stable.items():
        assert request.digest not in live_digests(fleet, robot), f"{robot} was rolled back"


def start(
    fleet: Fleet, healthy_after: float, wave_timeout: float, offline: str = "skip"
) -> dict[str, RenderedRequest]:
    stable = with_policy(fleet, policy(healthy_after, wave_timeout, offline))
    fleet.watch.live_launches.clear()
    return fleet.requests(stable)


# ------------------------------------------------------------------ robots that die


def test_a_canary_killed_right_after_its_wave_is_published_fails_it(fleet: Fleet) -> None:
    stable = start(fleet, healthy_after=2, wave_timeout=60)
    head = rename_all(fleet, "v2")
    new = fleet.requests(head)
    wait_published(fleet, CANARY, new[CANARY])
    kill_robot(fleet, CANARY)
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, head), "the rollback")
    assert status.rollout is not None and status.rollout.failed == [CANARY]
    assert live_digests(fleet, LAST) == []  # the next wave was never published
    assert fleet.watch.digest(CANARY) == stable[CANARY].digest  # held for when it is back


def test_a_canary_killed_during_healthy_after_fails_it(fleet: Fleet) -> None:
    start(fleet, healthy_after=30, wave_timeout=120)
    head = rename_all(fleet, "v2")
    new = fleet.requests(head)
    wait_for(lambda: running_digest(fleet, CANARY, new[CANARY]), "the canary running")
    kill_robot(fleet, CANARY)
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, head), "the rollback")
    assert status.rollout is not None and status.rollout.failed == [CANARY]
    assert live_digests(fleet, LAST) == []


def test_a_robot_killed_at_the_gate_fails_the_wave_it_was_just_sent(fleet: Fleet) -> None:
    start(fleet, healthy_after=1, wave_timeout=60)
    head = rename_all(fleet, "v2")
    new = fleet.requests(head)
    wait_published(fleet, LAST, new[LAST])  # the canary was healthy: the gate opened
    kill_robot(fleet, LAST)
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, head), "the rollback")
    assert status.rollout is not None and LAST in status.rollout.failed
    assert status.rollout.wave_name == "all"


def test_a_robot_dead_before_its_wave_is_waited_for_then_passed_over(fleet: Fleet) -> None:
    stable = start(fleet, healthy_after=0.5, wave_timeout=6, offline="wait")
    kill_robot(fleet, CANARY)
    head = rename_all(fleet, "v2")
    status = fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
    assert status.rollout is not None
    never_rolled_back(fleet, stable)
    # Back on: its request waited for it, retained.
    new = fleet.requests(head)
    fleet.agents[CANARY] = start_agent(fleet.lab, CANARY, fleet.broker.url, fleet.folder / "agents")
    wait_for(lambda: running_digest(fleet, CANARY, new[CANARY]), "the canary back, on the head")


# ------------------------------------------------------------------ a reconciler that dies


def test_a_reconciler_killed_before_a_wave_is_published_rolls_it_out(fleet: Fleet) -> None:
    stable = start(fleet, healthy_after=0.5, wave_timeout=60)
    kill_reconciler(fleet)
    head = rename_all(fleet, "v2")
    fleet.start_reconciler("--interval", "5")
    fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
    fleet.watch.wait_running(fleet.requests(head))
    never_rolled_back(fleet, stable)


def test_a_reconciler_killed_right_after_a_publish_resumes_it(fleet: Fleet) -> None:
    stable = start(fleet, healthy_after=1, wave_timeout=60)
    head = rename_all(fleet, "v2")
    new = fleet.requests(head)
    wait_published(fleet, CANARY, new[CANARY])
    kill_reconciler(fleet)
    fleet.start_reconciler("--interval", "5")
    fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
    fleet.watch.wait_running(new)
    never_rolled_back(fleet, stable)
    assert live_digests(fleet, CANARY) == [new[CANARY].digest]  # published once


def test_a_reconciler_killed_during_healthy_after_and_back_after_the_timeout_goes_on(
    fleet: Fleet,
) -> None:
    """The issue's example: the canary runs the new request all along; the reconciler comes
    back after the wave's timeout. It must not blame the canary for what it did not watch."""
    # The next wave's robots restart at once and count healthy from their brains' `ready`:
    # wave_timeout leaves them seconds beyond healthy_after even on a busy machine.
    stable = start(fleet, healthy_after=4, wave_timeout=8)
    head = rename_all(fleet, "v2")
    new = fleet.requests(head)
    wait_for(lambda: running_digest(fleet, CANARY, new[CANARY]), "the canary running")
    kill_reconciler(fleet)
    pid = fleet.watch.status(CANARY)
    time.sleep(9)  # past the wave's timeout, with nobody watching
    fleet.start_reconciler("--interval", "5")
    fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
    fleet.watch.wait_running(new)
    never_rolled_back(fleet, stable)
    latest = fleet.watch.status(CANARY)
    assert pid is not None and latest is not None and latest.pid == pid.pid  # never restarted


def test_a_reconciler_killed_at_the_gate_resumes_the_next_wave(fleet: Fleet) -> None:
    stable = start(fleet, healthy_after=1, wave_timeout=60)
    head = rename_all(fleet, "v2")
    new = fleet.requests(head)
    wait_published(fleet, LAST, new[LAST])
    kill_reconciler(fleet)
    fleet.start_reconciler("--interval", "5")
    fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
    fleet.watch.wait_running(new)
    never_rolled_back(fleet, stable)


def test_a_canary_that_dies_while_the_reconciler_is_down_fails_it(fleet: Fleet) -> None:
    # Back, the reconciler cannot tell a death from a broker that restarted meanwhile: the
    # canary has until the wave's timeout, counted from the restart, to come back.
    start(fleet, healthy_after=6, wave_timeout=8)
    head = rename_all(fleet, "v2")
    new = fleet.requests(head)
    wait_for(lambda: running_digest(fleet, CANARY, new[CANARY]), "the canary running")
    # The reconciler saw it online with its request: that is kept on the broker.
    fleet.watch.wait_reconciler(
        lambda s: s.rollout is not None and s.rollout.revision == head, "the wave under way"
    )
    kill_reconciler(fleet)
    kill_robot(fleet, CANARY)
    fleet.start_reconciler("--interval", "5")
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, head), "the rollback")
    assert status.rollout is not None and status.rollout.failed == [CANARY]


# ------------------------------------------------------------------ a broker that restarts


@pytest.mark.parametrize("persistent", [True, False], ids=["persistent", "forgetful"])
def test_a_broker_restarted_mid_wave_rolls_nothing_back(tmp_path: Path, persistent: bool) -> None:
    """Mosquitto publishes every client's Last Will as it stops, and a persistent one keeps
    them: robots that are only reconnecting are not dead. One that forgets everything holds no
    status at all for a while: not dead either."""
    broker = Mosquitto(tmp_path / "broker", persistence=persistent)
    (tmp_path / "broker").mkdir()
    broker.start()
    try:
        with fleet_on(tmp_path, broker) as fleet:
            stable = start(fleet, healthy_after=3, wave_timeout=60)
            head = rename_all(fleet, "v2")
            new = fleet.requests(head)
            wait_for(lambda: running_digest(fleet, CANARY, new[CANARY]), "the canary running")
            broker.restart()
            fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
            fleet.watch.wait_running(new)
            # A forgetful broker lost every request: the robots of waves not begun were given
            # the stable one again, as a robot that holds nothing readable is. Not the canary.
            never_rolled_back(fleet, stable if persistent else {CANARY: stable[CANARY]})
    finally:
        broker.kill()
