"""A password in a broker or receiver URL is never echoed, whatever is wrong with the URL,
the broker or the receiver (issue 10, item 10; issue 20, item 3)."""

from __future__ import annotations

import base64
import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support.fleet import GitLab, start_reconciler
from tests.support.lab import ROBOTCONF, Lab
from tests.support.mosquitto import Mosquitto
from tests.support.receivers import Recorder
from tests.support.watch import FleetWatch, wait_for

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


RAW = "pa@ss:w/rd-hunter2"  # a password as its owner knows it
ENCODED = "pa%40ss%3Aw%2Frd-hunter2"  # as a URL must hold it
RECEIVER_URLS = [
    "http://user:pa%ss:hunter2@host:99999x/",  # the password makes the port unparsable
    f"http://user:{RAW}@host/hook",  # unencoded: its / ends the host part early
    "http://user:hunter2#x@host/hook",
    f"http://user:{ENCODED}@host:70000/hook",
    f"http://user:{ENCODED}@[::1/hook",
    f"http://user:{ENCODED}@host/a b",
    f"http://user:{ENCODED}@host/\x1b[2J\nhook",
    f"slack:ftp://user:{ENCODED}@host/hook",
    f"https://user:{ENCODED}@/hook",
]


@pytest.mark.parametrize("url", RECEIVER_URLS)
def test_reconcile_never_echoes_a_receiver_password(url: str, tmp_path: Path) -> None:
    lab = Lab(tmp_path / "lab")
    lab.commit("base")
    out = run(
        "reconcile", "--repo", str(lab.root), "--branch", "main",
        "--broker", "mqtt://127.0.0.1:1", "--notify", "http://ok.example/", "--notify", url,
    )  # fmt: skip
    assert "--notify #2" in out and "hunter2" not in out and "Traceback" not in out
    assert len(out.strip().splitlines()) == 1, out


@pytest.fixture
def recorders() -> Iterator[dict[str, Recorder]]:
    made = {
        "ok": Recorder(),
        "500": Recorder(500),
        "redirect": Recorder(302, f"https://user:{ENCODED}@elsewhere.example/hook"),
    }
    try:
        yield made
    finally:
        for recorder in made.values():
            recorder.close()


def closed_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def test_a_receiver_password_reaches_the_receiver_and_no_log_line(
    tmp_path: Path,
    mosquitto: Mosquitto,
    watch: FleetWatch,
    recorders: dict[str, Recorder],
) -> None:
    """A real reconciler tells receivers whose URLs hold credentials: the one that answers
    gets them as Basic authentication; the ones that fail (500, nobody listening, a
    redirect) are logged by position and host, and the log holds no form of the password."""
    lab = GitLab(tmp_path / "lab")
    urls = [
        f"http://user:{ENCODED}@127.0.0.1:{recorders['ok'].port}/hook",
        f"http://user:{ENCODED}@127.0.0.1:{recorders['500'].port}/hook",
        f"http://user:{ENCODED}@127.0.0.1:{closed_port()}/hook",
        f"slack:http://user:{ENCODED}@127.0.0.1:{recorders['redirect'].port}/hook",
    ]
    options = [option for url in urls for option in ("--notify", url)]
    reconciler = start_reconciler(lab, mosquitto.url, tmp_path / "reconciler.log", *options)
    try:
        good = lab.head()
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == good, "applied")
        fleet = "configs/fleet.yaml"
        lab.write(fleet, lab.read(fleet).replace("robots:", "robots:\n  BAD ID!: {}", 1))
        bad = lab.commit("a robot id the rules refuse")
        posted = wait_for(lambda: recorders["ok"].requests(), "the refusal told")
        assert posted[0].body["revision"] == bad
        wait_for(lambda: reconciler.output().count("not delivered") == 3, "three receivers failing")
    finally:
        assert reconciler.stop() == 0, reconciler.output()[-3000:]
    pair = base64.b64encode(f"user:{RAW}".encode()).decode()
    assert posted[0].headers["authorization"] == f"Basic {pair}"
    assert [r.method for r in recorders["redirect"].requests()] == ["POST"]
    out = reconciler.output()
    assert "a redirect to elsewhere.example: not followed" in out
    assert f"#4 slack:http://127.0.0.1:{recorders['redirect'].port}" in out
    for secret in ("hunter2", pair, "/hook", "Traceback"):
        assert secret not in out
