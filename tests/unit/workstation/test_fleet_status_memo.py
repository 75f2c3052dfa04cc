"""`status --watch` keeps what it read of each payload: each redraw is the one a fresh read
gives, with the repository to compare with and without one."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robotconf.configurator.render import render_fleet
from robotconf.configurator.workspace import check
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from robotconf.readmodel.observed import ReadMemo
from robotconf.workstation.fleet_status import DesiredCache, fleet_status
from tests.support.lab import ROOT

T = Topics()


def _status(robot: str, state: AgentState, digest: str | None = None) -> bytes:
    return AgentStatus(robot_id=robot, state=state, digest=digest).model_dump_json().encode()


@pytest.mark.parametrize("repo", [ROOT, Path("/nonexistent/lab")])
def test_redraws_with_memos_are_fresh_reads(repo: Path) -> None:
    fleet = render_fleet(check(ROOT).repo)
    messages = {T.launch(r): q.payload() for r, q in fleet.requests.items()}
    first = next(iter(fleet.requests))
    messages[T.status(first)] = _status(first, AgentState.RUNNING, fleet.requests[first].digest)
    messages[T.launch("stranger")] = b"{not json"
    memos: dict[bool, ReadMemo] = {}
    seen: list[str] = []
    for step in range(3):
        if step == 1:
            messages[T.status(first)] = _status(first, AgentState.FAILED)
        if step == 2:
            del messages[T.launch(first)]
        got = fleet_status(dict(messages), T, DesiredCache(repo, None), memos)
        fresh = fleet_status(dict(messages), T, DesiredCache(repo, None))
        assert got.as_json(heartbeat=False) == fresh.as_json(heartbeat=False), step
        seen.append(json.dumps(got.as_json(heartbeat=False), sort_keys=True))
    assert len(set(seen)) == 3  # each change shows
    assert list(memos) == [repo != ROOT]  # requests read in full only without a repository


@pytest.mark.parametrize("repo", [ROOT, Path("/nonexistent/lab")])
def test_drift_is_worked_out_again_only_for_the_robot_whose_report_or_request_changed(
    repo: Path,
) -> None:
    from robotconf.configurator.drift import DriftMemo
    from robotconf.contract.interfaces import Interface, RobotInterfaces

    def report(*names: str) -> bytes:
        topics = [Interface(name=n, type="nav_msgs/msg/Odometry") for n in names]
        return RobotInterfaces(topics=topics, source="ros2").model_dump_json().encode()

    fleet = render_fleet(check(ROOT).repo)
    messages = {T.launch(r): q.payload() for r, q in fleet.requests.items()}
    for robot in fleet.requests:
        messages[T.interfaces(robot)] = report("/odom")
    memos: dict[bool, ReadMemo] = {}
    drift = DriftMemo()
    desired = DesiredCache(repo, None)
    first = fleet_status(dict(messages), T, desired, memos, drift)
    assert drift.computed == len(fleet.requests)
    again = fleet_status(dict(messages), T, desired, memos, drift)
    assert drift.computed == len(fleet.requests)  # nothing changed: nothing worked out
    assert again.as_json(heartbeat=False) == first.as_json(heartbeat=False)

    messages[T.interfaces("tb3-04")] = report("/odom", "/scan")
    changed = fleet_status(dict(messages), T, desired, memos, drift)
    assert drift.computed == len(fleet.requests) + 1  # tb3-04, and no other
    fresh = fleet_status(dict(messages), T, DesiredCache(repo, None))
    assert changed.as_json(heartbeat=False) == fresh.as_json(heartbeat=False)
