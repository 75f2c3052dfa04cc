"""The stand-in brain: says what it would load, refuses a malformed request, runs until told."""

from __future__ import annotations

import os
import signal
import subprocess
from pathlib import Path

from tests.support.agents import STANDIN, TIMEOUT, make_request


def test_prints_what_it_would_load_and_stops_on_sigterm(tmp_path: Path) -> None:
    request_file = tmp_path / "launch-request.json"
    request_file.write_bytes(make_request().payload())
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    proc = subprocess.Popen(
        [*STANDIN, str(request_file)], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        assert proc.stdout is not None
        lines = [proc.stdout.readline().rstrip("\n") for _ in range(7)]
        assert proc.poll() is None  # still running: it waits for a signal
        proc.send_signal(signal.SIGTERM)
        rest, _ = proc.communicate(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert lines[0].startswith("stand-in brain for tb3-01 (Delivery bot), scenario delivery-gazebo")
    assert lines[1:] == [
        "platform module: ROS2 (mapping scheme gazebo, robot template turtlebot3-camera)",
        "logic modules:",
        "  Follow: follow_with_poses",
        "mappings:",
        "  cmd_vel: topic /cmd_vel (geometry_msgs/msg/Twist)",
        "ROS domain: unset (ROS default, 0)",
    ]
    assert "SIGTERM received, stopping" in rest
    assert proc.returncode == 0


def test_an_action_with_several_logics_names_each(tmp_path: Path) -> None:
    """A multi-logic action arrives as a list (the agent validates it with the same models)."""
    request_file = tmp_path / "launch-request.json"
    logics = ["follow_with_poses", "follow_with_bluetooth"]
    request_file.write_bytes(make_request(logic=logics).payload())
    proc = subprocess.Popen([*STANDIN, str(request_file)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        lines = [proc.stdout.readline().rstrip("\n") for _ in range(4)]
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert lines[2:] == ["logic modules:", "  Follow: follow_with_poses, follow_with_bluetooth"]


def test_malformed_request_exits_non_zero(tmp_path: Path) -> None:
    for content in (b"{not json", b'{"apiVersion": "robotconf/v1"}'):
        request_file = tmp_path / "bad.json"
        request_file.write_bytes(content)
        result = subprocess.run(
            [*STANDIN, str(request_file)], capture_output=True, text=True, timeout=TIMEOUT
        )
        assert result.returncode == 1
        assert "malformed launch request" in result.stderr
        assert "Traceback" not in result.stderr


def test_missing_request_file_exits_non_zero(tmp_path: Path) -> None:
    result = subprocess.run(
        [*STANDIN, str(tmp_path / "nope.json")], capture_output=True, text=True, timeout=TIMEOUT
    )
    assert result.returncode == 2 and "cannot read" in result.stderr


def test_crash_on_demand_for_demos(tmp_path: Path) -> None:
    request_file = tmp_path / "launch-request.json"
    request_file.write_bytes(make_request().payload())
    result = subprocess.run(
        [*STANDIN, "--exit-after", "0", "--exit-code", "7", str(request_file)],
        capture_output=True,
        timeout=TIMEOUT,
    )
    assert result.returncode == 7


def test_sighup_rereads_the_request_and_a_broken_one_keeps_the_old(tmp_path: Path) -> None:
    request_file = tmp_path / "launch-request.json"
    first, second = make_request(), make_request(variant=1, revision="rev-2")
    request_file.write_bytes(first.payload())
    proc = subprocess.Popen([*STANDIN, str(request_file)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        for _ in range(7):  # what it loaded: its handlers are in place by now
            proc.stdout.readline()
        request_file.write_bytes(second.payload())
        proc.send_signal(signal.SIGHUP)
        reloaded = proc.stdout.readline().rstrip("\n")
        request_file.write_bytes(b"{not json")
        proc.send_signal(signal.SIGHUP)
        kept = proc.stdout.readline().rstrip("\n")
        assert proc.poll() is None  # neither reload ended it
        proc.send_signal(signal.SIGTERM)
        rest, _ = proc.communicate(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert reloaded == f"stand-in brain: SIGHUP received, reloaded {second.digest} at rev-2"
    assert kept.startswith(f"stand-in brain: cannot reload {request_file}")
    assert kept.endswith(f"keeping {second.digest}")
    assert "SIGTERM received, stopping" in rest and proc.returncode == 0


def test_hold_for_seconds_ends_by_removing_the_hold_file(tmp_path: Path) -> None:
    request_file = tmp_path / "launch-request.json"
    request_file.write_bytes(make_request().payload())
    hold = tmp_path / "brain.hold"
    env = {**os.environ, "ROBOTCONF_HOLD_FILE": str(hold)}
    proc = subprocess.Popen(
        [*STANDIN, str(request_file), "--hold", "0.5"], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        assert proc.stdout is not None
        lines = iter(proc.stdout.readline, "")
        assert any("busy, holding the agent off" in line for line in lines)
        assert any("done, hold released" in line for line in lines)
        assert not hold.exists()
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0
