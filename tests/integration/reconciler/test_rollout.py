"""Rollouts end to end: a real reconciler, real agents and stand-in brains on a real Mosquitto.
A canary that crashes stops the rollout and is rolled back; healthy waves advance in order; a
reconciler killed mid-rollout resumes without republishing; a paused rollout holds."""

from __future__ import annotations

import itertools
import json

import yaml

from robotconf.configurator.rendered import RenderedRequest
from robotconf.contract.wire import AgentState, ReconcilerStatus
from tests.integration.reconciler.conftest import Fleet
from tests.support.watch import wait_for

FLEET = "configs/fleet.yaml"
CANARY = "tb3-01"
ROBOTS = ["tb3-01", "tb3-02", "tb3-03", "tb3-04", "tb3-05", "tb3-06", "tb3-07"]


def with_policy(fleet: Fleet, policy: str) -> str:
    """Commits labels (tb3-01 is the canary) and a rollout policy; no request changes."""
    robots = yaml.safe_load(fleet.lab.read(FLEET))["robots"]
    for robot_id, assignment in robots.items():
        assignment["labels"] = {"ring": "canary"} if robot_id == CANARY else {}
    fleet.lab.write(FLEET, yaml.safe_dump({"robots": robots}, sort_keys=True) + policy)
    revision = fleet.lab.commit("roll out in waves")
    fleet.watch.wait_reconciler(lambda s: complete(s, revision), "the policy commit applied")
    return revision


def complete(status: ReconcilerStatus, revision: str) -> bool:
    rollout = status.rollout
    return (
        status.ready
        and status.last_applied_revision == revision
        and rollout is not None
        and rollout.revision == revision
        and rollout.state == "Complete"
    )


def rename_all(fleet: Fleet, suffix: str) -> str:
    """A commit that changes every robot's request (their names)."""
    text = fleet.lab.read(FLEET)
    for name in ("Delivery bot", "Guide bot", "Bluetooth delivery bot", "Lab patrol", "Corridor"):
        text = text.replace(f"name: {name}", f"name: {name} {suffix}")
    text = text.replace("name: Noetic patrol", f"name: Noetic patrol {suffix}")
    text = text.replace("name: Second delivery bot", f"name: Second delivery bot {suffix}")
    fleet.lab.write(FLEET, text)
    return fleet.lab.commit(f"rename {suffix}")


def launched(fleet: Fleet, robot: str) -> list[float]:
    topic = fleet.watch.topics.launch(robot)
    return [at for t, payload, at in fleet.watch.live_launches if t == topic and payload]


def running_digest(fleet: Fleet, robot: str, request: RenderedRequest) -> bool:
    status = fleet.watch.status(robot)
    return (
        status is not None
        and status.state is AgentState.RUNNING
        and status.digest == request.digest
    )


def test_a_crashing_canary_stops_the_rollout_and_is_rolled_back(fleet: Fleet) -> None:
    stable = with_policy(
        fleet,
        "rollout:\n  waves: [{name: canary, selector: {ring: canary}}, {name: all}]\n"
        # The canary's brain crashes as it starts: healthy_after outlasts that start on a loaded
        # machine (at 1 s a slow start could let the canary pass).
        "  healthy_after: 10\n  max_failures: 0\n  wave_timeout: 60\n  on_failure: rollback\n",
    )
    before = fleet.requests(stable)
    pid_06 = fleet.converged["tb3-06"].pid
    fleet.watch.live_launches.clear()
    # tb3-01 (the canary) and tb3-06 (wave "all") run this scenario: the brain crashes on it.
    fleet.lab.replace(
        "configs/scenarios/delivery-gazebo.yaml",
        'knowledge: {TARGET: {GOAL_ID: "2"}}',
        'knowledge: {TARGET: {GOAL_ID: "2"}, STANDIN_CRASH: 3}',
    )
    bad = fleet.lab.commit("a commit whose brain crashes")
    status = fleet.watch.wait_reconciler(lambda s: s.reason == "RolledBack", "the rollback")
    assert status.state == "Stalled" and status.reason == "RolledBack"
    assert status.failed_revision == bad and status.last_applied_revision == stable
    assert status.rollout is not None and status.rollout.failed == [CANARY]
    assert "over max_failures 0" in status.message
    # The canary got the bad request, crashed, and has the stable one back; tb3-06 never moved.
    assert launched(fleet, CANARY)
    wait_for(lambda: running_digest(fleet, CANARY, before[CANARY]), "the canary rolled back")
    assert launched(fleet, "tb3-06") == []
    assert fleet.watch.digest("tb3-06") == before["tb3-06"].digest
    latest = fleet.watch.status("tb3-06")
    assert latest is not None and latest.pid == pid_06
    # `robotconf status` says why.
    done = fleet.status_cli("--json")
    report = json.loads(done.stdout)
    assert report["reconciler"]["rollout"]["state"] == "RolledBack"
    text = fleet.status_cli().stdout
    assert "rollout:" in text and "RolledBack" in text and "failed: tb3-01" in text


