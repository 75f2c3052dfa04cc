"""The stand-in brain speaks robotconf.brain under a real agent and a real Mosquitto: it says
ready, runs its scenario's goal tasks as goals at the success rate and length its scenario's
knowledge sets, and a new request with another rate starts new counts."""

from __future__ import annotations

from typing import Any

from robotconf.agent.standin_brain import FAILURE_CODE, GOAL_SECONDS_KEY, SUCCESS_RATE_KEY
from robotconf.contract.goals import OutcomeState
from robotconf.contract.launch import LaunchGoal, LaunchRequest, make_launch_request
from robotconf.contract.wire import AgentState, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import ROBOT, make_request, publish
from tests.support.goals_watch import GoalsWatch
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch


def with_goals(rate: float, revision: str) -> LaunchRequest:
    knowledge: dict[str, Any] = {SUCCESS_RATE_KEY: rate, GOAL_SECONDS_KEY: 0.3}
    base = make_request(revision=revision, knowledge=knowledge)
    scenario = base.scenario.model_copy(
        update={"goals": [LaunchGoal(task="Delivery"), LaunchGoal(task="Patrol")]}
    )
    return make_launch_request(ROBOT, base.robot_name, revision, scenario)


def test_the_stand_in_runs_its_goals_at_the_rate_its_scenario_sets(
    mosquitto: Mosquitto, watch: FleetWatch, goals: GoalsWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent().start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    failing = with_goals(0.0, "rev-1")
    publish(mosquitto.url, Topics().launch(ROBOT), failing.payload())
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=failing.digest)
    summary = goals.wait_summary(
        ROBOT, lambda s: s.digest == failing.digest and s.failed >= 3, "three goals failed"
    )
    assert summary.reporting and summary.ready is True and summary.completed == 0
    assert summary.last is not None and summary.last.code == FAILURE_CODE
    assert set(summary.tasks) <= {"Delivery", "Patrol"} and summary.vitals.get("battery")
    records = [r for r in goals.records_of(ROBOT) if r.digest == failing.digest]
    assert records and {r.outcome for r in records} == {OutcomeState.FAILED}
    assert {r.revision for r in records} == {"rev-1"}

    # A commit that sets the rate to 1: new counts, every goal succeeds.
    fixed = with_goals(1.0, "rev-2")
    publish(mosquitto.url, Topics().launch(ROBOT), fixed.payload())
    summary = goals.wait_summary(
        ROBOT, lambda s: s.digest == fixed.digest and s.completed >= 3, "three goals succeeded"
    )
    assert summary.failed == 0 and summary.revision == "rev-2"
