"""The robot side installs alone: `pip install robotconf` into a fresh environment brings only
paho-mqtt, pydantic and PyYAML, and its `robotconf-agent` runs a brain from a real broker."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from contract.wire import AgentState, Topics
from tests.support.agents import ROBOT, AgentProc, make_request, publish
from tests.support.lab import ROOT
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

PACKAGES = ("contract", "configurator", "reconciler", "workstation", "agent")
ROBOT_NEEDS = {"paho-mqtt", "pydantic", "pyyaml"}
SERVER_ONLY = {"click", "cryptography", "gitpython", "watchfiles", "amqtt", "rich"}
INSTALL_TIMEOUT = 600


def _clean_env() -> dict[str, str]:
    """No PYTHONPATH: the fresh environment must not see this checkout."""
    return {k: v for k, v in os.environ.items() if k not in {"PYTHONPATH", "PYTHONHOME"}}


def _run(argv: list[str], cwd: Path | None = None) -> str:
    # Outside the checkout: `python -c` and `-m` put the working folder on sys.path.
    done = subprocess.run(
        argv,
        cwd=cwd or Path("/"),
        env=_clean_env(),
        capture_output=True,
        text=True,
        timeout=INSTALL_TIMEOUT,
        check=False,
    )
    assert done.returncode == 0, f"{' '.join(argv)}\n{done.stdout}\n{done.stderr}"
    return done.stdout


def _wheel(dest: Path) -> Path:
    """robotconf's wheel, built offline with this venv's setuptools from a copy of the project
    (so that the build's egg-info stays out of the checkout)."""
    project = dest / "project"
    project.mkdir(parents=True)
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, project / name)
    for package in PACKAGES:
        shutil.copytree(
            ROOT / package, project / package, ignore=shutil.ignore_patterns("__pycache__")
        )
    wheels = dest / "wheels"
    pip = [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation"]
    _run([*pip, "-w", str(wheels), str(project)])
    (wheel,) = wheels.glob("robotconf-*.whl")
    return wheel


@pytest.fixture(scope="module")
def robot_env(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh virtual environment (no system site-packages) with only the robot side."""
    root = tmp_path_factory.mktemp("robot-install")
    wheel = _wheel(root)
    env = root / "venv"
    _run([sys.executable, "-m", "venv", str(env)])
    _run([str(env / "bin" / "python"), "-m", "pip", "install", "-q", str(wheel)])
    return env


def _distributions(env: Path) -> set[str]:
    listed = _run([str(env / "bin" / "python"), "-m", "pip", "list", "--format=json"])
    return {entry["name"].lower().replace("_", "-") for entry in json.loads(listed)}


def test_the_robot_install_brings_only_the_three_libraries(robot_env: Path) -> None:
    code = (
        "import json; from importlib.metadata import requires; "
        "print(json.dumps([r for r in requires('robotconf') if 'extra ==' not in r]))"
    )
    required = json.loads(_run([str(robot_env / "bin" / "python"), "-c", code]))
    names = {r.split(">")[0].split("<")[0].split("=")[0].strip().lower() for r in required}
    assert names == ROBOT_NEEDS
    installed = _distributions(robot_env)
    assert installed >= ROBOT_NEEDS
    assert not installed & SERVER_ONLY, installed & SERVER_ONLY
    where = _run([str(robot_env / "bin" / "python"), "-c", "import agent; print(agent.__file__)"])
    assert where.startswith(str(robot_env)), where


def test_the_workstation_commands_say_what_to_install(robot_env: Path) -> None:
    done = subprocess.run(
        [str(robot_env / "bin" / "robotconf"), "validate"],
        cwd="/",
        env=_clean_env(),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2
    assert "robotconf[server]" in done.stderr and "Traceback" not in done.stderr
    helped = _run([str(robot_env / "bin" / "robotconf"), "agent", "--help"])
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
        command=[python, "-m", "agent.standin_brain", "{launch_request}"],
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
