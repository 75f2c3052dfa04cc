"""End-to-end harness: a real git lab, real `robotconf reconcile` and `robotconf agent` processes,
and an observer of every retained topic. Tests wait for conditions; nothing asserts timing.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import paho.mqtt.client as paho
import yaml
from pydantic import ValidationError

from configurator.launch import LaunchRequest
from configurator.mqtt import Connection
from configurator.safejson import PayloadError
from configurator.wire import AgentState, AgentStatus, ReconcilerStatus, Topics
from reconciler.desired import load_desired
from reconciler.retained import RetainedView, read_object
from tests.support.lab import Lab

TIMEOUT = 60.0  # generous: CI machines are slow and shared
ROBOTCONF = Path(sys.executable).parent / "robotconf"
T = TypeVar("T")


def robotconf_argv(*args: str) -> list[str]:
    if ROBOTCONF.exists():
        return [str(ROBOTCONF), *args]
    return [
        sys.executable,
        "-c",
        "import sys; from configurator.cli import main; sys.exit(main())",
        *args,
    ]


def wait_for(probe: Callable[[], T | None], what: str, timeout: float = TIMEOUT) -> T:
    """Polls until `probe` returns something truthy, and returns it."""
    deadline = time.monotonic() + timeout
    while True:
        found = probe()
        if found:
            return found
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.05)


class GitLab(Lab):
    """The example lab in a fresh git repository (branch main), committed."""

    def __init__(self, root: Path) -> None:
        super().__init__(root)
        self.first = self.commit("lab")

    def commit(self, message: str) -> str:
        if not (self.root / ".git").exists():
            self.git("init", "-q", "-b", "main")
            self.git("config", "user.email", "lab@example.org")
            self.git("config", "user.name", "Lab")
            self.git("config", "commit.gpgsign", "false")
        self.git("add", "configs", "models")
        self.git("commit", "-q", "--allow-empty", "-m", message)
        return self.git("rev-parse", "HEAD")

    def head(self) -> str:
        return self.git("rev-parse", "HEAD")

    def requests(self, revision: str | None = None) -> dict[str, LaunchRequest]:
        desired = load_desired(self.root, revision or self.head())
        assert desired.fleet is not None, desired.problems
        return desired.fleet.requests

    def robots(self) -> list[str]:
        fleet = yaml.safe_load(self.read("configs/fleet.yaml"))
        return sorted(fleet["robots"])


class Proc:
    """A background process with its output in a log file."""

    def __init__(self, argv: list[str], log: Path, cwd: Path | None = None) -> None:
        self.log = log
        self.argv = argv
        with log.open("ab") as out:
            self.popen = subprocess.Popen(
                argv,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                cwd=cwd,
                start_new_session=True,
            )

    @property
    def pid(self) -> int:
        return self.popen.pid

    def alive(self) -> bool:
        return self.popen.poll() is None

    def output(self) -> str:
        return self.log.read_text(encoding="utf-8", errors="replace")

    def stop(self, sig: signal.Signals = signal.SIGTERM, timeout: float = 20.0) -> int:
        if self.popen.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                self.popen.send_signal(sig)
            try:
                return self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.kill()
        return self.popen.wait()

    def kill(self) -> None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.popen.pid, signal.SIGKILL)
        self.popen.wait()


def start_agent(lab: GitLab, robot_id: str, url: str, folder: Path) -> Proc:
    """A real agent whose brain is the stand-in brain service."""
    work = folder / robot_id
    work.mkdir(parents=True, exist_ok=True)
    config = {
        "broker": url,
        "description": {"id": robot_id, "name": robot_id},
        "command": [sys.executable, "-m", "agent.standin_brain", "{launch_request}"],
        "workdir": str(work),
        "stop_timeout": 5,
        "startsecs": 0.2,
    }
    path = work / "agent.yaml"
    path.write_text(yaml.safe_dump(config), encoding="utf-8")
    return Proc(robotconf_argv("agent", "--config", str(path)), work / "agent.log")


def start_reconciler(lab: GitLab, url: str, log: Path, *extra: str) -> Proc:
    return Proc(
        robotconf_argv(
            "reconcile", "--repo", str(lab.root), "--branch", "main", "--broker", url, *extra
        ),
        log,
    )


class Watch:
    """Every retained robot and reconciler topic, plus a log of live (non-retained) launches."""

    def __init__(self, url: str | Connection, prefix: str = "robotconf") -> None:
        self.topics = Topics(prefix)
        self.view = RetainedView(
            url if isinstance(url, Connection) else Connection(url),
            [
                self.topics.all_launch,
                self.topics.all_status,
                self.topics.all_description,
                self.topics.reconciler_status,
            ],
            f"{prefix}/sync",
            role="test",
        )
        self.live_launches: list[tuple[str, bytes]] = []
        self._lock = threading.Lock()
        # Count what the reconciler publishes while we watch: a second paho handler on the
        # same client sees each message once, with its retain flag.
        client: paho.Client = self.view._client
        client.message_callback_add(self.topics.all_launch, self._on_launch)
        self.view.start()
        assert self.view.wait_synced(TIMEOUT), "the test observer could not reach the broker"

    def _on_launch(self, client: paho.Client, userdata: Any, message: paho.MQTTMessage) -> None:
        if not message.retain:
            with self._lock:
                self.live_launches.append((message.topic, bytes(message.payload)))
        self.view._handle_message(client, userdata, message)

    def close(self) -> None:
        self.view.stop()

    def retained(self) -> dict[str, bytes]:
        return self.view.snapshot()

    def launch(self, robot_id: str) -> dict[str, Any] | None:
        payload = self.retained().get(self.topics.launch(robot_id))
        return json.loads(payload) if payload else None

    def status(self, robot_id: str) -> AgentStatus | None:
        payload = self.retained().get(self.topics.status(robot_id))
        return AgentStatus.model_validate_json(payload) if payload else None

    def reconciler(self) -> ReconcilerStatus | None:
        """The retained reconciler status; None when there is none or it is unreadable."""
        payload = self.retained().get(self.topics.reconciler_status)
        if not payload:
            return None
        try:
            return ReconcilerStatus.model_validate(read_object(payload))
        except (PayloadError, ValidationError):
            return None

    def digest(self, robot_id: str) -> str | None:
        """The digest retained on a robot's launch topic; "unreadable", or None for nothing."""
        payload = self.retained().get(self.topics.launch(robot_id))
        if not payload:
            return None
        try:
            digest = read_object(payload).get("digest")
        except PayloadError:
            return "unreadable"
        return digest if isinstance(digest, str) else "unreadable"

    def running(self, requests: dict[str, LaunchRequest]) -> dict[str, AgentStatus] | None:
        """Every robot's status when each one runs its request's digest, else None."""
        found = {}
        for robot_id, request in requests.items():
            status = self.status(robot_id)
            if status is None or status.state is not AgentState.RUNNING:
                return None
            if status.digest != request.digest or status.pid is None:
                return None
            found[robot_id] = status
        return found

    def wait_running(self, requests: dict[str, LaunchRequest]) -> dict[str, AgentStatus]:
        return wait_for(lambda: self.running(requests), f"{sorted(requests)} running")

    def wait_reconciler(
        self, predicate: Callable[[ReconcilerStatus], bool], what: str
    ) -> ReconcilerStatus:
        def probe() -> ReconcilerStatus | None:
            status = self.reconciler()
            return status if status is not None and predicate(status) else None

        return wait_for(probe, f"reconciler status: {what}")


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    with contextlib.suppress(OSError):
        # A zombie is dead for our purpose.
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        return state != "Z"
    return True
