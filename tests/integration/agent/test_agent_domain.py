"""The request's ROS domain in the brain's environment: real agents, a real Mosquitto, the
stand-in brain (which prints the ROS_DOMAIN_ID it was started with)."""

from __future__ import annotations

import pytest

from robotconf.contract.launch import LaunchRequest, with_digest
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import ROBOT, AgentProc, make_request, publish
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

LAUNCH = Topics().launch(ROBOT)


def on_domain(domain: int | None, variant: int = 0) -> LaunchRequest:
    return with_digest(make_request(variant=variant).model_copy(update={"ros_domain_id": domain}))


def run(
    agent: AgentProc, watch: FleetWatch, broker: Mosquitto, request: LaunchRequest, said: str
) -> AgentStatus:
    """`request` published; its brain running, and `said` in the brain's log after its start."""
    before = agent.brain_log() if (agent.workdir / "brain.log").exists() else ""
    publish(broker.url, LAUNCH, request.payload())
    running = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(running.pid)
    wait_for(lambda: said in agent.brain_log()[len(before) :], f"the brain to say {said!r}")
    return running


def test_the_requests_domain_is_the_brains_over_the_agents_own(
    mosquitto: Mosquitto,
    watch: FleetWatch,
    make_agent: AgentFactory,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The agent itself runs with one (a shell profile, a systemd unit): the repository's wins.
    monkeypatch.setenv("ROS_DOMAIN_ID", "9")
    agent = make_agent().start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    running = run(agent, watch, mosquitto, on_domain(4), "ROS domain: 4\n")
    assert running.warnings == []
    # A request without one leaves the brain the agent's environment, as before domains.
    running = run(agent, watch, mosquitto, on_domain(None, variant=1), "ROS domain: 9\n")
    assert running.warnings == []


def test_agent_yaml_overrides_the_domain_and_the_conflict_is_reported(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent(env={"ROS_DOMAIN_ID": "7"}).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    running = run(agent, watch, mosquitto, on_domain(4), "ROS domain: 7\n")
    conflict = (
        "agent.yaml's env sets ROS_DOMAIN_ID to 7, the launch request's ros_domain_id is 4: the "
        "brain runs in domain 7 (agent.yaml wins on the robot); make the two agree, or remove "
        "ROS_DOMAIN_ID from agent.yaml's env"
    )
    assert running.warnings == [conflict]  # in the retained status
    wait_for(lambda: conflict in agent.log_tail(200), "the conflict in the agent's log")
    # Equal values are no conflict; a change of domain restarts the brain.
    again = run(agent, watch, mosquitto, on_domain(7, variant=1), "ROS domain: 7\n")
    assert again.warnings == [] and again.pid != running.pid and again.reloads == 0
