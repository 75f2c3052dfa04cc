"""Fleet status carries each robot's reloads (brains that applied a request without a restart)."""

from __future__ import annotations

from robotconf.contract.wire import AgentState, AgentStatus
from robotconf.readmodel.observed import Retained, RobotSeen
from robotconf.readmodel.verdicts import DesiredRobot, FleetStatus, Verdict, build_rows

D1 = "sha256:" + "1" * 64


def test_reloads_are_in_each_row_and_in_the_json() -> None:
    reloaded = AgentStatus(robot_id="r1", state=AgentState.RUNNING, digest=D1, pid=7, reloads=2)
    retained = Retained(
        robots={
            "r1": RobotSeen(launch_digest=D1, status=reloaded),
            "r2": RobotSeen(status=AgentStatus(robot_id="r2", state=AgentState.IDLE)),
        }
    )
    rows = build_rows({"r1": DesiredRobot("r1", "delivery", D1)}, retained)
    assert [(r.robot_id, r.verdict, r.reloads) for r in rows] == [
        ("r2", Verdict.UNASSIGNED, 0),
        ("r1", Verdict.IN_SYNC, 2),  # a reloaded brain runs the desired request: in sync
    ]
    robots = FleetStatus(rows, None, "test").as_json()["robots"]
    assert {r["robot_id"]: r["reloads"] for r in robots} == {"r1": 2, "r2": 0}
    # A robot that never reported has no reloads to show.
    unseen = build_rows({"r3": DesiredRobot("r3", "delivery", D1)}, Retained(robots={}))
    assert unseen[0].reloads == 0 and unseen[0].verdict is Verdict.OFFLINE
