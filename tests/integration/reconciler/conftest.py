"""Fixtures for the reconciler: a git lab, and a whole converged fleet on a real Mosquitto."""

from __future__ import annotations

import contextlib
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from robotconf.configurator.rendered import RenderedRequest
from robotconf.contract.wire import AgentStatus
from tests.support.fleet import (
    GitLab,
    Proc,
    robotconf_argv,
    start_agent,
    start_agents,
    start_reconciler,
)
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch

# One more robot shares tb3-01's scenario, so that "its robots" is more than one.
EXTRA_ROBOT = "  tb3-06: {scenario: delivery-gazebo, name: Second delivery bot}\n"


@pytest.fixture
def lab(tmp_path: Path, request: pytest.FixtureRequest) -> GitLab:
    """The example lab, committed; a test marked `robots(ID, ...)` keeps only those robots."""
    lab = GitLab(tmp_path / "lab")
    kept = request.node.get_closest_marker("robots")
    if kept is not None:
        lab.keep_robots(*kept.args)
    return lab


@dataclass
class Fleet:
    lab: GitLab
    broker: Mosquitto
    watch: FleetWatch
    folder: Path
    agents: dict[str, Proc] = field(default_factory=dict)  # one process a robot (apart)
    host: Proc | None = None  # or every robot's agent in one process
    reconciler: Proc | None = None
    converged: dict[str, AgentStatus] = field(default_factory=dict)
    logs: int = 0

    def start_reconciler(self, *extra: str) -> Proc:
        self.logs += 1
        self.reconciler = start_reconciler(
            self.lab, self.broker.url, self.folder / f"reconciler-{self.logs}.log", *extra
        )
        return self.reconciler

    def requests(self, revision: str | None = None) -> dict[str, RenderedRequest]:
        return self.lab.requests(revision)

    def status_cli(self, *extra: str) -> subprocess.CompletedProcess[str]:
        """`robotconf status` of this fleet, as a real process; never a traceback."""
        done = subprocess.run(
            robotconf_argv(
                "status", "--repo", str(self.lab.root), "--broker", self.broker.url, *extra
            ),
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert "Traceback" not in done.stdout + done.stderr, done.stderr
        return done


@contextlib.contextmanager
def fleet_on(tmp_path: Path, broker: Mosquitto, apart: bool = False) -> Iterator[Fleet]:
    """Seven agents with the stand-in brain and a reconciler on `main` on `broker`, all running
    (converged); stopped on the way out. The agents share one process (as a simulation host
    runs them), or with `apart` each has its own, for tests that kill or start one robot."""
    lab = GitLab(tmp_path / "lab")
    lab.write("configs/fleet.yaml", lab.read("configs/fleet.yaml") + EXTRA_ROBOT)
    lab.commit("one more robot")
    watch = FleetWatch(broker.url)
    state = Fleet(lab, broker, watch, tmp_path)
    try:
        if apart:
            for robot_id in lab.robots():
                state.agents[robot_id] = start_agent(lab, robot_id, broker.url, tmp_path / "agents")
        else:
            state.host = start_agents(lab.robots(), broker.url, tmp_path / "agents")
        state.start_reconciler("--interval", "5")
        state.converged = watch.wait_running(state.requests())
        yield state
    finally:
        watch.close()
        if state.reconciler is not None:
            state.reconciler.stop()
        for proc in [*state.agents.values(), *([state.host] if state.host else [])]:
            proc.stop()


@pytest.fixture
def fleet(tmp_path: Path, mosquitto: Mosquitto, request: pytest.FixtureRequest) -> Iterator[Fleet]:
    """The whole fleet on the test's broker; a test marked `agents_apart` gets an agent
    process per robot (fleet.agents)."""
    apart = request.node.get_closest_marker("agents_apart") is not None
    with fleet_on(tmp_path, mosquitto, apart) as state:
        yield state
