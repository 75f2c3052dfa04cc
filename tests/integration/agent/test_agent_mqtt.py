"""The agent end to end: real `robotconf agent` processes, a real Mosquitto, the stand-in brain."""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

from robotconf.agent.process import is_alive
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import (
    ROBOT,
    STANDIN,
    TIMEOUT,
    make_request,
    publish,
    read_retained,
    start_running,
)
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

TOPICS = Topics()
LAUNCH = TOPICS.launch(ROBOT)


def test_launch_starts_the_brain_with_the_request(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    running = start_running(agent, watch, mosquitto)

    request = make_request()
    assert running.revision == request.revision
    assert running.warnings == []
    assert running.seq >= 1
    # Running only after `starting`: the brain had to stay up for startsecs first.
    states = [s.state for s in watch.history(ROBOT)]
    assert states.index(AgentState.STARTING) < states.index(AgentState.RUNNING)
    # Described itself on the broker.
    description = wait_for(lambda: watch.description(ROBOT), "the robot description")
    assert description.recommended_template == "turtlebot3-camera"
    assert description.platform == "ROS2"
    # The request is on disk, private, byte for byte what was published.
    on_disk = agent.workdir / "launch-request.json"
    assert stat.S_IMODE(on_disk.stat().st_mode) == 0o600
    assert on_disk.read_bytes() == request.payload()
    # The stand-in brain read it; its output went to the brain log.
    wait_for(lambda: "platform module: ROS2" in agent.brain_log(), "the brain's output")
    assert "Follow: follow_with_poses" in agent.brain_log()


def test_the_brain_gets_its_request_path_robot_and_digest_in_its_environment(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    show = 'echo "env: $ROBOTCONF_ROBOT_ID $ROBOTCONF_DIGEST $ROBOTCONF_LAUNCH_REQUEST $HOME"'
    agent = make_agent(command=["sh", "-c", f"{show}; exec sleep 60"])
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    request = make_request()
    publish(mosquitto.url, LAUNCH, request.payload())
    running = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(running.pid)
    path = agent.workdir / "launch-request.json"
    # Its own three variables, and the agent's environment (HOME) besides.
    line = f"env: {ROBOT} {request.digest} {path} {os.environ.get('HOME', '')}"
    wait_for(lambda: line in agent.brain_log(), "the brain's environment in its log")


def test_agent_yaml_env_reaches_the_brain_only(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    secret = "s3cret-token-value"
    show = 'echo "ros: $ROS_DOMAIN_ID $RMW_IMPLEMENTATION $LAB_TOKEN $ROBOTCONF_ROBOT_ID"'
    agent = make_agent(
        command=["sh", "-c", f"{show}; exec sleep 60"],
        env={"ROS_DOMAIN_ID": "7", "RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp", "LAB_TOKEN": secret},
    )
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    request = make_request()
    publish(mosquitto.url, LAUNCH, request.payload())
    running = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(running.pid)
    # The brain sees them, beside the agent's own variables.
    line = f"ros: 7 rmw_cyclonedds_cpp {secret} {ROBOT}"
    wait_for(lambda: line in agent.brain_log(), "the brain's environment in its log")
    # Never logged (the agent logs at debug level here) nor published.
    assert secret not in agent.log_tail(10_000)
    assert "LAB_TOKEN" not in agent.log_tail(10_000)
    for topic in (TOPICS.status(ROBOT), TOPICS.description(ROBOT)):
        assert secret.encode() not in read_retained(mosquitto.url, topic)
    # The agent itself runs without them: only the brain's environment has them.
    assert agent.proc is not None
    own = (Path("/proc") / str(agent.pid) / "environ").read_bytes()
    assert secret.encode() not in own and b"ROS_DOMAIN_ID=7" not in own


def test_same_digest_again_changes_nothing(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    running = start_running(agent, watch, mosquitto)
    seen_before = len(watch.history(ROBOT))

    # A new commit that renders the same content: new revision, same digest.
    publish(mosquitto.url, LAUNCH, make_request(revision="rev-2").payload())
    # Messages on one topic arrive in order: once this marker is rejected, the agent has
    # handled the request before it.
    publish(mosquitto.url, LAUNCH, b"{not json")
    watch.wait_state(ROBOT, AgentState.REJECTED, agent=agent)
    publish(mosquitto.url, LAUNCH, make_request(revision="rev-3").payload())
    again = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent)

    assert again.pid == running.pid and again.pid is not None and is_alive(again.pid)
    assert again.revision == running.revision  # the brain still runs what it was started with
    states = {s.state for s in watch.history(ROBOT)[seen_before:]}
    assert states == {AgentState.REJECTED, AgentState.RUNNING}
    assert agent.brain_log().count("started pid") == 1  # started once, never again
    assert "launch request rejected: malformed launch request" in agent.brain_log()


def test_new_digest_stops_then_starts(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    first = start_running(agent, watch, mosquitto)
    second_request = make_request(variant=1, revision="rev-2")
    publish(mosquitto.url, LAUNCH, second_request.payload())

    second = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=second_request.digest)
    agent.note_brain(second.pid)
    assert second.pid != first.pid
    assert first.pid is not None and not is_alive(first.pid)
    # (A brain that stops this fast may never be reported `stopping`: see the stubborn one.)
    assert agent.request_on_disk()["digest"] == second_request.digest
    assert "SIGTERM received, stopping" in agent.brain_log()  # stopped gracefully


def test_empty_payload_stops_the_brain(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    running = start_running(agent, watch, mosquitto)
    publish(mosquitto.url, LAUNCH, b"")

    idle = watch.wait_state(ROBOT, AgentState.IDLE, agent=agent, pid=None)
    assert idle.digest is None
    assert running.pid is not None and not is_alive(running.pid)


def test_refused_requests_leave_the_brain_alone(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    running = start_running(agent, watch, mosquitto)
    other_api = json.loads(make_request(variant=2).payload())
    other_api["apiVersion"] = "robotconf/v9"
    refused = [
        (make_request(robot_id="tb3-99").payload(), "'tb3-99'"),
        (b"{truncated", "malformed JSON"),
        (json.dumps(other_api).encode(), "unknown apiVersion 'robotconf/v9'"),
        (make_request(variant=3, platform="ROS1").payload(), "platform 'ROS1'"),
    ]
    for payload, reason in refused:
        publish(mosquitto.url, LAUNCH, payload)

        def refused_for(s: AgentStatus, reason: str = reason) -> bool:
            return s.state == AgentState.REJECTED and reason in s.message

        status = watch.wait_for(ROBOT, refused_for, f"rejected: {reason}", agent=agent)
        assert status.pid == running.pid and status.digest == running.digest
        assert running.pid is not None and is_alive(running.pid)


def test_other_template_is_a_warning_not_a_rejection(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent().start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    request = make_request(template="turtlebot3-burger")
    publish(mosquitto.url, LAUNCH, request.payload())

    status = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(status.pid)
    assert len(status.warnings) == 1
    assert "turtlebot3-burger" in status.warnings[0]
    assert "turtlebot3-camera" in status.warnings[0]


def test_crash_loop_backs_off_then_fails(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent(
        command=[*STANDIN, "--exit-after", "0", "--exit-code", "3", "{launch_request}"],
        restart={
            "policy": "on-failure",
            "max_restarts": 2,
            "backoff_initial": 0.1,
            "backoff_max": 0.2,
        },
    ).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    publish(mosquitto.url, LAUNCH, make_request().payload())

    failed = watch.wait_state(ROBOT, AgentState.FAILED, agent=agent)
    assert failed.exit_code == 3
    assert failed.restarts == 2
    assert "gave up after 2 restarts" in failed.message
    backoffs = [s for s in watch.history(ROBOT) if s.state == AgentState.BACKOFF]
    assert [s.restarts for s in backoffs] == [0, 1]  # each restart went through a backoff


def test_clean_exit_is_exited(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent(command=[*STANDIN, "--exit-after", "0.5", "{launch_request}"]).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    publish(mosquitto.url, LAUNCH, make_request().payload())

    exited = watch.wait_state(ROBOT, AgentState.EXITED, agent=agent)
    assert exited.exit_code == 0 and exited.pid is None and exited.restarts == 0


def test_missing_executable_fails_with_the_os_error(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent(command=["/nonexistent/cbs-brain", "{launch_request}"]).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    publish(mosquitto.url, LAUNCH, make_request().payload())

    failed = watch.wait_state(ROBOT, AgentState.FAILED, agent=agent)
    assert "/nonexistent/cbs-brain" in failed.message
    assert "No such file or directory" in failed.message
    assert failed.pid is None


CHATTY = "import sys, time\nwhile True:\n    print('x' * 999, flush=True)\n    time.sleep(0.002)\n"


def test_brain_output_goes_to_a_capped_rotated_log(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent(
        command=[sys.executable, "-c", CHATTY, "{launch_request}"],
        log={"max_bytes": 4096, "backups": 2},
    ).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    publish(mosquitto.url, LAUNCH, make_request().payload())
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent)

    second = agent.workdir / "brain.log.2"
    wait_for(second.exists, "two rotations of brain.log")
    assert "x" * 999 in second.read_text(encoding="utf-8")
    assert not (agent.workdir / "brain.log.3").exists()  # only `backups` old files are kept


def test_stubborn_brain_is_killed_after_stop_timeout(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent(command=[*STANDIN, "--ignore-sigterm", "{launch_request}"], stop_timeout=0.5)
    first = start_running(agent, watch, mosquitto)
    second_request = make_request(variant=1)
    publish(mosquitto.url, LAUNCH, second_request.payload())

    second = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=second_request.digest)
    agent.note_brain(second.pid)
    assert first.pid is not None and not is_alive(first.pid)
    history = watch.history(ROBOT)
    # A brain that takes its time to stop is reported `stopping`, with its pid, all along.
    stopping = [s for s in history if s.state == AgentState.STOPPING]
    assert stopping and all(s.pid == first.pid for s in stopping)
    assert stopping[0].message.startswith("stopping for new request")
    assert any("sent SIGKILL" in s.message for s in stopping)


def test_broker_restart_keeps_the_brain(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    running = start_running(agent, watch, mosquitto)
    assert running.pid is not None

    mosquitto.kill()
    assert is_alive(running.pid)
    mosquitto.start()  # same port, retained messages gone (no persistence)

    back = watch.wait_for(
        ROBOT, lambda s: s.seq > running.seq, "a status from a new connection", agent=agent
    )
    assert back.state == AgentState.RUNNING and back.pid == running.pid
    assert is_alive(running.pid)
    wait_for(lambda: watch.description(ROBOT), "the description again")
    # The reconciler republishes after a broker loss: same digest, so still the same brain.
    publish(mosquitto.url, LAUNCH, make_request(revision="rev-2").payload())
    publish(mosquitto.url, LAUNCH, b"marker: not json")
    watch.wait_state(ROBOT, AgentState.REJECTED, agent=agent, pid=running.pid)


def test_an_agent_started_before_its_broker_waits_answers_signals_and_connects(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    mosquitto.stop()
    # Credentials in the URL (this broker takes any): they must not reach the log.
    with_password = f"mqtt://robot:s3cret-pw@{mosquitto.host}:{mosquitto.port}"
    waiting = make_agent("waiting", broker=with_password).start()
    failure = f"cannot connect to mqtt://{mosquitto.host}:{mosquitto.port}: "
    wait_for(lambda: failure in waiting.log_tail(), "a connection failure")
    assert "retrying with backoff" in waiting.log_tail()
    # Connecting runs beside the loop: a signal is handled while the broker is still away.
    waiting.signal(signal.SIGTERM)
    assert waiting.wait() == 0
    assert "agent stopped" in waiting.log_tail()
    assert "s3cret-pw" not in waiting.log_tail(lines=1000)

    agent = make_agent().start()
    wait_for(lambda: "retrying with backoff" in agent.log_tail(), "a connection failure")
    mosquitto.start()  # same port
    idle = watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    assert idle.seq >= 1


def test_sigterm_stops_the_brain_and_reports_offline(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    running = start_running(agent, watch, mosquitto)
    agent.signal(signal.SIGTERM)

    assert agent.wait() == 0
    assert running.pid is not None and not is_alive(running.pid)
    final = AgentStatus.model_validate_json(read_retained(mosquitto.url, TOPICS.status(ROBOT)))
    assert final.state == AgentState.OFFLINE
    assert final.message == "agent stopped"  # its own goodbye, not its Last Will
    assert final.seq == running.seq
    assert "SIGTERM received, stopping" in agent.brain_log()
    assert not (agent.workdir / "brain.pid").exists()


def test_sigint_is_a_graceful_stop_too(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    running = start_running(agent, watch, mosquitto)
    agent.signal(signal.SIGINT)

    assert agent.wait() == 0
    assert running.pid is not None and not is_alive(running.pid)
    watch.wait_state(ROBOT, AgentState.OFFLINE, message="agent stopped")


def test_sigkill_leaves_an_orphan_that_the_next_agent_stops(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    running = start_running(agent, watch, mosquitto)
    assert running.pid is not None
    agent.signal(signal.SIGKILL)
    agent.wait()

    will = watch.wait_state(ROBOT, AgentState.OFFLINE, agent=agent)
    assert will.seq == running.seq and "Last Will" in will.message
    assert is_alive(running.pid)  # the brain outlived its agent

    agent.start()  # same agent.yaml, same work directory
    back = watch.wait_for(
        ROBOT,
        lambda s: s.state == AgentState.RUNNING and s.pid != running.pid,
        "a fresh brain",
        agent=agent,
    )
    agent.note_brain(back.pid)
    assert back.seq > running.seq  # seq persisted across agents
    assert not is_alive(running.pid)
    assert f"brain pid {running.pid} left behind" in agent.log_tail(200)


GHOST = textwrap.dedent(
    """
    import sys, time
    import paho.mqtt.client as paho
    from paho.mqtt.enums import CallbackAPIVersion
    host, port, topic, will = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
    client = paho.Client(CallbackAPIVersion.VERSION2, client_id="ghost-of-an-old-connection")
    client.will_set(topic, will, qos=1, retain=True)
    client.on_connect = lambda *a: print("connected", flush=True)
    client.connect(host, port)
    client.loop_forever()
    """
)


def test_late_last_will_from_an_older_connection_is_overwritten(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    running = start_running(agent, watch, mosquitto)
    seen_before = len(watch.history(ROBOT))
    stale = AgentStatus(robot_id=ROBOT, state=AgentState.OFFLINE, seq=running.seq - 1)
    # A connection that dies only now, carrying a will from before the live connection: what
    # the broker does when it notices a dead connection of the agent's previous run late.
    ghost = subprocess.Popen(
        [
            sys.executable,
            "-c",
            GHOST,
            mosquitto.host,
            str(mosquitto.port),
            TOPICS.status(ROBOT),
            stale.model_dump_json(),
        ],
        stdout=subprocess.PIPE,
    )
    try:
        assert ghost.stdout is not None and ghost.stdout.readline().strip() == b"connected"
    finally:
        os.kill(ghost.pid, signal.SIGKILL)
        ghost.wait()

    # The agent may overwrite it within a millisecond: look through the history, not the latest.
    watch.wait_seen(
        ROBOT,
        lambda s: s.state == AgentState.OFFLINE and s.seq == stale.seq,
        "the late Last Will",
        since=seen_before,
    )
    live = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, seq=running.seq)
    assert live.pid == running.pid
    retained = AgentStatus.model_validate_json(read_retained(mosquitto.url, TOPICS.status(ROBOT)))
    assert retained.state == AgentState.RUNNING and retained.seq == running.seq


def test_a_second_agent_on_the_same_workdir_is_refused(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent()
    running = start_running(agent, watch, mosquitto)
    intruder = subprocess.run(
        [sys.executable, "-m", "robotconf.agent.cli", "--config", str(agent.config_path)],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
    )
    assert intruder.returncode == 2
    assert "another agent" in intruder.stderr and "Traceback" not in intruder.stderr
    assert running.pid is not None and is_alive(running.pid)
