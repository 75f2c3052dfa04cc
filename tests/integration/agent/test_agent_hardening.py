"""No payload stops the agent, and a new request never stops the running brain before the new
one can start (issue 10, items 3 and 9): real agents, real Mosquitto, the stand-in brain."""

from __future__ import annotations

import json
import os

import pytest

from robotconf.agent.process import is_alive
from robotconf.contract.wire import AgentState, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import ROBOT, make_request, publish, start_running
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch

TOPICS = Topics()
LAUNCH, STATUS = TOPICS.launch(ROBOT), TOPICS.status(ROBOT)

KILLERS = [
    b"[" * 100_000 + b"]" * 100_000,
    b'{"apiVersion": "robotconf/v1", "robot_id": "tb3-01", "issued_at": Infinity}',
    b'{"apiVersion": "robotconf/v1", "robot_id": "tb3-01", "issued_at": 1e999}',
    b'{"apiVersion": "robotconf/v1", "robot_id": "tb3-01", "x": "\\ud800"}',
    b'{"apiVersion": "robotconf/v1", "robot_id": "tb3-01", "n": ' + b"9" * 5000 + b"}",
    b"x" * 3_000_000,
]


@pytest.mark.parametrize("payload", KILLERS, ids=range(len(KILLERS)))
def test_a_retained_hostile_request_is_rejected_at_every_start(
    payload: bytes, mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    publish(mosquitto.url, LAUNCH, payload)
    agent = make_agent().start()
    watch.wait_state(ROBOT, AgentState.REJECTED, agent=agent)
    # And again after a restart: the retained payload is delivered once more.
    agent.signal(__import__("signal").SIGTERM)
    assert agent.wait() == 0
    agent.start()
    watch.wait_state(ROBOT, AgentState.REJECTED, agent=agent)
    # A good request still gets through.
    request = make_request()
    publish(mosquitto.url, LAUNCH, request.payload())
    status = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(status.pid)


def test_hostile_payloads_on_its_own_status_topic_change_nothing(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    running = start_running(agent, watch, mosquitto)
    for payload in (
        b"[" * 100_000,
        b'{"robot_id": "tb3-01", "state": "offline", "seq": ' + b"9" * 5000 + b"}",
        b'{"robot_id": "tb3-01", "state": "bogus", "seq": 1}',
        b"\xff" * 100_000,
    ):
        publish(mosquitto.url, STATUS, payload, retain=False)
    request = make_request(variant=1)
    publish(mosquitto.url, LAUNCH, request.payload())
    status = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(status.pid)
    assert status.pid != running.pid and agent.proc is not None and agent.proc.poll() is None


def test_a_request_that_cannot_be_written_leaves_the_brain_running(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    running = start_running(agent, watch, mosquitto)
    # Where the next request is staged cannot take a file (a full or read-only disk fails
    # there the same way: before anything is stopped).
    staged = agent.workdir / "launch-request.json.next"
    staged.mkdir()
    publish(mosquitto.url, LAUNCH, make_request(variant=1).payload())
    refused = watch.wait_state(ROBOT, AgentState.REJECTED, agent=agent)
    assert refused.pid == running.pid and running.pid is not None and is_alive(running.pid)
    assert str(staged) in refused.message and "EISDIR" in refused.message
    assert "left as it is" in refused.message
    # Once the disk is writable again, the next request goes through.
    os.rmdir(staged)
    request = make_request(variant=2)
    publish(mosquitto.url, LAUNCH, request.payload())
    status = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(status.pid)
    assert agent.request_on_disk()["digest"] == request.digest
    assert not staged.exists()


def test_a_peer_cannot_forge_a_line_in_the_agents_log(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent().start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    forged = "\n2026-01-01 00:00:00 tb3-01 ERROR FORGED\r\x1b[2J\u2028"
    request = make_request().model_dump(mode="json")
    request["robot_id"] = "tb3-01" + forged
    publish(mosquitto.url, LAUNCH, json.dumps(request).encode())
    refused = watch.wait_state(ROBOT, AgentState.REJECTED, agent=agent)
    assert "FORGED" in refused.message  # what it refused is said...
    log = agent.stderr_path.read_text(encoding="utf-8")
    assert "FORGED" in log
    # ... on its own line, escaped: no line of the agent's log is the peer's.
    assert not any(line.startswith("2026-01-01") for line in log.splitlines())
    assert "\x1b" not in log and "\r" not in log and "\u2028" not in log
