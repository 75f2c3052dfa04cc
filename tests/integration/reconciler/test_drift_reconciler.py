"""The reconciler and drift: alerts and metrics as robots report interfaces, and the `hold`
policy keeping a robot's last good request until its interfaces fit."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Iterator

import pytest

from robotconf.contract.mqtt import Connection
from robotconf.reconciler.metrics import Metrics
from robotconf.reconciler.notify import Notifier, parse_receiver
from robotconf.reconciler.source import LocalBranch
from robotconf.reconciler.telemetry import Telemetry
from tests.integration.reconciler.test_alerts import Receiver, free_port, scrape, value
from tests.support.fleet import ROBOTS, GitLab, Running, robotconf_argv
from tests.support.interfaces import publish_interfaces, report
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

FLEET = "configs/fleet.yaml"
# tb3-04 runs patrol-real: navigate_with_nav2 needs the /navigate_to_pose action and /odom.
ODOM = ("/odom", "nav_msgs/msg/Odometry")
NAV2 = ("/navigate_to_pose", "nav2_msgs/action/NavigateToPose")


@pytest.fixture
def receiver() -> Iterator[Receiver]:
    made = Receiver("ok")
    try:
        yield made
    finally:
        made.close()


def test_drift_is_told_once_each_way_and_scraped(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch, receiver: Receiver
) -> None:
    port = free_port()
    metrics = Metrics()
    metrics.serve("127.0.0.1", port)
    notifier = Notifier([parse_receiver(receiver.url, 1)])
    telemetry = Telemetry(
        Connection(mosquitto.url), "robotconf", notifier=notifier, metrics=metrics
    )
    telemetry.start()
    running = Running(LocalBranch(lab.root, "main"), mosquitto.url, on_step=telemetry.on_step)
    try:
        # The series are there from the start, before any robot reports.
        first = scrape(port)
        assert value(first, "robotconf_drifted_robots") == 0.0
        assert value(first, "robotconf_robot_interfaces", interfaces="error") == 0.0
        head = lab.head()
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == head, "applied")
        wait_for(
            lambda: (
                value(scrape(port), "robotconf_robot_interfaces", interfaces="unknown")
                == len(ROBOTS)
            ),
            "every robot's interfaces unknown",
        )
        publish_interfaces(mosquitto.url, "tb3-04", report(ODOM))  # no Nav2
        publish_interfaces(mosquitto.url, "tb3-02", b"garbage")
        told = wait_for(lambda: receiver.events("robot_drifted"), "tb3-04's drift told")
        assert told[0]["robot"] == "tb3-04"
        assert told[0]["message"] == (
            "tb3-04 drifted: lacks /navigate_to_pose (nav2_msgs/action/NavigateToPose), "
            "needed by navigate_with_nav2 via action client mapping navigate_to_pose"
        )
        wait_for(
            lambda: (
                (m := scrape(port))
                and value(m, "robotconf_drifted_robots") == 1
                and value(m, "robotconf_robot_interfaces", interfaces="error") == 1
                and value(m, "robotconf_robot_interfaces", interfaces="reported") == 1
            ),
            "one robot drifted, one unreadable, scraped",
        )
        # Another report with the same drift is no new transition.
        publish_interfaces(mosquitto.url, "tb3-04", report(ODOM, ("/scan", "x/msg/Y")))
        publish_interfaces(mosquitto.url, "tb3-04", report(ODOM, actions=(NAV2,)))
        wait_for(lambda: receiver.events("robot_drift_cleared"), "tb3-04 fits again, told")
        wait_for(lambda: value(scrape(port), "robotconf_drifted_robots") == 0, "no robot drifted")
        assert len(receiver.events("robot_drifted")) == 1
        assert len(receiver.events("robot_drift_cleared")) == 1
    finally:
        running.stop()
        telemetry.stop()


def test_hold_keeps_the_old_request_until_the_robot_s_interfaces_fit(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch
) -> None:
    lab.write(FLEET, lab.read(FLEET) + "drift: hold\n")
    lab.commit("hold on drift")
    running = Running(LocalBranch(lab.root, "main"), mosquitto.url)
    try:
        first = lab.head()
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == first, "applied")
        old = lab.requests()["tb3-04"].digest
        assert watch.digest("tb3-04") == old  # unknown interfaces: delivered, never held
        publish_interfaces(mosquitto.url, "tb3-04", report(ODOM))  # no Nav2

        lab.replace(FLEET, "name: Lab patrol,", "name: Lab patrol 2,")
        second = lab.commit("rename the patrol robot: a new request for tb3-04")
        new = lab.requests()["tb3-04"].digest
        status = watch.wait_reconciler(
            lambda s: s.last_applied_revision == second and bool(s.held), "tb3-04 held"
        )
        assert [h.robot for h in status.held] == ["tb3-04"]
        assert "lacks /navigate_to_pose" in status.held[0].reason
        assert "held for drift" in status.message
        assert watch.digest("tb3-04") == old  # its last good request stays

        # `robotconf status` says why it is not in sync.
        done = subprocess.run(
            robotconf_argv("status", "--repo", str(lab.root), "--broker", mosquitto.url, "--json"),
            capture_output=True,
            text=True,
            timeout=60,
        )
        rows = {r["robot_id"]: r for r in json.loads(done.stdout)["robots"]}
        assert "held by the reconciler for drift" in rows["tb3-04"]["reason"]
        assert rows["tb3-04"]["drift"][0]["mapping"] == "navigate_to_pose"

        publish_interfaces(mosquitto.url, "tb3-04", report(ODOM, actions=(NAV2,)))
        wait_for(lambda: watch.digest("tb3-04") == new, "tb3-04 released when it fits")
        watch.wait_reconciler(lambda s: not s.held and s.ready, "nothing held")
    finally:
        running.stop()
