"""Beyond one broker: the fleet through two real Mosquittos bridged together — the reconciler on
the central broker, the agents on a site broker that bridges its robots' topics to it."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from robotconf.contract.wire import AgentState, AgentStatus
from tests.support.fleet import (
    GitLab,
    Proc,
    pid_alive,
    robotconf_argv,
    start_agent,
    start_reconciler,
)
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch

PREFIX = "robotconf"


def bridge_to(central: Mosquitto, name: str = "site-b") -> list[str]:
    """The site broker's bridge section (mosquitto.conf(5), "Configuring bridges"), as the
    docs/how-to/production-broker.md shows it: requests and the reconciler's status come in, the
    robots' statuses and descriptions go out, all at QoS 1. `try_private` (the default, written
    out because it matters) marks the connection as a bridge, so that the central broker keeps
    the retain flag of what it forwards: with `false` the requests are not retained on the site
    broker, no agent there ever finds its own, and this test fails."""
    return [
        f"connection {name}",
        f"address {central.host}:{central.port}",
        "try_private true",
        "cleansession true",
        "restart_timeout 1",  # a test need not wait 5 to 30 s for a retry
        f"topic {PREFIX}/robots/+/launch in 1",
        f"topic {PREFIX}/reconciler/status in 1",
        f"topic {PREFIX}/robots/+/status out 1",
        f"topic {PREFIX}/robots/+/description out 1",
        # From the desk (robotconf logs, robotconf restart): asks in, the log out.
        f"topic {PREFIX}/robots/+/restart in 1",
        f"topic {PREFIX}/robots/+/logs/request in 1",
        f"topic {PREFIX}/robots/+/logs out 1",
    ]


@pytest.fixture
def site(tmp_path_factory: pytest.TempPathFactory, mosquitto: Mosquitto) -> Iterator[Mosquitto]:
    """A second real broker, bridged to the `mosquitto` fixture (the central broker)."""
    broker = Mosquitto(
        Path(tmp_path_factory.mktemp("site-broker")), extra_config=bridge_to(mosquitto)
    )
    broker.start()
    try:
        yield broker
    finally:
        broker.kill()


def status_cli(lab: GitLab, broker: Mosquitto) -> tuple[int, dict[str, Any]]:
    done = subprocess.run(
        robotconf_argv(
            "status", "--repo", str(lab.root), "--broker", broker.url, "--json", "--wait", "10"
        ),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "Traceback" not in done.stdout + done.stderr, done.stderr
    return done.returncode, json.loads(done.stdout)


def desk_reaches_the_site(
    central: Mosquitto, at_center: FleetWatch, running: AgentStatus
) -> AgentStatus:
    """`robotconf logs` and `robotconf restart` of tb3-01 on the central broker: the log comes
    back, and the robot (`running` so) runs again, restarted by ops; its new status."""
    logs = subprocess.run(
        robotconf_argv("logs", "tb3-01", "--broker", central.url, "-n", "100"),
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert logs.returncode == 0 and "--- robotconf agent" in logs.stdout, logs.stderr
    restart = subprocess.run(
        robotconf_argv("restart", "tb3-01", "--broker", central.url, "--as", "ops"),
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert restart.returncode == 0, restart.stderr
    restarted = at_center.wait_for(
        "tb3-01",
        lambda s: s.state is AgentState.RUNNING and s.pid != running.pid,
        "tb3-01 running again after the restart",
    )
    assert restarted.restart_requested_by == "ops"
    return restarted


def retire_across_the_bridge(
    lab: GitLab, at_center: FleetWatch, at_site: FleetWatch, running: AgentStatus
) -> str:
    """A commit retiring tb3-05 (`running` so): its request cleared on both brokers, its brain
    stopped, the commit applied; the commit."""
    old_pid = running.pid
    lab.replace("configs/fleet.yaml", "  tb3-05:", "  # tb3-05:")
    retired = lab.commit("retire tb3-05")
    at_center.wait_for("tb3-05", lambda s: s.state is AgentState.IDLE, "tb3-05 idle")
    at_site.wait(lambda: at_site.launch("tb3-05") is None, "tb3-05 cleared at the site")
    assert at_center.launch("tb3-05") is None
    assert old_pid is not None and not pid_alive(old_pid)
    at_center.wait_reconciler(
        lambda s: s.ready and s.last_applied_revision == retired, "the retirement applied"
    )
    return retired


def test_the_fleet_runs_through_two_bridged_brokers(
    lab: GitLab, mosquitto: Mosquitto, site: Mosquitto, tmp_path: Path
) -> None:
    central = mosquitto
    agents: dict[str, Proc] = {}
    reconciler = start_reconciler(lab, central.url, tmp_path / "reconciler.log", "--interval", "5")
    at_center, at_site = FleetWatch(central.url), FleetWatch(site.url)
    try:
        first = lab.head()
        # The reconciler's status crossing the bridge says it is up.
        at_site.wait_reconciler(lambda s: s.last_applied_revision == first, "the bridge up")
        for robot_id in lab.robots():
            agents[robot_id] = start_agent(lab, robot_id, site.url, tmp_path / "agents")
        requests = lab.requests(first)
        at_site.wait_running(requests)
        converged = at_center.wait_running(requests)  # the statuses came back across

        code, report = status_cli(lab, central)
        assert code == 0, report
        verdicts = {r["robot_id"]: r["verdict"] for r in report["robots"]}
        assert verdicts == {robot: "InSync" for robot in requests}

        # From the desk on the central broker: a robot's log, and a restart, cross the bridge.
        converged["tb3-01"] = desk_reaches_the_site(central, at_center, converged["tb3-01"])

        # A commit reaches exactly its robots through the bridge.
        lab.replace(
            "configs/scenarios/patrol-real.yaml", "goal_tolerance: 0.3", "goal_tolerance: 0.25"
        )
        head = lab.commit("tighter patrol")
        requests = lab.requests(head)
        after = at_center.wait_running(requests)
        at_site.wait(lambda: at_site.digest("tb3-04") == requests["tb3-04"].digest, "tb3-04")
        moved = {r for r in requests if after[r].pid != converged[r].pid}
        assert moved == {"tb3-04", "tb3-07"}  # the lab's two patrollers

        # A robot leaving the fleet: the clear (an empty retained message) crosses too.
        retired = retire_across_the_bridge(lab, at_center, at_site, converged["tb3-05"])

        code, report = status_cli(lab, central)
        assert code == 0, report
        verdicts = {r["robot_id"]: r["verdict"] for r in report["robots"]}
        assert verdicts == {**{r: "InSync" for r in lab.requests(retired)}, "tb3-05": "Unassigned"}
    finally:
        at_center.close()
        at_site.close()
        assert reconciler.stop() == 0, reconciler.output()[-3000:]
        for proc in agents.values():
            proc.stop()
    assert "Traceback" not in reconciler.output()
