"""End-to-end harness: a real git lab, and real `robotconf reconcile` and `robotconf agent`
processes (their broker is watched with tests/support/watch.py). Nothing asserts timing.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

from robotconf.configurator.rendered import RenderedRequest
from robotconf.contract.mqtt import Connection
from robotconf.reconciler.controller import Controller
from robotconf.reconciler.desired import load_desired
from robotconf.reconciler.source import BranchSource
from tests.support.lab import Lab

ROBOTCONF = Path(sys.executable).parent / "robotconf"


def refused_reconcile(lab: GitLab, url: str, options: list[str]) -> str:
    """`robotconf reconcile` with options it must refuse: its one-line stderr (exit 2, no
    traceback)."""
    done = subprocess.run(
        robotconf_argv(
            "reconcile", "--repo", str(lab.root), "--branch", "main", "--broker", url, *options
        ),
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1
    return done.stderr


def robotconf_argv(*args: str) -> list[str]:
    if ROBOTCONF.exists():
        return [str(ROBOTCONF), *args]
    return [
        sys.executable,
        "-c",
        "import sys; from robotconf.workstation.cli import main; sys.exit(main())",
        *args,
    ]


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

    def keep_robots(self, *robot_ids: str) -> str:
        """fleet.yaml down to `robot_ids` (its other lines as they were), committed."""
        kept = []
        for line in self.read("configs/fleet.yaml").splitlines(keepends=True):
            robot = re.match(r"  ([\w.-]+): \{", line)
            if robot is None or robot.group(1) in robot_ids:
                kept.append(line)
        self.write("configs/fleet.yaml", "".join(kept))
        assert self.robots() == sorted(robot_ids), self.robots()
        return self.commit(f"only {', '.join(robot_ids)}")

    def requests(self, revision: str | None = None) -> dict[str, RenderedRequest]:
        desired = load_desired(self.root, revision or self.head())
        assert desired.fleet is not None, desired.problems
        return desired.fleet.requests

    def robots(self) -> list[str]:
        fleet = yaml.safe_load(self.read("configs/fleet.yaml"))
        return sorted(fleet["robots"])


# Every Proc started and not yet reaped: `kill_leftovers` (an autouse fixture of
# tests/conftest.py) ends those a failed test left running, so none outlives its test.
STARTED: list[Proc] = []


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
        STARTED.append(self)

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


def kill_leftovers(since: int = 0) -> int:
    """Kills every Proc started since the `since`-th (len(STARTED) then) still running, each
    with its whole session; returns how many there were. Those started before (by a fixture
    of a wider scope, set up first) are left to their fixture."""
    alive = [proc for proc in STARTED[since:] if proc.popen.poll() is None]
    for proc in alive:
        proc.kill()
    del STARTED[since:]
    return len(alive)


def start_agent(
    lab: GitLab, robot_id: str, url: str, folder: Path, brain_options: Sequence[str] = ()
) -> Proc:
    """A real agent whose brain is the stand-in brain service (given `brain_options`, such as
    `--hold-while MARKER`)."""
    path = agent_config(robot_id, url, folder, brain_options)
    return Proc(robotconf_argv("agent", "--config", str(path)), path.parent / "agent.log")


def start_agents(robot_ids: Sequence[str], url: str, folder: Path) -> Proc:
    """Real agents for `robot_ids`, all in one process (`--config` repeated, as a simulation
    host runs them): each with its own connection, work folder and stand-in brain, without
    the start-up of a process each. Tests that kill or start one robot use `start_agent`."""
    argv = ["agent"]
    for robot_id in robot_ids:
        argv += ["--config", str(agent_config(robot_id, url, folder))]
    return Proc(robotconf_argv(*argv), folder / "agents.log")


def agent_config(robot_id: str, url: str, folder: Path, brain_options: Sequence[str] = ()) -> Path:
    """The agent.yaml of `robot_id` in `folder/robot_id`, written."""
    work = folder / robot_id
    work.mkdir(parents=True, exist_ok=True)
    config = {
        "broker": url,
        "description": {"id": robot_id, "name": robot_id},
        "command": [
            sys.executable,
            "-m",
            "robotconf.agent.standin_brain",
            "{launch_request}",
            *brain_options,
        ],
        "workdir": str(work),
        "stop_timeout": 5,
        "startsecs": 0.2,
    }
    path = work / "agent.yaml"
    path.write_text(yaml.safe_dump(config), encoding="utf-8")
    return path


def start_reconciler(lab: GitLab, url: str, log: Path, *extra: str) -> Proc:
    return Proc(
        robotconf_argv(
            "reconcile", "--repo", str(lab.root), "--branch", "main", "--broker", url, *extra
        ),
        log,
    )


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


ROBOTS = ["tb3-01", "tb3-02", "tb3-03", "tb3-04", "tb3-05", "tb3-07"]


class Running:
    """A Controller on its own thread, as `robotconf reconcile` runs it."""

    def __init__(
        self, source: BranchSource, url: str, interval: float = 30.0, **options: Any
    ) -> None:
        self.controller = Controller(source, Connection(url), "robotconf", interval, **options)
        self.thread = threading.Thread(target=self.controller.run, daemon=True)
        self.thread.start()

    def stop(self) -> None:
        self.controller.stop()
        self.thread.join(20)
        assert not self.thread.is_alive()
