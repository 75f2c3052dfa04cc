"""The loop end to end: git commit -> reconciler -> Mosquitto -> real agents and brains."""

from __future__ import annotations

import json
import subprocess

from robotconf.contract.wire import AgentState
from tests.integration.reconciler.conftest import Fleet
from tests.support.fleet import pid_alive, robotconf_argv
from tests.support.watch import wait_for


def test_initial_convergence(fleet: Fleet) -> None:
    head = fleet.lab.head()
    status = fleet.watch.wait_reconciler(lambda s: s.ready, "ready")
    assert status.state == "Ready"
    assert status.last_applied_revision == head
    assert status.last_attempted_revision == head
    assert status.robots == 7
    assert status.diagnostics == []
    for robot_id, request in fleet.requests().items():
        launch = fleet.watch.launch(robot_id)
        assert launch is not None
        assert launch["digest"] == request.digest
        assert launch["revision"] == head
        assert pid_alive(fleet.converged[robot_id].pid or 0)

    done = subprocess.run(
        robotconf_argv(
            "status", "--repo", str(fleet.lab.root), "--broker", fleet.broker.url, "--json"
        ),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    report = json.loads(done.stdout)
    assert report["in_sync"] is True
    assert {r["robot_id"]: r["verdict"] for r in report["robots"]} == {
        r: "InSync" for r in fleet.requests()
    }
    assert report["reconciler"]["last_applied_revision"] == head


def test_changed_scenario_restarts_exactly_the_planned_robots(fleet: Fleet) -> None:
    base = fleet.lab.head()
    fleet.lab.replace(
        "configs/scenarios/delivery-gazebo.yaml", "move_speed: 0.1", "move_speed: 0.12"
    )
    # `plan` reads the work tree before the commit, as in a pull request.
    planned = subprocess.run(
        robotconf_argv("plan", "--repo", str(fleet.lab.root), "--base", base, "--format", "json"),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert planned.returncode == 1, planned.stderr  # 1: there are changes
    restarts = {c["robot_id"] for c in json.loads(planned.stdout)["changes"]}
    assert restarts == {"tb3-01", "tb3-06"}

    head = fleet.lab.commit("slower delivery")
    requests = fleet.requests(head)
    after = fleet.watch.wait_running(requests)
    fleet.watch.wait_reconciler(lambda s: s.last_applied_revision == head, "head applied")

    restarted = {r for r in requests if after[r].pid != fleet.converged[r].pid}
    assert restarted == restarts
    for robot_id in set(requests) - restarts:
        # Not republished (the retained request still names the first revision) and not touched.
        launch = fleet.watch.launch(robot_id)
        assert launch is not None and launch["revision"] == base
        assert after[robot_id].restarts == fleet.converged[robot_id].restarts
        assert pid_alive(after[robot_id].pid or 0)
    for robot_id in restarts:
        assert not pid_alive(fleet.converged[robot_id].pid or 0)


def test_removed_robot_is_stopped_and_its_topic_cleared(fleet: Fleet) -> None:
    old_pid = fleet.converged["tb3-05"].pid or 0
    fleet.lab.replace("configs/fleet.yaml", "  tb3-05:", "  # tb3-05:")
    head = fleet.lab.commit("retire tb3-05")

    def stopped() -> bool:
        status = fleet.watch.status("tb3-05")
        return status is not None and status.state is AgentState.IDLE

    wait_for(stopped, "tb3-05 idle")
    assert fleet.watch.launch("tb3-05") is None
    assert not pid_alive(old_pid)
    status = fleet.watch.wait_reconciler(lambda s: s.last_applied_revision == head, "applied")
    assert status.cleared == 1 and status.published == 0
    others = {r: s for r, s in fleet.converged.items() if r != "tb3-05"}
    now = fleet.watch.wait_running(fleet.requests(head))
    assert {r: s.pid for r, s in now.items()} == {r: s.pid for r, s in others.items()}


def test_invalid_commit_changes_nothing_and_is_reported(fleet: Fleet) -> None:
    good = fleet.lab.head()
    fleet.lab.replace(
        "configs/scenarios/delivery-gazebo.yaml",
        "capability: turtlebot3-camera",
        "capability: nope",
    )
    bad = fleet.lab.commit("typo")

    status = fleet.watch.wait_reconciler(
        lambda s: s.last_attempted_revision == bad, "the bad commit attempted"
    )
    assert status.state == "Stalled" and not status.ready
    assert status.reason == "BuildFailed" and status.failed_revision == bad
    assert status.last_applied_revision == good
    assert any("nope" in d and "delivery-gazebo.yaml" in d for d in map(str, status.diagnostics))
    for robot_id, request in fleet.requests(good).items():
        launch = fleet.watch.launch(robot_id)
        assert launch is not None and launch["digest"] == request.digest
        current = fleet.watch.status(robot_id)
        assert current is not None and current.pid == fleet.converged[robot_id].pid

    done = subprocess.run(
        robotconf_argv("status", "--repo", str(fleet.lab.root), "--broker", fleet.broker.url),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 1  # robots run the last good revision, but the branch is stalled
    assert "Stalled (BuildFailed)" in done.stdout and "nope" in done.stdout
    assert f"failed on {bad[:12]}" in done.stdout

    fleet.lab.replace(
        "configs/scenarios/delivery-gazebo.yaml",
        "capability: nope",
        "capability: turtlebot3-camera",
    )
    fixed = fleet.lab.commit("fix the typo")
    status = fleet.watch.wait_reconciler(
        lambda s: s.ready and s.last_applied_revision == fixed, "the fix applied"
    )
    assert status.diagnostics == []


def test_restarted_reconciler_publishes_nothing(fleet: Fleet) -> None:
    assert fleet.reconciler is not None
    assert fleet.reconciler.stop() == 0
    head = fleet.lab.head()
    fleet.watch.live_launches.clear()
    restarted = fleet.start_reconciler("--interval", "5")
    wait_for(
        lambda: f"in sync with {head[:12]}" in restarted.output(), "the new reconciler in sync"
    )
    assert fleet.watch.live_launches == []
    # Mosquitto speaks MQTT 5: the reconciler reads the launch topics without echoes.
    assert "(MQTT 5, No Local)" in restarted.output()
    now = fleet.watch.wait_running(fleet.requests())
    assert {r: s.pid for r, s in now.items()} == {r: s.pid for r, s in fleet.converged.items()}


def test_broker_restart_refills_the_retained_topics(fleet: Fleet) -> None:
    fleet.broker.stop()  # without persistence: every retained message is lost
    fleet.broker.start()
    requests = fleet.requests()

    def refilled() -> bool:
        return all(
            (fleet.watch.launch(r) or {}).get("digest") == q.digest for r, q in requests.items()
        )

    wait_for(refilled, "every request published again")
    now = fleet.watch.wait_running(requests)
    # Same digest again: no brain restarts.
    assert {r: s.pid for r, s in now.items()} == {r: s.pid for r, s in fleet.converged.items()}
    fleet.watch.wait_reconciler(lambda s: s.ready, "ready again")

    # And the reconciler still follows the branch afterwards.
    fleet.lab.replace(
        "configs/scenarios/patrol-real.yaml", "goal_tolerance: 0.3", "goal_tolerance: 0.25"
    )
    head = fleet.lab.commit("tighter patrol")
    after = fleet.watch.wait_running(fleet.requests(head))
    assert after["tb3-04"].pid != fleet.converged["tb3-04"].pid
    assert after["tb3-01"].pid == fleet.converged["tb3-01"].pid


def test_a_robot_removed_while_cut_off_is_stopped_when_it_comes_back(fleet: Fleet) -> None:
    """The broker loses its retained messages while tb3-05 is removed: no retained clear
    can reach it, yet its brain must stop once it reports running again."""
    before = fleet.converged["tb3-05"]
    fleet.broker.stop()
    text = fleet.lab.read("configs/fleet.yaml")
    fleet.lab.write(
        "configs/fleet.yaml",
        "".join(line for line in text.splitlines(True) if "tb3-05" not in line),
    )
    head = fleet.lab.commit("tb3-05 leaves while the broker is down")
    fleet.broker.start()
    fleet.watch.wait_running(fleet.requests(head))

    def stopped() -> bool:
        status = fleet.watch.status("tb3-05")
        return status is not None and status.state is AgentState.IDLE

    wait_for(stopped, "tb3-05 idle")
    assert before.pid is not None and not pid_alive(before.pid)
