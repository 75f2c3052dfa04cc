"""The commands' edges: one clear line and exit 2 on trouble, `status --watch` following changes."""

from __future__ import annotations

import fcntl
import json
import os
import pty
import select
import signal
import struct
import subprocess
import termios
import threading
from pathlib import Path

from robotconf.contract.mqtt import Connection
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from robotconf.readmodel.retained import RetainedView
from robotconf.reconciler.controller import Controller
from robotconf.reconciler.source import LocalBranch
from tests.support.fleet import ROBOTS, GitLab, Proc, robotconf_argv
from tests.support.mosquitto import Mosquitto, free_port
from tests.support.watch import FleetWatch, wait_for


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(robotconf_argv(*args), capture_output=True, text=True, timeout=60)


def one_line_error(done: subprocess.CompletedProcess[str]) -> str:
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    return lines[0]


def test_status_without_a_broker_says_so(lab: GitLab) -> None:
    url = f"mqtt://127.0.0.1:{free_port()}"
    line = one_line_error(run("status", "--repo", str(lab.root), "--broker", url, "--wait", "1"))
    assert url in line and "is the broker running?" in line


def test_reconcile_argument_problems(lab: GitLab) -> None:
    line = one_line_error(run("reconcile", "--repo", str(lab.root), "--branch", "mian"))
    assert "branch 'mian' does not exist" in line and "main" in line
    line = one_line_error(
        run("reconcile", "--repo", str(lab.root), "--branch", "main", "--broker", "http://x")
    )
    assert "mqtt://" in line
    line = one_line_error(
        run("reconcile", "--repo", str(lab.root), "--branch", "main", "--interval", "0")
    )
    assert "--interval" in line


def test_reconcile_stops_on_sigterm(lab: GitLab, mosquitto: Mosquitto, tmp_path: Path) -> None:
    proc = Proc(
        robotconf_argv(
            "reconcile", "--repo", str(lab.root), "--branch", "main", "--broker", mosquitto.url
        ),
        tmp_path / "reconciler.log",
    )
    wait_for(lambda: "in sync with" in proc.output(), "the reconciler in sync")
    assert proc.stop(signal.SIGTERM) == 0
    assert "Traceback" not in proc.output()
    # A clean stop sends no Last Will: the reconciler says it is offline itself.
    watch = FleetWatch(mosquitto.url)
    try:
        status = watch.wait_reconciler(lambda s: s.state == "Offline", "offline")
        assert status.last_applied_revision == lab.head() and "stopped" in status.message
    finally:
        watch.close()


def test_status_watch_follows_the_fleet(lab: GitLab, mosquitto: Mosquitto, tmp_path: Path) -> None:
    controller = Controller(
        LocalBranch(lab.root, "main"), Connection(mosquitto.url), "robotconf", 30
    )
    thread = threading.Thread(target=controller.run, daemon=True)
    thread.start()
    watch = FleetWatch(mosquitto.url)
    try:
        watch.wait_reconciler(lambda s: s.ready, "ready")
        proc = Proc(
            robotconf_argv(
                "status", "--repo", str(lab.root), "--broker", mosquitto.url, "--watch", "--json"
            ),
            tmp_path / "watch.out",
        )

        def reports() -> list[dict[str, object]]:
            lines = [line for line in proc.output().splitlines() if line.startswith("{")]
            return [json.loads(line) for line in lines]

        def verdicts() -> dict[str, str] | None:
            found = reports()
            if not found:
                return None
            robots = found[-1]["robots"]
            assert isinstance(robots, list)
            return {r["robot_id"]: r["verdict"] for r in robots}

        assert wait_for(verdicts, "a first report") == dict.fromkeys(ROBOTS, "Offline")
        request = lab.requests()["tb3-01"]
        running = AgentStatus(
            robot_id="tb3-01", state=AgentState.RUNNING, digest=request.digest, pid=1
        )
        publisher = RetainedView(Connection(mosquitto.url), [], "robotconf/sync", role="test-pub")
        publisher.start()
        try:
            assert publisher.wait_synced(30)
            assert publisher.publish_retained(
                [(Topics().status("tb3-01"), running.model_dump_json().encode())], 30
            )
        finally:
            publisher.stop()
        wait_for(lambda: (verdicts() or {}).get("tb3-01") == "InSync", "tb3-01 InSync")
        assert proc.stop(signal.SIGINT) == 1  # the others are still offline
        assert "Traceback" not in proc.output()
    finally:
        watch.close()
        controller.stop()
        thread.join(20)


def test_status_watch_on_a_terminal_is_a_live_screen(lab: GitLab, mosquitto: Mosquitto) -> None:
    """On a terminal the fleet is redrawn in place (rich); elsewhere it is plain text."""
    argv = robotconf_argv("status", "--repo", str(lab.root), "--broker", mosquitto.url, "--watch")
    terminal, screen = pty.openpty()
    # A terminal of 40 rows by 160 columns (a fresh pseudo-terminal has no size).
    fcntl.ioctl(screen, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 160, 0, 0))
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    proc = subprocess.Popen(argv, stdin=screen, stdout=screen, stderr=screen, env=env)
    os.close(screen)
    shown = bytearray()

    def read() -> str:
        while select.select([terminal], [], [], 0.1)[0]:
            try:
                chunk = os.read(terminal, 65536)
            except OSError:  # the process has gone and the terminal is closed
                break
            if not chunk:
                break
            shown.extend(chunk)
        return shown.decode("utf-8", errors="replace")

    try:
        wait_for(lambda: "6 robots: 6 Offline" in read(), "the fleet on the screen")
        text = read()
        assert "\x1b[" in text  # drawn for a terminal: cursor movement, colour
        assert all(robot in text for robot in ROBOTS)
        assert "its agent has never reported" in text
    finally:
        proc.send_signal(signal.SIGINT)
        code = proc.wait(60)
        read()
        os.close(terminal)
    assert code == 1  # the robots are offline
    assert "Traceback" not in shown.decode("utf-8", errors="replace")