def test_healthy_waves_advance_in_order(fleet: Fleet) -> None:
    with_policy(
        fleet,
        "rollout:\n  waves: [{name: canary, selector: {ring: canary}}, {name: half, percent: 50},"
        " {name: all}]\n  healthy_after: 0.5\n  max_failures: 0\n  wave_timeout: 120\n",
    )
    fleet.watch.live_launches.clear()
    head = rename_all(fleet, "v2")
    status = fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
    assert status.rollout is not None and status.rollout.wave_name == "all"
    requests = fleet.requests(head)
    fleet.watch.wait_running(requests)
    # canary: tb3-01; half of seven is four: tb3-02 to tb3-04 join; all: the rest.
    waves = [[CANARY], ["tb3-02", "tb3-03", "tb3-04"], ["tb3-05", "tb3-06", "tb3-07"]]
    first = {robot: min(launched(fleet, robot)) for robot in ROBOTS}
    for earlier, later in itertools.pairwise(waves):
        # A later wave is published only once every robot of the earlier one has run the new
        # request: its first `running` with the new digest came before the later publish.
        started = min(first[r] for r in later)
        for robot in earlier:
            ran = [
                at
                for at, who, s in fleet.watch.timeline
                if who == robot
                and s.state is AgentState.RUNNING
                and s.digest == requests[robot].digest
            ]
            assert ran and min(ran) < started, f"{robot} was not running before {later}"
        assert max(first[r] for r in earlier) < started
    # Labels select robots in status too, and each row names its wave.
    report = json.loads(fleet.status_cli("--json", "--selector", "ring=canary").stdout)
    assert [(r["robot_id"], r["wave"]) for r in report["robots"]] == [(CANARY, "canary")]


def test_a_reconciler_killed_mid_rollout_resumes_without_republishing(fleet: Fleet) -> None:
    with_policy(
        fleet,
        "rollout:\n  waves: [{name: canary, selector: {ring: canary}}, {name: all}]\n"
        "  healthy_after: 3600\n  wave_timeout: 7200\n",
    )
    head = rename_all(fleet, "v3")
    requests = fleet.requests(head)
    wait_for(lambda: running_digest(fleet, CANARY, requests[CANARY]), "the canary running")
    first = fleet.watch.wait_reconciler(
        lambda s: s.rollout is not None and s.rollout.revision == head, "the rollout in wave 1"
    )
    assert first.rollout is not None and first.rollout.state == "Progressing"
    assert fleet.reconciler is not None
    fleet.reconciler.kill()  # SIGKILL: nothing said, nothing kept but what the broker holds
    fleet.watch.live_launches.clear()
    fleet.start_reconciler("--interval", "1")
    heartbeat = first.heartbeat or 0.0
    resumed = fleet.watch.wait_reconciler(
        lambda s: (
            s.state != "Offline" and (s.heartbeat or 0.0) > heartbeat + 2 and s.rollout is not None
        ),
        "the restarted reconciler's status",
    )
    assert resumed.rollout is not None and first.rollout is not None
    assert resumed.rollout.revision == head and resumed.rollout.wave == 0
    assert resumed.rollout.wave_started_at == first.rollout.wave_started_at
    assert fleet.watch.live_launches == []  # nothing published again
    assert fleet.watch.digest("tb3-06") != requests["tb3-06"].digest  # the next wave waits


def test_a_paused_rollout_holds(fleet: Fleet) -> None:
    policy = (
        "rollout:\n  waves: [{name: canary, selector: {ring: canary}}, {name: all}]\n"
        "  healthy_after: 0\n  paused: true\n"
    )
    with_policy(fleet, policy)
    fleet.watch.live_launches.clear()
    head = rename_all(fleet, "v4")
    status = fleet.watch.wait_reconciler(
        lambda s: s.rollout is not None and s.rollout.revision == head, "the paused rollout"
    )
    assert status.rollout is not None and status.rollout.state == "Paused"
    assert status.reason == "RolloutPaused"
    assert fleet.watch.live_launches == []
    fleet.lab.replace(FLEET, "paused: true", "paused: false")
    resumed = fleet.lab.commit("go on")
    fleet.watch.wait_reconciler(lambda s: complete(s, resumed), "the rollout complete")
    fleet.watch.wait_running(fleet.requests(resumed))
