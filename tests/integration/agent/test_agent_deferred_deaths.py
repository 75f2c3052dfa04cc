"""Killed while deferred: a real agent whose stand-in brain holds it off (its hold file) is
killed with SIGKILL while a new request waits for the hold, and started again — alone (its
brain left running), and with its brain (a power cut, the hold left behind as a tree). Each
time the waiting request is not lost: it runs, and the next brain is not born held."""

from __future__ import annotations

import contextlib
import os
import signal
from pathlib import Path

from robotconf.agent.process import is_alive
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.integration.agent.test_agent_busy import LOGIC, busy_agent, deferred, run_held
from tests.support.agents import ROBOT, AgentProc, make_request, publish
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

TOPICS = Topics()


def kill_agent(agent: AgentProc) -> None:
    agent.signal(signal.SIGKILL)
    agent.wait()


def defer_a_new_request(
    agent: AgentProc, watch: FleetWatch, broker: Mosquitto, first: AgentStatus, variant: int
) -> str:
    """Publishes a request that restarts the brain; returns its digest once it is deferred."""
    request = make_request(variant=variant, logic=LOGIC if variant % 2 else "follow_with_poses")
    publish(broker.url, TOPICS.launch(ROBOT), request.payload())
    deferred(watch, agent, first, f"restart for request {request.digest}")
    return request.digest


def test_an_agent_killed_while_deferred_runs_the_waiting_request_when_back(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    agent, marker = busy_agent(make_agent, tmp_path)
    request = make_request()
    first = run_held(agent, watch, mosquitto, request.payload(), request.digest)
    waiting = defer_a_new_request(agent, watch, mosquitto, first, 1)
    kill_agent(agent)  # mid-deferral: the brain runs on, holding, an orphan
    assert first.pid is not None and is_alive(first.pid)
    marker.unlink()  # the next brain does not hold
    seen = len(watch.history(ROBOT))
    agent.start()
    # Back: the orphan is stopped (the agent's own stop is never deferred), and the request
    # that waited is the one that runs — retained on the broker, nothing lost.
    second = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=waiting)
    agent.note_brain(second.pid)
    assert second.pid != first.pid and not is_alive(first.pid)
    assert "left behind by a previous agent" in agent.log_tail(200)
    after = watch.history(ROBOT)[seen:]
    assert all(s.state is not AgentState.DEFERRED for s in after), [s.state for s in after]
    assert not (agent.workdir / "brain.hold").exists()


def test_a_power_cut_while_deferred_leaves_no_hold_on_the_next_brain(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    agent, marker = busy_agent(make_agent, tmp_path)
    request = make_request()
    first = run_held(agent, watch, mosquitto, request.payload(), request.digest)
    waiting = defer_a_new_request(agent, watch, mosquitto, first, 1)
    kill_agent(agent)  # the power goes: agent and brain, SIGKILL
    brain = first.pid
    assert brain is not None
    with contextlib.suppress(ProcessLookupError):
        os.killpg(brain, signal.SIGKILL)
    wait_for(lambda: not is_alive(brain), "the brain dead")
    # What the dead brain held with: a whole tree (a brain's scratch), not a file.
    hold = agent.workdir / "brain.hold"
    with contextlib.suppress(FileNotFoundError):
        hold.unlink()
    (hold / "task" / "step").mkdir(parents=True)
    (hold / "task" / "state.json").write_text("{}", encoding="utf-8")
    marker.unlink()
    agent.start()
    second = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=waiting)
    agent.note_brain(second.pid)
    assert not os.path.lexists(hold)  # removed before the brain started: never born held
    free = watch.wait_for(ROBOT, lambda s: not s.busy, "not busy", agent=agent)
    assert free.pid == second.pid
    # The next request that restarts it is not deferred by what the dead brain left.
    seen = len(watch.history(ROBOT))
    third = make_request(variant=2)
    publish(mosquitto.url, TOPICS.launch(ROBOT), third.payload())
    running = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=third.digest)
    agent.note_brain(running.pid)
    assert running.pid != second.pid
    after = watch.history(ROBOT)[seen:]
    assert all(s.state is not AgentState.DEFERRED for s in after), [s.state for s in after]
