"""The desk on `robotconf up`'s fleet out of the box: status, logs and restart with no options,
its broker port kept across a quick restart, a broker that never answers, reload shown."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path

from robotconf.workstation.broker import free_port
from tests.integration.reconciler.test_up import TWO_ROBOTS, in_sync, start_up, up_folder
from tests.support.fleet import GitLab, robotconf_argv
from tests.support.watch import wait_for

TIME_WAIT = "06"  # the state column of /proc/net/tcp


def desk(lab: GitLab, *argv: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """A desk command as a user types it: no broker options, no $ROBOTCONF_BROKER."""
    env = {k: v for k, v in os.environ.items() if k != "ROBOTCONF_BROKER"}
    return subprocess.run(
        robotconf_argv(*argv),
        capture_output=True,
        text=True,
        timeout=90,
        cwd=cwd or lab.root,
        env=env,
    )


@contextlib.contextmanager
def silent_listener() -> Iterator[int]:
    """A port that takes TCP connections (the kernel's backlog) and never speaks MQTT."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.bind(("127.0.0.1", 0))
        sock.listen(64)
        yield int(sock.getsockname()[1])
    finally:
        sock.close()


def time_wait_on(port: int) -> bool:
    """True when a TCP connection whose local port is `port` is in TIME-WAIT."""
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        fields = line.split()
        if int(fields[1].split(":")[1], 16) == port and fields[3] == TIME_WAIT:
            return True
    return False


@TWO_ROBOTS
def test_status_logs_and_restart_need_no_options_even_when_the_port_moved(
    lab: GitLab, tmp_path: Path
) -> None:
    port = free_port("127.0.0.1")
    taken = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    taken.bind(("127.0.0.1", port))
    taken.listen(1)  # really taken: up's broker must move, and the desk must still find it
    try:
        up = start_up(lab, tmp_path, "--port", str(port))
        try:
            in_sync(up, lab)
            out = up.output()
            assert f"(port {port} is taken)" in out, out
            assert (
                "another terminal: robotconf status    robotconf logs ROBOT    "
                "robotconf restart ROBOT" in out
            ), out
            desk_file = lab.root / ".robotconf" / "up" / "desk.json"
            assert oct(desk_file.stat().st_mode & 0o777) == "0o600"
            password = (Path(up_folder(lab)) / "broker" / "operator.password").read_text()
            assert password.strip() not in desk_file.read_text()
            assert json.loads(desk_file.read_text())["broker"] != f"mqtt://127.0.0.1:{port}"

            status = desk(lab, "status")
            assert status.returncode == 0, status.stdout + status.stderr
            assert len(re.findall(r"^tb3-0\d\s+InSync\s", status.stdout, re.M)) == 2
            logs = desk(lab, "logs", "tb3-01", "--lines", "5", cwd=lab.root / "configs")
            assert logs.returncode == 0 and logs.stdout.strip(), logs.stdout + logs.stderr
            # up's agents verify signatures: the restart is signed with up's key, found too.
            restart = desk(lab, "restart", "tb3-02")
            assert restart.returncode == 0, restart.stdout + restart.stderr
            assert "tb3-02: restart requested by operator" in restart.stdout
            assert password.strip() not in status.stdout + logs.stdout + restart.stdout
        finally:
            assert up.stop(signal.SIGINT, timeout=60) == 0, up.output()
    finally:
        taken.close()
    assert not (lab.root / ".robotconf" / "up" / "desk.json").exists()


@TWO_ROBOTS
def test_a_desk_file_whose_up_is_gone_is_not_trusted(lab: GitLab, tmp_path: Path) -> None:
    up = start_up(lab, tmp_path, "--port", str(free_port("127.0.0.1")))
    try:
        in_sync(up, lab)
    finally:
        up.kill()  # no chance to remove its desk file
    assert (lab.root / ".robotconf" / "up" / "desk.json").exists()
    status = desk(lab, "status", "--wait", "1")
    # Whatever answers on 1883 then (nothing, or another broker), not the dead up's broker.
    assert status.returncode != 0
    assert "desk.json is stale: the robotconf up that wrote it" in status.stderr, status.stderr


@TWO_ROBOTS
def test_a_quick_restart_keeps_the_broker_port(lab: GitLab, tmp_path: Path) -> None:
    port = free_port("127.0.0.1")
    first = start_up(lab, tmp_path, "--port", str(port), log="first.out")
    try:
        in_sync(first, lab)
        # A client that never sends its CONNECT: the broker closes it first, so the broker's
        # side of it waits in TIME-WAIT on the port once the broker is gone.
        with socket.create_connection(("127.0.0.1", port)) as client:
            client.settimeout(30)
            assert client.recv(1) == b""
    finally:
        assert first.stop(signal.SIGINT, timeout=60) == 0, first.output()
    assert time_wait_on(port), "no TIME-WAIT connection on the port: the test proves nothing"
    second = start_up(lab, tmp_path, "--port", str(port), log="second.out")
    try:
        in_sync(second, lab)
        out = second.output()
        assert f"embedded amqtt at mqtt://127.0.0.1:{port}," in out, out
        assert "is taken" not in out
    finally:
        assert second.stop(signal.SIGINT, timeout=60) == 0, second.output()


def test_a_given_broker_that_never_answers_is_an_error_with_a_reason(
    lab: GitLab, tmp_path: Path
) -> None:
    with silent_listener() as port:
        url = f"mqtt://127.0.0.1:{port}"
        env = {**os.environ, "ROBOTCONF_BROKER": url}
        up = subprocess.run(
            robotconf_argv("up", "--repo", str(lab.root), "--workdir", str(tmp_path / "work")),
            capture_output=True,
            text=True,
            timeout=90,
            env=env,
        )
        assert up.returncode == 2, up.stdout + up.stderr
        assert f"the broker {url} (given by $ROBOTCONF_BROKER) did not answer" in up.stderr
        assert "never answered MQTT's CONNECT" in up.stderr
        assert "unset ROBOTCONF_BROKER" in up.stderr
        for argv in (
            ["status", "--wait", "1"],
            ["logs", "tb3-01", "--wait", "1"],
            ["restart", "tb3-01", "--wait", "1"],
            ["draft", "tb3-01", "--platform", "ROS2", "--template", "drafted", "--wait", "1"],
        ):
            done = desk(lab, *argv, "--broker", url)
            assert done.returncode == 2, (argv, done.stdout + done.stderr)
            assert "never answered MQTT's CONNECT" in done.stderr, (argv, done.stderr)


def test_a_given_broker_nobody_listens_on_is_said_at_once(lab: GitLab, tmp_path: Path) -> None:
    url = f"mqtt://127.0.0.1:{free_port('127.0.0.1')}"
    env = {**os.environ, "ROBOTCONF_BROKER": url}
    up = subprocess.run(
        robotconf_argv("up", "--repo", str(lab.root), "--workdir", str(tmp_path / "work")),
        capture_output=True,
        text=True,
        timeout=90,
        env=env,
    )
    assert up.returncode == 2, up.stdout + up.stderr
    assert (
        f"the broker {url} (given by $ROBOTCONF_BROKER) cannot be connected to (connection "
        "refused: nothing listens on that port): start it or give another; unset "
        "ROBOTCONF_BROKER" in up.stderr
    ), up.stderr


@TWO_ROBOTS
def test_a_settings_only_commit_reloads_up_s_brains(lab: GitLab, tmp_path: Path) -> None:
    up = start_up(lab, tmp_path, "--port", str(free_port("127.0.0.1")))
    try:
        in_sync(up, lab)
        lab.replace(
            "configs/scenarios/guide-gazebo.yaml", "goal_tolerance: 0.2", "goal_tolerance: 0.3"
        )
        head = lab.commit("looser guide")
        wait_for(lambda: f"all robots InSync with {head[:12]}" in up.output(), "the commit")
        status = desk(lab, "status", "--json")
        robots = json.loads(status.stdout)["robots"]
        changed = [r for r in robots if r["scenario"] == "guide-gazebo"]
        assert changed, robots
        for robot in changed:
            brain_log = lab.root / ".robotconf" / "up" / robot["robot_id"] / "brain.log"
            assert "SIGHUP received, reloaded" in brain_log.read_text(), robot
            assert (robot["reloads"], robot["restarts"]) == (1, 0), robot
    finally:
        assert up.stop(signal.SIGINT, timeout=60) == 0, up.output()
