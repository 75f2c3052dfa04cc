"""Fixtures of the agent tests: an watch of the fleet topics and agent processes."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.support.agents import AgentProc
from tests.support.goals_watch import GoalsWatch
from tests.support.mosquitto import Mosquitto

AgentFactory = Callable[..., AgentProc]


@pytest.fixture
def make_agent(tmp_path: Path, mosquitto: Mosquitto) -> Iterator[AgentFactory]:
    """Builds (not starts) agents against the test broker; all are cleaned up afterwards."""
    made: list[AgentProc] = []

    def factory(name: str = "agent", **settings: Any) -> AgentProc:
        agent = AgentProc(tmp_path / name, mosquitto.url, **settings)
        made.append(agent)
        return agent

    try:
        yield factory
    finally:
        for agent in made:
            agent.cleanup()


@pytest.fixture
def goals(mosquitto: Mosquitto) -> Iterator[GoalsWatch]:
    """The robots' goals summaries and outcome records, as the broker sends them."""
    watcher = GoalsWatch(mosquitto.url)
    try:
        yield watcher
    finally:
        watcher.close()
