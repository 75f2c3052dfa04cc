"""One incremental fleet reader serves `status --watch`, the browser view and `up`'s screen
(issue 33 item 3): after the first read, a change to one robot costs that robot in each, and
the rows are those a whole read gives (a real Mosquitto, a real lab, a real reconciler)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from robotconf.contract.mqtt import Connection
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from robotconf.readmodel.retained import RetainedView
from robotconf.reconciler.controller import Controller
from robotconf.reconciler.source import LocalBranch
from robotconf.workstation.fleet_reader import FleetReader, open_reader, watch
from robotconf.workstation.fleet_status import DesiredCache, DesiredSource, fleet_status
from robotconf.workstation.ui.state import LiveFleet
from robotconf.workstation.up import ServingDesired
from tests.support.fleet import GitLab
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for


@pytest.fixture
def controller(lab: GitLab, mosquitto: Mosquitto) -> Iterator[Controller]:
    running = Controller(LocalBranch(lab.root, "main"), Connection(mosquitto.url), "robotconf", 30)
    thread = threading.Thread(target=running.run, daemon=True)
    thread.start()
    watch_ = FleetWatch(mosquitto.url)
    try:
        watch_.wait_reconciler(lambda s: s.ready, "ready")
        yield running
    finally:
        watch_.close()
        running.stop()
        thread.join(20)


def _publish(mosquitto: Mosquitto, robot: str, state: AgentState, digest: str) -> None:
    publisher = RetainedView(Connection(mosquitto.url), [], "robotconf/sync", role="test-pub")
    publisher.start()
    try:
        assert publisher.wait_synced(30)
        status = AgentStatus(robot_id=robot, state=state, digest=digest, pid=1)
        payload = status.model_dump_json().encode()
        assert publisher.publish_retained([(Topics().status(robot), payload)], 30)
    finally:
        publisher.stop()


def _one_change_costs_one_robot(
    lab: GitLab, mosquitto: Mosquitto, desired: DesiredSource, robot: str, state: AgentState
) -> None:
    """`watch` over `open_reader`, as `status --watch` and `up`'s screen read the fleet."""
    changed, stop = threading.Event(), threading.Event()
    view, reader = open_reader(Connection(mosquitto.url), "robotconf", desired, changed.set)
    view.start()
    try:
        assert view.wait_synced(30)
        states = watch(view, reader, changed, stop)
        first = next(states)
        assert first is not None and reader.rows_made == len(first.rows) > 1
        _publish(mosquitto, robot, state, lab.requests()[robot].digest)
        after = next(states)
        assert after is not None and reader.rows_made == 1
        assert next(r for r in after.rows if r.robot_id == robot).state == state.value
        whole = fleet_status(view.snapshot(), Topics(), desired)
        assert after.rows == whole.rows
    finally:
        stop.set()
        view.stop()


def test_status_watch_reads_one_robots_change_alone(
    lab: GitLab, mosquitto: Mosquitto, controller: Controller
) -> None:
    desired = DesiredCache(lab.root, None)
    _one_change_costs_one_robot(lab, mosquitto, desired, "tb3-01", AgentState.RUNNING)


def test_ups_screen_reads_one_robots_change_alone(
    lab: GitLab, mosquitto: Mosquitto, controller: Controller
) -> None:
    desired = ServingDesired(controller)
    robots, where, _ = desired.get(None)
    assert robots is not None and "tb3-02" in robots and "(main)" in where
    _one_change_costs_one_robot(lab, mosquitto, desired, "tb3-02", AgentState.FAILED)


def test_the_browser_views_reader_is_the_same_one(
    lab: GitLab, mosquitto: Mosquitto, controller: Controller, tmp_path: Path
) -> None:
    live = LiveFleet(Connection(mosquitto.url), "robotconf", lab.root)
    live.start()
    try:
        wait_for(lambda: live.snapshot.fleet, "the first state")
        reader = live._reader
        assert isinstance(reader, FleetReader)
        _publish(mosquitto, "tb3-03", AgentState.RUNNING, lab.requests()["tb3-03"].digest)
        wait_for(lambda: (r := live.snapshot.row("tb3-03")) and r.state == "running", "tb3-03")
        assert reader.rows_made == 1
    finally:
        live.stop()
