"""A password in a broker URL is never echoed, whatever is wrong with the URL or the broker
(issue 10, item 10)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from tests.support.lab import ROBOTCONF, Lab

SECRET = "s3cr3t-Pa55"
URLS = [
    f"mqtt://robot:{SECRET}@127.0.0.1:99999",  # port out of range
    f"mqtt://robot:{SECRET}@127.0.0.1:notaport",
    f"ftp://robot:{SECRET}@127.0.0.1:1883",  # wrong scheme
    f"mqtt://robot:{SECRET}@127.0.0.1:1883/path",
    f"mqtt://robot:{SECRET}@127.0.0.1:1",  # nobody listens there
]


def run(*args: str, cwd: Path | None = None) -> str:
    done = subprocess.run([ROBOTCONF, *args], capture_output=True, text=True, timeout=60, cwd=cwd)
    assert done.returncode != 0
    return done.stdout + done.stderr


@pytest.mark.parametrize("url", URLS)
def test_status_never_echoes_the_password(url: str, tmp_path: Path) -> None:
    out = run("status", "--broker", url, "--wait", "1", "--repo", str(tmp_path))
    assert SECRET not in out and "Traceback" not in out


@pytest.mark.parametrize("url", URLS[:4])
def test_agent_check_and_reconcile_never_echo_the_password(url: str, tmp_path: Path) -> None:
    config = tmp_path / "agent.yaml"
    config.write_text(
        "description: {id: tb3-01}\ncommand: [brain, '{launch_request}']\nworkdir: w\n"
    )
    out = run("agent", "--config", str(config), "--broker", url, "--check")
    assert SECRET not in out and "Traceback" not in out
    lab = Lab(tmp_path / "lab")
    lab.commit("base")
    out = run("reconcile", "--repo", str(lab.root), "--branch", "main", "--broker", url)
    assert SECRET not in out and "Traceback" not in out
