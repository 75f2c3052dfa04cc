"""Busy robots, end to end: real agents and stand-in brains holding their hold file over a real
Mosquitto; a new request, a reload, a signed stop and a restart from the desk wait for it."""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

from robotconf.agent.process import is_alive
from robotconf.contract.launch import StopRequest
from robotconf.contract.signing import generate_keys, load_private_key, sign
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import ROBOT, STANDIN, AgentProc, make_request, publish
from tests.support.lab import ROBOTCONF
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

TOPICS = Topics()
LOGIC = "follow_by_spinning"  # another capability: a new request restarts the brain


def busy_agent(make_agent: AgentFactory, tmp_path: Path, **settings: Any) -> tuple[AgentProc, Path]:
    """An agent whose stand-in brain holds its agent off while the returned marker exists."""
    marker = tmp_path / "busy"
    marker.touch()
    command = [*STANDIN, "{launch_request}", "--hold-while", str(marker)]
    settings.setdefault("max_defer", 60)
    return make_agent(command=command, **settings), marker


def run_held(
    agent: AgentProc, watch: FleetWatch, broker: Mosquitto, payload: bytes, digest: str
) -> AgentStatus:
    """Starts the agent with `payload` and waits until its brain runs and holds."""
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    publish(broker.url, TOPICS.launch(ROBOT), payload)
    status = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=digest)
    agent.note_brain(status.pid)
    wait_for(lambda: "busy, holding the agent off" in agent.brain_log(), "the brain to hold")
    assert (agent.workdir / "brain.hold").exists()
    return status


def deferred(watch: FleetWatch, agent: AgentProc, first: AgentStatus, what: str) -> AgentStatus:
    """The robot's `deferred` status: the same brain runs on, on the request it ran."""
    status = watch.wait_state(ROBOT, AgentState.DEFERRED, agent=agent)
    assert status.pid == first.pid and first.pid is not None and is_alive(first.pid)
    assert status.digest == first.digest
    assert status.deferred_since is not None and status.max_defer is not None
    assert f"{what} deferred by the brain's hold file since" in status.message
    return status


def test_a_new_request_waits_until_the_brain_releases_its_hold(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    agent, marker = busy_agent(make_agent, tmp_path)
    request = make_request()
    first = run_held(agent, watch, mosquitto, request.payload(), request.digest)
    newer = make_request(logic=LOGIC)
    publish(mosquitto.url, TOPICS.launch(ROBOT), newer.payload())
    deferred(watch, agent, first, f"restart for request {newer.digest}")
    newest = make_request(logic=LOGIC, variant=1)  # replaces the one that waits
    publish(mosquitto.url, TOPICS.launch(ROBOT), newest.payload())
    watch.wait_for(
        ROBOT,
        lambda s: s.state == AgentState.DEFERRED and newest.digest in s.message,
        "the newest request to wait instead",
        agent=agent,
    )
    assert is_alive(first.pid or 0)
    marker.unlink()  # the brain's task is done: it removes its hold file
    second = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=newest.digest)
    agent.note_brain(second.pid)
    assert second.pid != first.pid and second.deferred_since is None
    assert "removed its hold file" in agent.brain_log()
    assert newer.digest not in {s.digest for s in watch.history(ROBOT)}


def test_max_defer_ends_a_hold_that_never_lifts(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    agent, _ = busy_agent(make_agent, tmp_path, max_defer=1)
    request = make_request()
    first = run_held(agent, watch, mosquitto, request.payload(), request.digest)
    newer = make_request(logic=LOGIC)
    publish(mosquitto.url, TOPICS.launch(ROBOT), newer.payload())
    deferred(watch, agent, first, f"restart for request {newer.digest}")
    second = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=newer.digest)
    agent.note_brain(second.pid)
    assert second.pid != first.pid
    wait_for(lambda: "deferral ran out after 1 s (max_defer)" in agent.log_tail(200), "why")


def test_a_reload_waits_for_the_hold_then_signals_the_same_brain(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    agent, marker = busy_agent(make_agent, tmp_path, reload={"signal": "SIGHUP"})
    request = make_request()
    first = run_held(agent, watch, mosquitto, request.payload(), request.digest)
    newer = make_request(knowledge={"shelves": {"A": {"x": 1.0, "y": 2.0}}})
    assert newer.restart_digest == request.restart_digest  # a reload, not a restart
    publish(mosquitto.url, TOPICS.launch(ROBOT), newer.payload())
    deferred(watch, agent, first, f"reload to request {newer.digest}")
    assert "SIGHUP received" not in agent.brain_log()
    marker.unlink()
    reloaded = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=newer.digest)
    assert reloaded.pid == first.pid and reloaded.reloads == 1
    wait_for(lambda: "SIGHUP received, reloaded" in agent.brain_log(), "the brain's reload")


def test_a_signed_stop_for_a_robot_leaving_the_fleet_waits_for_the_hold(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    keys = generate_keys(tmp_path / "keys")
    private = load_private_key(keys.private)
    agent, marker = busy_agent(make_agent, tmp_path, public_key=str(keys.public))
    request = sign(make_request(), private)
    first = run_held(agent, watch, mosquitto, request.payload(), request.digest)
    stop = sign(StopRequest(robot_id=ROBOT, revision="rev-gone"), private)
    publish(mosquitto.url, TOPICS.launch(ROBOT), stop.payload())
    deferred(watch, agent, first, "stop (no launch request for this robot)")
    marker.unlink()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    assert first.pid is not None and not is_alive(first.pid)
    assert "SIGTERM received, stopping" in agent.brain_log()


def test_a_restart_from_the_desk_is_taken_deferred_then_carried_out(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    agent, marker = busy_agent(make_agent, tmp_path)
    request = make_request()
    first = run_held(agent, watch, mosquitto, request.payload(), request.digest)
    done = subprocess.run(
        [str(ROBOTCONF), "restart", ROBOT, "--as", "ops", "--broker", mosquitto.url],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert "restart requested by ops: deferred" in done.stdout
    status = deferred(watch, agent, first, "restart requested by ops")
    assert status.restart_requested_by == "ops"
    marker.unlink()
    second = watch.wait_for(
        ROBOT,
        lambda s: s.state == AgentState.RUNNING and s.pid != first.pid,
        "a new brain",
        agent=agent,
    )
    agent.note_brain(second.pid)
    assert second.digest == request.digest


def test_the_status_says_busy_while_the_hold_file_exists(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    """Before any request would wait for it: the reconciler holds a group's restart while one
    of its robots says it is busy."""
    agent, marker = busy_agent(make_agent, tmp_path, max_defer=45)
    request = make_request()
    first = run_held(agent, watch, mosquitto, request.payload(), request.digest)
    busy = watch.wait_for(ROBOT, lambda s: s.busy, "the status saying busy", agent=agent)
    assert busy.state is AgentState.RUNNING and busy.max_defer == 45
    assert busy.pid == first.pid
    marker.unlink()  # the brain lets go of its hold file
    free = watch.wait_for(ROBOT, lambda s: not s.busy, "busy no more", agent=agent)
    assert free.state is AgentState.RUNNING and free.max_defer is None
