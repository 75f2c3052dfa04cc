"""Desk commands against a broker that is not there: a refused or closed connection is said at
once, in one line naming the broker and what to do; only a silent listener is waited out."""

from __future__ import annotations

import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support.fleet import robotconf_argv
from tests.support.lab import ROOT
from tests.support.mosquitto import Mosquitto, free_port
from tests.support.tlsutil import make_pki

# Every desk command that connects; each is given a --wait far longer than a test may take,
# so only an answer from the network can end it in time.
DESK_COMMANDS = [
    ["status", "--repo", str(ROOT)],
    ["logs", "tb3-01"],
    ["restart", "tb3-01"],
    ["rollout", "resume"],
    ["rollout", "abort"],
    ["promote", "HEAD", "--to", "prod"],
    ["draft", "tb3-01", "--repo", str(ROOT), "--platform", "ROS2", "--template", "t"],
]


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        robotconf_argv(*args), capture_output=True, text=True, timeout=120, cwd=cwd
    )


def one_line(done: subprocess.CompletedProcess[str]) -> str:
    """The command's only stderr line, after checking that it failed as a tool (exit 2) with no
    traceback."""
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    return lines[0]


@pytest.mark.parametrize("command", DESK_COMMANDS, ids=lambda c: "-".join(c[:2]))
def test_a_stopped_broker_is_said_at_once(
    mosquitto: Mosquitto, tmp_path: Path, command: list[str]
) -> None:
    url = mosquitto.url
    mosquitto.stop()  # the port it had: nothing listens there now
    line = one_line(run(*command, "--broker", url, "--wait", "600", cwd=tmp_path))
    assert f"cannot connect to the broker at {url} (connection refused" in line, line
    assert "`./dev up` or `robotconf up` starts one; --broker URL names another" in line


def test_a_port_nobody_listens_on_is_said_at_once() -> None:
    url = f"mqtt://127.0.0.1:{free_port()}"
    line = one_line(run("status", "--repo", str(ROOT), "--broker", url, "--wait", "600"))
    assert line.startswith(f"robotconf: cannot connect to the broker at {url} ("), line


@pytest.fixture
def tls_broker(tmp_path: Path) -> Iterator[Mosquitto]:
    """A Mosquitto whose one listener speaks TLS only."""
    pki = make_pki(tmp_path / "pki")
    broker = Mosquitto(
        tmp_path / "tls-broker",
        listener_options=[f"certfile {pki.server_cert}", f"keyfile {pki.server_key}"],
    )
    broker.start()
    try:
        yield broker
    finally:
        broker.kill()


def test_a_broker_that_closes_the_connection_is_said_at_once(tls_broker: Mosquitto) -> None:
    """Plain MQTT to a TLS listener: Mosquitto drops the connection without an answer."""
    url = tls_broker.url  # mqtt://, where mqtts:// is spoken
    line = one_line(run("status", "--repo", str(ROOT), "--broker", url, "--wait", "600"))
    assert f"cannot connect to the broker at {url} (" in line, line
    assert "closed the connection" in line or "reset" in line, line
    assert "does it speak what --broker's scheme says" in line, line


def test_tls_to_a_plain_listener_names_the_handshake(mosquitto: Mosquitto) -> None:
    url = mosquitto.url.replace("mqtt://", "mqtts://")
    line = one_line(run("logs", "tb3-01", "--broker", url, "--wait", "600"))
    # Mosquitto resets the connection on a TLS hello, or the handshake fails on its answer.
    assert f"cannot connect to the broker at {url} (" in line, line
    assert "TLS handshake failed" in line or "reset" in line, line
    assert "does it speak what --broker's scheme says" in line, line


def test_a_silent_listener_is_waited_out() -> None:
    """It takes the TCP connection and never answers MQTT's CONNECT: only the wait ends it."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)  # never accepted: the kernel completes the handshake, nobody answers
        url = f"mqtt://127.0.0.1:{silent.getsockname()[1]}"
        line = one_line(run("status", "--repo", str(ROOT), "--broker", url, "--wait", "1"))
    assert f"no answer from the broker at {url} within 1 s" in line, line
    assert "never answered MQTT's CONNECT" in line, line
