"""Several robots' agents in one process (`--config a.yaml --config b.yaml`): a simulation host
with a real Mosquitto, real stand-in brains, real signals."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from robotconf.agent.cli import main
from robotconf.agent.process import is_alive
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import make_request, publish, read_retained
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

TOPICS = Topics()
ROBOTS = ["tb3-01", "tb3-02"]


def test_one_process_runs_two_robots_and_sigterm_stops_both_brains(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory
) -> None:
    first, second = (make_agent(robot, robot_id=robot) for robot in ROBOTS)
    host = first.start(second)
    for agent in (first, second):
        watch.wait_state(agent.robot_id, AgentState.IDLE, agent=host)
    running: dict[str, AgentStatus] = {}
    for variant, agent in enumerate((first, second)):
        request = make_request(robot_id=agent.robot_id, variant=variant)
        publish(mosquitto.url, TOPICS.launch(agent.robot_id), request.payload())
        status = watch.wait_state(
            agent.robot_id, AgentState.RUNNING, agent=host, digest=request.digest
        )
        host.note_brain(status.pid)
        running[agent.robot_id] = status
        # Each robot has its own work directory, request and brain.
        assert agent.request_on_disk()["robot_id"] == agent.robot_id
        wait_for(lambda a=agent: "platform module: ROS2" in a.brain_log(), "a brain's output")
    pids = {status.pid for status in running.values()}
    assert None not in pids and len(pids) == 2
    assert running["tb3-01"].digest != running["tb3-02"].digest

    host.signal(signal.SIGTERM)
    assert host.wait() == 0
    for agent in (first, second):
        assert not is_alive(running[agent.robot_id].pid or 0)
        assert "SIGTERM received, stopping" in agent.brain_log()
        final = AgentStatus.model_validate_json(
            read_retained(mosquitto.url, TOPICS.status(agent.robot_id))
        )
        assert (final.state, final.message) == (AgentState.OFFLINE, "agent stopped")
    # Every line of the shared log says which robot it is about.
    log = first.stderr_path.read_text(encoding="utf-8")
    for robot in ROBOTS:
        assert f" {robot} INFO started brain pid {running[robot].pid} " in log


def _agent_yaml(folder: Path, robot: str, workdir: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "agent.yaml"
    path.write_text(
        f"description: {{id: {robot}}}\ncommand: [sleep, '60']\nworkdir: {workdir}\n",
        encoding="utf-8",
    )
    return path


def test_check_covers_every_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a = _agent_yaml(tmp_path / "a", "tb3-01", "work")
    b = _agent_yaml(tmp_path / "b", "tb3-02", "work")  # relative to its own folder: distinct
    assert main(["--config", str(a), "--config", str(b), "--check"]) == 0
    assert capsys.readouterr().out.splitlines() == [
        f"{a}: ok (robot tb3-01)",
        f"{b}: ok (robot tb3-02)",
    ]
    bad = _agent_yaml(tmp_path / "bad", "tb3 03", "work")
    assert main(["--config", str(a), "--config", str(bad), "--check"]) == 2
    assert capsys.readouterr().err.startswith(f"{bad}:1: robot id 'tb3 03'")


def test_broker_overrides_every_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a = _agent_yaml(tmp_path / "a", "tb3-01", "work")
    b = _agent_yaml(tmp_path / "b", "tb3-02", "work")
    argv = ["--config", str(a), "--config", str(b), "--check", "--broker"]
    assert main([*argv, "mqtt://other:1884"]) == 0
    assert main([*argv, "tcp://x"]) == 2
    assert capsys.readouterr().err.startswith("--broker: broker URL 'tcp://x'")


@pytest.mark.parametrize("check", [True, False])
def test_one_robot_or_one_workdir_in_two_files_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], check: bool
) -> None:
    flag = ["--check"] if check else []
    a = _agent_yaml(tmp_path / "a", "tb3-01", str(tmp_path / "work-a"))
    same_robot = _agent_yaml(tmp_path / "b", "tb3-01", str(tmp_path / "work-b"))
    same_workdir = _agent_yaml(tmp_path / "c", "tb3-03", str(tmp_path / "work-a"))
    shared = (tmp_path / "work-a").resolve()

    assert main(["--config", str(a), "--config", str(same_robot), *flag]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [
        f"robotconf agent: {a} and {same_robot} both configure robot 'tb3-01'; one agent per robot"
    ]
    assert main(["--config", str(a), "--config", str(same_workdir), *flag]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [
        f"robotconf agent: {a} and {same_workdir} share workdir {shared}; give each its own"
    ]
    assert main(["--config", str(a), "--config", str(a), *flag]) == 2
    assert "both configure robot 'tb3-01'" in capsys.readouterr().err
