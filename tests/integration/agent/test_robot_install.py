"""The robot side installs alone: `pip install robotconf` into a fresh environment brings only
paho-mqtt, pydantic and PyYAML, and its `robotconf-agent` runs a brain from a real broker, on a
robot that already holds packages of its own named `agent` and `contract`."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from robotconf.contract.wire import AgentState, Topics
from tests.support.agents import ROBOT, AgentProc, make_request, publish
from tests.support.install import (
    DECOYS,
    clean_env,
    fresh_install,
    run,
    shared_wheel,
    site_packages,
)
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

ROBOT_NEEDS = {"paho-mqtt", "pydantic", "pyyaml"}
SERVER_ONLY = {"click", "cryptography", "gitpython", "watchfiles", "amqtt", "rich"}


@pytest.fixture(scope="module")
def robot_env(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh virtual environment with only the robot side: `pip install robotconf`, into an
    environment that holds unrelated `agent` and `contract` packages (DECOYS) already."""
    wheel = shared_wheel(tmp_path_factory)
    return fresh_install(tmp_path_factory.mktemp("robot-install"), wheel, decoys=True)


def _distributions(env: Path) -> set[str]:
    listed = run([str(env / "bin" / "python"), "-m", "pip", "list", "--format=json"])
    return {entry["name"].lower().replace("_", "-") for entry in json.loads(listed)}


def test_the_robot_install_brings_only_the_three_libraries(robot_env: Path) -> None:
    code = (
        "import json; from importlib.metadata import requires; "
        "print(json.dumps([r for r in requires('robotconf') if 'extra ==' not in r]))"
    )
    required = json.loads(run([str(robot_env / "bin" / "python"), "-c", code]))
    names = {r.split(">")[0].split("<")[0].split("=")[0].strip().lower() for r in required}
    assert names == ROBOT_NEEDS
    installed = _distributions(robot_env)
    assert installed >= ROBOT_NEEDS
    assert not installed & SERVER_ONLY, installed & SERVER_ONLY
    code = "import robotconf.agent as a; print(a.__file__)"
    where = run([str(robot_env / "bin" / "python"), "-c", code])
    assert where.startswith(str(robot_env)), where
    # The brain library is the robot side's too: it imports with the three alone.
    code = "import sys, robotconf.brain as b; print(b.__file__, 'click' in sys.modules)"
    where, click = run([str(robot_env / "bin" / "python"), "-c", code]).split()
    assert where.startswith(str(robot_env)) and click == "False", where


def test_the_workstation_commands_say_what_to_install(robot_env: Path) -> None:
    done = subprocess.run(
        [str(robot_env / "bin" / "robotconf"), "validate"],
        cwd="/",
        env=clean_env(),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2
    assert "robotconf[server]" in done.stderr and "Traceback" not in done.stderr
    helped = run([str(robot_env / "bin" / "robotconf"), "agent", "--help"])
    assert "--config" in helped


def test_a_robot_only_agent_runs_a_brain_from_the_broker(
    robot_env: Path,
    tmp_path: Path,
    mosquitto: Mosquitto,
    watch: FleetWatch,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The agent and its brain must find this checkout nowhere: not on PYTHONPATH, not in cwd.
    monkeypatch.delenv("PYTHONPATH", raising=False)
    monkeypatch.chdir(tmp_path)
    python = str(robot_env / "bin" / "python")
    agent = AgentProc(
        tmp_path / "robot",
        mosquitto.url,
        command=[python, "-m", "robotconf.agent.standin_brain", "{launch_request}"],
        program=[str(robot_env / "bin" / "robotconf-agent")],
    )
    try:
        agent.start()
        watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
        request = make_request()
        publish(mosquitto.url, Topics().launch(ROBOT), request.payload())
        running = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
        agent.note_brain(running.pid)
        wait_for(lambda: "platform module: ROS2" in agent.brain_log(), "the brain's output")
        # It ran from the fresh environment, not from this checkout.
        cmdline = Path(f"/proc/{agent.pid}/cmdline").read_bytes().split(b"\0")
        assert cmdline[1].decode() == str(robot_env / "bin" / "robotconf-agent")
    finally:
        agent.cleanup()


def test_the_install_lands_under_robotconf_alone_and_leaves_other_packages_be(
    robot_env: Path,
) -> None:
    """Nothing of ours at the top of site-packages but `robotconf`; the robot's own `agent`
    and `contract` are still theirs after the install (a wheel of top-level packages once
    wrote over them), and the agent ran beside them (the test above)."""
    ours = run([str(robot_env / "bin" / "python"), "-m", "pip", "show", "-f", "robotconf"])
    files = [line.strip() for line in ours.split("Files:", 1)[1].splitlines() if line.strip()]
    tops = {name.split("/")[0] for name in files if not name.startswith("../")}
    assert {top for top in tops if not top.endswith(".dist-info")} == {"robotconf"}, tops
    code = "import agent, contract; print(agent.OWNER); print(contract.OWNER)"
    owners = run([str(robot_env / "bin" / "python"), "-c", code]).splitlines()
    assert owners == [f"someone else's {name}" for name in DECOYS]
    for name in DECOYS:
        assert (site_packages(robot_env) / name / "__init__.py").read_text().startswith("OWNER")
