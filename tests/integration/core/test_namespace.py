"""One import namespace (issue 33): installed, robotconf is one top-level package, so a
workstation that holds packages of its own named `agent` and `contract` keeps them, and the
commands work beside them. (The robot side's install is tried in test_robot_install.py.)"""

from __future__ import annotations

import json
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from tests.support.install import DECOYS, add_decoys, clean_env, run, shared_wheel, site_packages
from tests.support.lab import ROOT


@pytest.fixture(scope="module")
def workstation_env(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh environment: the unrelated `agent` and `contract` first, then robotconf's wheel.
    The server side's libraries (click, GitPython, ...) are this test run's own, named by a
    .pth file, so that the test needs no package index; robotconf itself comes from the wheel
    alone (the editable install's finder lives in a .pth there, which a named folder's .pth
    never runs)."""
    root = tmp_path_factory.mktemp("workstation-install")
    wheel = shared_wheel(tmp_path_factory)
    env = root / "venv"
    run([sys.executable, "-m", "venv", str(env)])
    add_decoys(env)
    python = str(env / "bin" / "python")
    run([python, "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)])
    (site_packages(env) / "libraries.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return env


def _robotconf(env: Path, *argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(env / "bin" / "robotconf"), *argv],
        cwd="/",
        env=clean_env(),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_robotconf_comes_from_the_wheel_and_the_decoys_stay_theirs(workstation_env: Path) -> None:
    code = (
        "import json, agent, contract, robotconf.workstation.cli as cli, robotconf.agent.cli as a\n"
        "print(json.dumps([agent.OWNER, contract.OWNER, cli.__file__, a.__file__]))"
    )
    agent, contract, cli, robot = json.loads(
        run([str(workstation_env / "bin" / "python"), "-c", code])
    )
    assert [agent, contract] == [f"someone else's {name}" for name in DECOYS]
    assert cli.startswith(str(workstation_env)) and robot.startswith(str(workstation_env))


def test_the_commands_work_beside_packages_named_agent_and_contract(
    workstation_env: Path,
) -> None:
    checked = _robotconf(workstation_env, "validate", "--repo", str(ROOT))
    assert checked.returncode == 0, checked.stderr
    assert "no problems" in checked.stderr
    rendered = _robotconf(workstation_env, "render", "tb3-01", "--repo", str(ROOT))
    assert rendered.returncode == 0, rendered.stderr
    assert json.loads(rendered.stdout)["robot_id"] == "tb3-01"
    helped = _robotconf(workstation_env, "agent", "--help")
    assert helped.returncode == 0 and "--config" in helped.stdout, helped.stderr
