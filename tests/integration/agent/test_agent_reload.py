"""Reload without restart, end to end: a real agent, a real Mosquitto, the stand-in brain."""

from __future__ import annotations

import subprocess
import sys

from robotconf.agent.process import is_alive
from robotconf.contract.wire import AgentState, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import ROBOT, TIMEOUT, make_request, publish, start_running
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

LAUNCH = Topics().launch(ROBOT)
RELOAD = {"signal": "SIGHUP"}
SHELVES = {"shelves": {"A": {"x": 1.0, "y": 2.0}}}


def test_a_knowledge_only_change_reloads_the_running_brain(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent(reload=RELOAD)
    first = start_running(agent, watch, mosquitto)
    assert first.reloads == 0
    # `running` may come from startsecs before the brain's hello on its socket, which makes it
    # `starting` again until its ready: the reload is asked of a brain that said ready.
    watch.wait_for(ROBOT, lambda s: s.message.endswith(", ready)"), "ready", agent=agent)
    request = make_request(knowledge=SHELVES, revision="rev-2")
    assert request.restart_digest == make_request().restart_digest  # only knowledge changed
    publish(mosquitto.url, LAUNCH, request.payload())

    reloaded = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    assert reloaded.pid == first.pid and first.pid is not None and is_alive(first.pid)
    assert (reloaded.reloads, reloaded.restarts, reloaded.revision) == (1, 0, "rev-2")
    # The new request is on disk, byte for byte as published, and the brain read it.
    assert (agent.workdir / "launch-request.json").read_bytes() == request.payload()
    line = f"stand-in brain: SIGHUP received, reloaded {request.digest} at rev-2"
    wait_for(lambda: line in agent.brain_log(), "the brain's reload in its log")
    assert "SIGTERM" not in agent.brain_log()  # never stopped
    assert agent.brain_log().count("started pid") == 1
    # Only `running` was reported since: no stop, no start.
    after = [s.state for s in watch.history(ROBOT) if s.digest == request.digest]
    assert set(after) == {AgentState.RUNNING}


def test_a_logic_change_restarts_the_brain(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent(reload=RELOAD)
    first = start_running(agent, watch, mosquitto)
    publish(mosquitto.url, LAUNCH, make_request(knowledge=SHELVES).payload())
    reloaded = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, reloads=1)
    assert reloaded.pid == first.pid
    request = make_request(knowledge=SHELVES, logic="follow_by_spinning")
    publish(mosquitto.url, LAUNCH, request.payload())

    second = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(second.pid)
    assert second.pid != first.pid and first.pid is not None and not is_alive(first.pid)
    assert second.reloads == 0  # a new capability: a new brain, counting afresh
    assert agent.request_on_disk()["restart_digest"] == request.restart_digest
    assert "SIGTERM received, stopping" in agent.brain_log()


def test_without_reload_in_agent_yaml_a_knowledge_change_restarts(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    first = start_running(agent, watch, mosquitto)
    request = make_request(knowledge=SHELVES)
    publish(mosquitto.url, LAUNCH, request.payload())

    second = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(second.pid)
    assert second.pid != first.pid and second.reloads == 0
    assert "reloaded" not in agent.brain_log()


def test_a_request_from_an_older_reconciler_restarts(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent(reload=RELOAD)
    first = start_running(agent, watch, mosquitto)
    older = make_request(knowledge=SHELVES).model_copy(update={"restart_digest": None})
    publish(mosquitto.url, LAUNCH, older.payload())

    second = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=older.digest)
    agent.note_brain(second.pid)
    assert second.pid != first.pid and second.reloads == 0


def test_a_reload_that_cannot_be_written_leaves_the_brain_on_its_request(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent(reload=RELOAD)
    running = start_running(agent, watch, mosquitto)
    before = agent.request_on_disk()
    staged = agent.workdir / "launch-request.json.next"
    staged.mkdir()  # where the next request is written cannot take a file, as on a full disk
    publish(mosquitto.url, LAUNCH, make_request(knowledge=SHELVES).payload())

    refused = watch.wait_state(ROBOT, AgentState.REJECTED, agent=agent)
    assert (refused.pid, refused.digest, refused.reloads) == (running.pid, running.digest, 0)
    assert "EISDIR" in refused.message and "left as it is" in refused.message
    assert agent.request_on_disk() == before
    assert "reloaded" not in agent.brain_log()
    # Once it can be written, the same request arriving again is reloaded.
    staged.rmdir()
    request = make_request(knowledge=SHELVES, revision="rev-2")
    publish(mosquitto.url, LAUNCH, request.payload())
    reloaded = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    assert reloaded.pid == running.pid and reloaded.reloads == 1


def test_a_bad_reload_signal_is_a_located_config_error(make_agent: AgentFactory) -> None:
    agent = make_agent(reload={"signal": "SIGKILL"})
    lines = agent.config_path.read_text(encoding="utf-8").splitlines()
    line = 1 + next(n for n, text in enumerate(lines) if "SIGKILL" in text)
    result = subprocess.run(
        [sys.executable, "-m", "robotconf.agent.cli", "--config", str(agent.config_path)],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        check=False,
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.splitlines() == [
        f"{agent.config_path}:{line}: reload.signal: 'SIGKILL' is not a signal a brain catches "
        "to reload; use one of SIGHUP, SIGUSR1, SIGUSR2, e.g. reload: {signal: SIGHUP}"
    ]
