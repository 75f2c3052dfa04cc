"""What `robotconf status` shows tells the truth: the footer's counts agree with its verdict on
the fleet, restart lines, RELOADS beside RESTARTS (issue 22, item 4)."""

from __future__ import annotations

from robotconf.contract.wire import AgentStatus, ReconcilerStatus, RolloutStatus
from robotconf.readmodel.observed import Retained, RobotSeen
from robotconf.readmodel.verdicts import DesiredRobot, FleetStatus, build_rows
from robotconf.workstation.cli.fleet_view import fleet_status_text

STABLE = "sha256:" + "1" * 64  # the stable revision's request for each robot
HEAD, OLD = "b" * 40, "a" * 40
ROBOTS = [f"tb3-0{n}" for n in range(1, 6)]


def running(robot: str, digest: str = STABLE, **extra: object) -> RobotSeen:
    status = AgentStatus.model_validate(
        {"robot_id": robot, "state": "running", "digest": digest, "pid": 7, **extra}
    )
    return RobotSeen(launch_digest=digest, status=status)


def rolled_back_fleet() -> FleetStatus:
    """Five robots back on the stable revision after the rollout of HEAD failed."""
    desired = {r: DesiredRobot(r, "delivery", STABLE) for r in ROBOTS}
    retained = Retained(robots={r: running(r) for r in ROBOTS})
    rollout = RolloutStatus(
        revision=HEAD,
        stable_revision=OLD,
        state="RolledBack",
        waves=2,
        wave_name="canary",
        failed=["tb3-01"],
        counts={"healthy": 0, "failed": 1, "pending": 0},
        message="1 robot(s) of wave 'canary' failed (tb3-01); rolled back to aaaaaaa",
    )
    reconciler = ReconcilerStatus(
        state="Stalled",
        ready=False,
        reason="RolledBack",
        last_applied_revision=OLD,
        failed_revision=HEAD,
        rollout=rollout,
    )
    return FleetStatus(build_rows(desired, retained), reconciler, f"repo at {OLD[:7]}")


def test_a_rollback_footer_says_why_five_in_sync_robots_are_not_a_fleet_in_sync() -> None:
    fleet = rolled_back_fleet()
    footer = fleet_status_text(fleet).splitlines()[-1]
    assert footer == (
        "5 robots: 5 InSync — not in sync: the rollout of bbbbbbbbbbbb was rolled back: the robots "
        "run aaaaaaaaaaaa, the last revision that fully rolled out"
    )
    shown = fleet.as_json()
    assert shown["in_sync"] is False and shown["counts"] == {"InSync": 5}
    assert shown["not_in_sync_because"].startswith("the rollout of bbbbbbbbbbbb was rolled back")


def test_the_footer_names_what_keeps_a_fleet_out_of_sync() -> None:
    fleet = rolled_back_fleet()
    assert fleet.reconciler is not None
    halted = fleet.reconciler.model_copy(
        update={"rollout": fleet.reconciler.rollout.model_copy(update={"state": "Halted"})}
    )
    assert fleet_status_text(FleetStatus(fleet.rows, halted, "t")).endswith(
        "5 robots: 5 InSync — not in sync: the rollout of bbbbbbbbbbbb is halted\n"
    )
    ready = ReconcilerStatus(state="Ready", ready=True, last_applied_revision=OLD)
    assert fleet_status_text(FleetStatus(fleet.rows, ready, "t")).endswith("5 robots: 5 InSync\n")
    assert FleetStatus(fleet.rows, ready, "t").as_json()["not_in_sync_because"] is None
    missing = fleet_status_text(FleetStatus(fleet.rows, None, "t"))
    assert missing.endswith("not in sync: no reconciler status on the broker\n")


def test_reloads_stand_beside_restarts_in_the_table_and_the_json() -> None:
    desired = {r: DesiredRobot(r, "delivery", STABLE) for r in ROBOTS[:2]}
    retained = Retained(
        robots={
            "tb3-01": running("tb3-01", restarts=1, reloads=3),
            "tb3-02": running("tb3-02"),
        }
    )
    ready = ReconcilerStatus(state="Ready", ready=True, last_applied_revision=OLD)
    fleet = FleetStatus(build_rows(desired, retained), ready, "t")
    lines = fleet_status_text(fleet).splitlines()
    header = next(line for line in lines if line.startswith("ROBOT"))
    row = next(line for line in lines if line.startswith("tb3-01"))
    assert header.split()[-2:] == ["RESTARTS", "RELOADS"]
    assert row.split()[-2:] == ["1", "3"]
    assert [(r["restarts"], r["reloads"]) for r in fleet.as_json()["robots"]] == [(1, 3), (0, 0)]


def test_status_json_is_the_fleet_with_one_robot_per_line() -> None:
    import json

    from robotconf.workstation.cli.status import fleet_json

    fleet = rolled_back_fleet()
    found = fleet.as_json()
    assert found["reconciler"]["rollout"] is not None  # a nested object above the robots
    found["reconciler"]["robots"] = []  # a nested "robots" key is left alone
    text = fleet_json(found)
    assert json.loads(text) == found
    lines = [line.removesuffix(",") for line in text.splitlines()]
    for row in found["robots"]:
        assert "    " + json.dumps(row) in lines  # each robot whole, on a line of its own
    empty = {**found, "robots": []}
    assert json.loads(fleet_json(empty)) == empty
