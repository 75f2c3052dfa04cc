"""The documented production example stays true: current with the fleet, a valid agent.yaml, and
a systemd unit that systemd accepts and that runs that agent.yaml as the robotconf user."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from robotconf.agent.config import load_config
from tests.support.lab import ROBOTCONF, ROOT
from tests.support.private import write_private

EXAMPLE = ROOT / "examples" / "production"


def test_example_broker_files_are_what_broker_config_writes(tmp_path: Path) -> None:
    out = tmp_path / "broker"
    done = subprocess.run(
        [
            ROBOTCONF, "broker-config", "--repo", str(ROOT), "--out", str(out),
            "--install-dir", "/etc/mosquitto/robotconf",
            "--certfile", "/etc/mosquitto/certs/server.crt",
            "--keyfile", "/etc/mosquitto/certs/server.key",
        ],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    for name in ("acl", "mosquitto.conf"):
        assert (out / name).read_text() == (EXAMPLE / name).read_text(), (
            f"examples/production/{name} is stale: regenerate it (see its README)"
        )
    assert not (EXAMPLE / "passwd").exists() and not (EXAMPLE / "secrets").exists()


def test_example_agent_yaml_is_valid(tmp_path: Path) -> None:
    text = (EXAMPLE / "agent.yaml").read_text(encoding="utf-8")
    folder = tmp_path / "etc"
    folder.mkdir()
    # The referenced files and workdir exist on a robot; stand them in here.
    write_private(folder / "tb3-01.password", "secret\n")
    (folder / "ca.crt").write_text("")
    subprocess.run([ROBOTCONF, "keys", "generate", "--out", str(folder)], check=True)
    text = text.replace("/var/lib/robotconf/tb3-01", str(tmp_path / "work"))
    (folder / "agent.yaml").write_text(text, encoding="utf-8")
    config = load_config(folder / "agent.yaml")
    assert config.public_key == folder / "launch-signing.pub"
    assert config.connection().address.tls


UNIT = EXAMPLE / "robotconf-agent.service"
INSTALLED_CONFIG = "/etc/robotconf/agent.yaml"  # where agent.yaml's header says it goes
# The robot-only install's command (docs/how-to/robot-agent.md).
INSTALLED_TOOL = "/opt/robotconf/bin/robotconf-agent"


def unit_settings(text: str) -> dict[str, str]:
    """`Key=value` lines of a unit file by key (the last one wins, as for these keys)."""
    settings = {}
    for line in text.splitlines():
        if "=" in line and not line.startswith(("#", ";", "[")):
            key, value = line.split("=", 1)
            settings[key.strip()] = value.strip()
    return settings


def test_the_unit_runs_the_example_agent_yaml_as_the_robotconf_user() -> None:
    unit = unit_settings(UNIT.read_text(encoding="utf-8"))
    agent = yaml.safe_load((EXAMPLE / "agent.yaml").read_text(encoding="utf-8"))
    assert INSTALLED_CONFIG in (EXAMPLE / "agent.yaml").read_text(encoding="utf-8")
    assert unit["ExecStart"] == f"{INSTALLED_TOOL} --config {INSTALLED_CONFIG}"
    assert unit["User"] == "robotconf" and unit["Type"] == "simple"
    assert unit["Restart"] == "on-failure"
    # SIGTERM to the agent alone, which stops its brain; systemd must wait for that.
    assert unit["KillMode"] == "mixed"
    assert float(unit["TimeoutStopSec"]) > float(agent["stop_timeout"]) + 5
    # The workdir is writable under ProtectSystem=strict: it is in the state directory.
    assert unit["ProtectSystem"] == "strict" and unit["NoNewPrivileges"] == "yes"
    assert agent["workdir"].startswith(f"/var/lib/{unit['StateDirectory']}/")
    # A ROS 2 brain talks DDS over UDP and lists interfaces over netlink.
    families = unit["RestrictAddressFamilies"].split()
    assert {"AF_INET", "AF_INET6", "AF_NETLINK", "AF_UNIX"} <= set(families)


@pytest.mark.skipif(
    shutil.which("systemd-analyze") is None,
    reason="systemd-analyze is not installed (Debian's systemd package provides it)",
)
def test_systemd_accepts_the_unit_and_finds_it_hardened(tmp_path: Path) -> None:
    # verify checks that ExecStart's program exists: the robot's venv stands in as this one's.
    beside = Path(ROBOTCONF).with_name("robotconf-agent")
    text = UNIT.read_text(encoding="utf-8").replace(INSTALLED_TOOL, str(beside))
    assert str(beside) in text
    unit = tmp_path / UNIT.name
    unit.write_text(text, encoding="utf-8")
    done = subprocess.run(
        ["systemd-analyze", "verify", str(unit)], capture_output=True, text=True, timeout=60
    )
    # An unknown or misspelt key is only a warning (exit 0): no line may name this unit.
    problems = [line for line in done.stderr.splitlines() if unit.name in line]
    assert done.returncode == 0 and problems == [], done.stderr
    # Hardening that is dropped or misspelt raises the exposure: 2.1 now; 4.0 (the threshold
    # counts tenths) allows for a newer systemd counting more. Without any: 9.2.
    security = subprocess.run(
        ["systemd-analyze", "security", "--offline=yes", "--threshold=40", str(unit)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert security.returncode == 0, security.stdout + security.stderr
