"""`robotconf up` as a user runs it: a subprocess, stopped with Ctrl-C (SIGINT)."""

from __future__ import annotations

import contextlib
import re
import signal
import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from agent.config import parse_config
from configurator.mqtt import Connection
from reconciler.desired import load_desired
from reconciler.up import agent_yaml
from tests.support.fleet import GitLab, Proc, robotconf_argv
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for


@contextlib.contextmanager
def port_1883_taken() -> Iterator[bool]:
    """Holds 127.0.0.1:1883 when it can; True when this test is the one holding it."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        try:
            sock.bind(("127.0.0.1", 1883))
            sock.listen(1)
            held = True
        except OSError:
            held = False  # someone else has it: taken all the same
        yield held
    finally:
        sock.close()


def processes_mentioning(text: str) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        with contextlib.suppress(OSError):
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            stat = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
            if text in cmdline and stat != "Z":
                found.append(int(entry.name))
    return found


def start_up(lab: GitLab, tmp_path: Path, *extra: str) -> Proc:
    return Proc(
        robotconf_argv("up", "--repo", str(lab.root), *extra), tmp_path / "up.out", cwd=lab.root
    )


def test_up_runs_the_whole_loop_and_stops_cleanly(lab: GitLab, tmp_path: Path) -> None:
    lab.replace("configs/scenarios/guide-gazebo.yaml", "goal_tolerance: 0.2", "goal_tolerance: 0.3")
    with port_1883_taken() as held:
        up = start_up(lab, tmp_path)
        try:
            wait_for(lambda: "all robots InSync" in up.output(), "up to report InSync")
            out = up.output()
            if held:
                assert "port 1883 is taken" in out
            assert "uncommitted change(s) in configs/ or models/ are NOT applied" in out
            match = re.search(r"embedded amqtt at (mqtt://[\d.]+:\d+)", out)
            assert match, out
            url = match.group(1)

            status = subprocess.run(
                robotconf_argv("status", "--repo", str(lab.root), "--broker", url),
                capture_output=True,
                text=True,
                timeout=60,
            )
            assert status.returncode == 0, status.stdout + status.stderr
            assert len(re.findall(r"^tb3-0\d\s+InSync\s", status.stdout, re.M)) == 5

            # A commit while it runs is rolled out too (the uncommitted edit goes with it).
            head = lab.commit("looser guide")
            wait_for(lambda: f"all robots InSync with {head[:12]}" in up.output(), "the new commit")
            workdir = str(lab.root / ".robotconf" / "up")
            assert len(processes_mentioning(workdir)) >= 10  # five agents, five brains
        finally:
            code = up.stop(signal.SIGINT, timeout=60)
    assert code == 0, up.output()
    assert "stopped" in up.output()
    assert processes_mentioning(workdir) == []
    assert "Traceback" not in up.output()


def test_up_with_an_existing_broker(lab: GitLab, tmp_path: Path, mosquitto: Mosquitto) -> None:
    up = start_up(lab, tmp_path, "--broker", mosquitto.url)
    try:
        wait_for(lambda: "all robots InSync" in up.output(), "up to report InSync")
        watch = FleetWatch(mosquitto.url)
        try:
            status = watch.reconciler()
            assert status is not None and status.last_applied_revision == lab.head()
            assert watch.running(lab.requests()) is not None
        finally:
            watch.close()
    finally:
        code = up.stop(signal.SIGINT, timeout=60)
    assert code == 0, up.output()
    assert "amqtt" not in up.output()


def test_up_refuses_a_folder_that_is_not_a_git_repository(tmp_path: Path) -> None:
    lab = tmp_path / "plain"
    lab.mkdir()
    (lab / "configs").mkdir()
    done = subprocess.run(
        robotconf_argv("up", "--repo", str(lab)), capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 2
    assert "not a git repository" in done.stderr and "git init" in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize("branch", ["nope"])
def test_up_names_a_missing_branch(lab: GitLab, branch: str) -> None:
    done = subprocess.run(
        robotconf_argv("up", "--repo", str(lab.root), "--branch", branch),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert f"branch '{branch}' does not exist" in done.stderr


def test_the_generated_agent_yaml_is_valid_with_credentials_and_tls(
    lab: GitLab, tmp_path: Path
) -> None:
    secrets = {}
    for name in ("password", "ca.crt", "client.crt", "client.key"):
        secrets[name] = tmp_path / name
        secrets[name].write_text("x\n", encoding="utf-8")
    connection = Connection(
        url="mqtts://broker.lab:8883",
        username="lab",
        password_file=secrets["password"],
        ca_file=secrets["ca.crt"],
        cert_file=secrets["client.crt"],
        key_file=secrets["client.key"],
    )
    fleet = lab.requests()

    render = load_desired(lab.root, lab.head()).fleet
    assert render is not None
    settings = agent_yaml(render, "tb3-01", tmp_path / "work", connection, "robotconf")
    config = parse_config(yaml.safe_dump(settings), "agent.yaml", base=tmp_path)
    assert config.robot_id == "tb3-01"
    assert config.description.recommended_template == (
        fleet["tb3-01"].scenario.capability.robot_template
    )
    assert config.connection().address.tls and config.username == "lab"
    assert config.tls is not None and config.tls.ca_file == secrets["ca.crt"]
