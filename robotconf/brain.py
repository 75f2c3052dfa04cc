"""The library a brain imports: its Launch Request as typed data, and what it achieves reported.

    from robotconf import brain

    req = brain.request()              # $ROBOTCONF_LAUNCH_REQUEST, or brain.request(path)
    brain.ready()                      # healthy from now on (as systemd's READY=1)
    for task in req.goals:
        goal = brain.goal(task)
        goal.progress(0.5, eta=12.0, note="halfway")
        goal.succeeded()               # or goal.failed("NAV2_TIMEOUT", "no path"), goal.canceled()
    brain.vitals({"battery": 0.82, "pose": "3.1,4.2"})
    brain.event("warning", "bumper pressed")

Under an agent, reports go as JSON lines (contract/goals.py) to the socket the agent owns,
`$ROBOTCONF_BRAIN_SOCKET`; the brain never holds broker credentials. A report never blocks the
brain: lines wait in a small buffer while the agent is slow or away (a background thread sends
them), and past its size the oldest progress, vitals and events go first. Outside an agent (no
socket) the lines are printed to stderr, or dropped with `ROBOTCONF_BRAIN_REPORT=drop`, so that
a brain's own unit tests need no fleet.

Robot-only: the standard library, pydantic and `contract` (docs/how-to/write-a-brain.md).
"""

from __future__ import annotations

import atexit
import collections
import contextlib
import itertools
import os
import signal
import socket
import sys
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

from pydantic import BaseModel, ValidationError

from robotconf.contract.goals import (
    MAX_LINE_BYTES,
    MAX_TEXT,
    EventLine,
    GoalLine,
    Hello,
    Ready,
    Severity,
    VitalsLine,
)
from robotconf.contract.launch import LaunchRequest
from robotconf.contract.lifecycle import on_stop_signals
from robotconf.contract.textsafe import shorten

__all__ = [
    "Binding",
    "BrainError",
    "Goal",
    "Request",
    "event",
    "goal",
    "ready",
    "request",
    "stop_signal",
    "vitals",
]

REQUEST_ENV = "ROBOTCONF_LAUNCH_REQUEST"
SOCKET_ENV = "ROBOTCONF_BRAIN_SOCKET"
DIGEST_ENV = "ROBOTCONF_DIGEST"
REPORT_ENV = "ROBOTCONF_BRAIN_REPORT"  # without a socket: print (the default) or drop
LIBRARY = "robotconf.brain/1"
MAX_WAITING = 256  # lines kept while the agent is slow or away; then the least needed go
RETRY_EVERY = 1.0  # seconds between attempts to reach the agent's socket
SEND_EVERY = 0.2  # seconds between the sender's looks while lines wait
EXIT_FLUSH = 1.0  # seconds a brain's exit waits, at most, for its last lines to go
_LONGEST = 4 * MAX_TEXT  # the most text a line carries (the agent cuts further)


class BrainError(Exception):
    """The Launch Request cannot be read: the message says which file and what is wrong."""


# ---------------------------------------------------------------- the request, typed


@dataclass(frozen=True)
class Binding:
    """One mapping as bound on this robot: the name the logics use, what it is, and its
    resolved ROS name (in the robot's namespace) and type."""

    name: str
    kind: str  # topic, service or action_client
    resolved: str  # e.g. /tb3_01/cmd_vel
    type: str  # e.g. geometry_msgs/msg/Twist


@dataclass(frozen=True)
class Request:
    """A brain's Launch Request: who it is, what it runs, what it is to achieve."""

    robot_id: str
    robot_name: str
    revision: str
    digest: str
    scenario: str
    environment: str | None
    environment_type: str | None  # e.g. Gazebo or Real
    namespace: str | None
    ros_domain_id: int | None
    platform: str
    robot_template: str | None
    mapping_scheme: str
    tasks: tuple[str, ...]  # tasks the capability's actions achieve
    actions: tuple[str, ...]
    logics: dict[str, tuple[str, ...]]  # action -> the logic modules selected for it
    mappings: dict[str, Binding]  # every mapping as bound, by the name the logics use
    robot_settings: dict[str, Any]
    logic_settings: dict[str, dict[str, Any]]
    knowledge: dict[str, Any]
    goals: tuple[str, ...]  # the scenario's goal tasks, in order
    goal_locations: tuple[dict[str, Any] | None, ...]  # each goal's location, expanded
    launch: LaunchRequest = field(repr=False)  # all of it, as the contract types it

    def settings(self, logic: str | None = None) -> dict[str, Any]:
        """The robot's settings with `logic`'s settings over them (every default filled)."""
        merged = dict(self.robot_settings)
        if logic is not None:
            merged.update(self.logic_settings.get(logic, {}))
        return merged

    @classmethod
    def of(cls, launch: LaunchRequest) -> Request:
        scenario = launch.scenario
        capability = scenario.capability
        return cls(
            robot_id=launch.robot_id,
            robot_name=launch.robot_name,
            revision=launch.revision,
            digest=launch.digest,
            scenario=scenario.name,
            environment=scenario.environment_name,
            environment_type=scenario.environment_type,
            namespace=launch.namespace,
            ros_domain_id=launch.ros_domain_id,
            platform=capability.platform,
            robot_template=capability.robot_template,
            mapping_scheme=capability.mapping_scheme,
            tasks=tuple(capability.tasks),
            actions=tuple(capability.actions),
            logics={
                action: (chosen,) if isinstance(chosen, str) else tuple(chosen)
                for action, chosen in capability.logics.items()
            },
            mappings={
                name: Binding(name, bound.kind, bound.name, bound.type)
                for name, bound in capability.mappings.items()
            },
            robot_settings=dict(scenario.robot_settings),
            logic_settings={k: dict(v) for k, v in scenario.logic_settings.items()},
            knowledge=dict(scenario.environment_knowledge),
            goals=tuple(goal.task for goal in scenario.goals),
            goal_locations=tuple(goal.location for goal in scenario.goals),
            launch=launch,
        )


def read_request(path: Path) -> Request:
    """The Launch Request in `path`; BrainError saying what is wrong."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise BrainError(f"cannot read the launch request {path}: {exc.strerror}") from None
    try:
        return Request.of(LaunchRequest.model_validate_json(raw))
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in error['loc']) or '(top level)'}: {error['msg']}"
            for error in exc.errors()[:5]
        )
        raise BrainError(f"{path} is not a launch request: {problems}") from None


_requests: dict[Path, Request] = {}


def request(path: str | os.PathLike[str] | None = None) -> Request:
    """This brain's Launch Request: the file `path`, else `$ROBOTCONF_LAUNCH_REQUEST` (the
    agent sets it). Read once per file; a reloading brain (SIGHUP) reads it anew with
    `read_request(Path(...))`."""
    where = path if path is not None else os.environ.get(REQUEST_ENV)
    if not where:
        raise BrainError(
            f"no launch request: give its path, or run under an agent (which sets {REQUEST_ENV})"
        )
    key = Path(where)
    if key not in _requests:
        _requests[key] = read_request(key)
    return _requests[key]


# ---------------------------------------------------------------- the wire to the agent


def _line(message: BaseModel) -> bytes:
    return message.model_dump_json(exclude_none=True).encode() + b"\n"


def _droppable(line: bytes) -> bool:
    """Progress, vitals and events may go when the buffer is full; starts, ends, hello and
    ready are kept as long as anything can be."""
    return (
        line.startswith(b'{"v":1,"type":"vitals"')
        or line.startswith(b'{"v":1,"type":"event"')
        or b'"state":"progress"' in line
    )


_READY = b'{"v":1,"type":"ready"'


class Link:
    """The brain's side of the socket: lines queued, sent by a daemon thread, never blocking
    the caller. One per process (`_link()`), or made by tests."""

    def __init__(
        self,
        path: str | None,
        *,
        report: str = "print",
        out: Any = None,
        digest: str | None = None,
    ) -> None:
        self.path = path
        self.report = report
        self.out = out
        self.digest = digest
        self.dropped = 0  # lines that went unsent because the buffer was full
        self._waiting: collections.deque[bytes] = collections.deque()
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._sock: socket.socket | None = None
        self._partial = b""  # the rest of a line the socket took only part of
        self._next_try = 0.0
        self._ready = False
        self._thread: threading.Thread | None = None

    def send(self, line: bytes) -> None:
        if self.path is None:
            self._local(line)
            return
        with self._lock:
            if line.startswith(_READY):
                self._ready = True
            self._waiting.append(line)
            while len(self._waiting) > MAX_WAITING:
                self._drop_one()
            self._flush()
            if self._waiting or self._partial:
                self._start_sender()
                self._wake.notify()

    def drain(self, seconds: float = EXIT_FLUSH) -> None:
        """Sends what waits, for at most `seconds` (at exit: a brain that ends its last goal
        and returns should not lose that end)."""
        deadline = time.monotonic() + seconds
        while self.pending() and time.monotonic() < deadline:
            with self._lock:
                self._next_try = min(self._next_try, time.monotonic())
                self._flush()
            if self.pending():
                time.sleep(0.02)

    def close(self) -> None:
        with self._lock:
            self._flush()
            if self._sock is not None:
                with contextlib.suppress(OSError):
                    self._sock.close()
                self._sock = None

    def _local(self, line: bytes) -> None:
        if self.report == "drop":
            return
        out = self.out or sys.stderr
        with contextlib.suppress(OSError, ValueError):
            out.write(line.decode())
            out.flush()

    def _drop_one(self) -> None:
        for index, line in enumerate(self._waiting):
            if _droppable(line):
                del self._waiting[index]
                break
        else:
            self._waiting.popleft()
        self.dropped += 1

    def _connect(self) -> bool:
        """Under the lock: a connection to the agent, with this process's hello (and ready,
        when it was said) first."""
        if self._sock is not None:
            return True
        now = time.monotonic()
        if now < self._next_try or self.path is None:
            return False
        self._next_try = now + RETRY_EVERY
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.settimeout(0.5)
            sock.connect(self.path)
            sock.setblocking(False)
        except OSError:
            sock.close()
            return False
        self._sock = sock
        hello = _line(Hello(type="hello", pid=os.getpid(), digest=self.digest, library=LIBRARY))
        # A ready said before is said again to this agent, unless one waits to be sent.
        again = self._ready and not any(line.startswith(_READY) for line in self._waiting)
        ready = [_line(Ready(type="ready"))] if again else []
        self._partial = b""
        self._waiting.extendleft(reversed([hello, *ready]))  # before those already waiting
        return True

    def _flush(self) -> None:
        """Under the lock: as much as the socket takes now, without waiting."""
        if not self._connect():
            return
        assert self._sock is not None
        while self._partial or self._waiting:
            if not self._partial:
                self._partial = self._waiting.popleft()
            try:
                sent = self._sock.send(self._partial)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # the agent went away: its next one gets a new hello
                with contextlib.suppress(OSError):
                    self._sock.close()
                self._sock = None
                self._partial = b""  # a line cut in two is not sent again in part
                return
            self._partial = self._partial[sent:]

    def _start_sender(self) -> None:
        if self._thread is None or not self._thread.is_alive():
            self._thread = threading.Thread(
                target=self._sender, name="robotconf.brain", daemon=True
            )
            self._thread.start()

    def _sender(self) -> None:
        with self._lock:
            while self._waiting or self._partial:
                self._wake.wait(SEND_EVERY)
                self._flush()

    def pending(self) -> int:
        with self._lock:
            return len(self._waiting) + bool(self._partial)


_the_link: Link | None = None
_link_lock = threading.Lock()


def _link() -> Link:
    global _the_link
    with _link_lock:
        if _the_link is None:
            _the_link = Link(
                os.environ.get(SOCKET_ENV) or None,
                report=os.environ.get(REPORT_ENV, "print"),
                digest=os.environ.get(DIGEST_ENV) or None,
            )
            atexit.register(_the_link.drain)
        return _the_link


# ---------------------------------------------------------------- what a brain says

_ids = itertools.count(1)


def _cut(text: str | None) -> str | None:
    return None if text is None else shorten(text, _LONGEST)


def _checked(make: Any, **fields: Any) -> bytes:
    """One line, or ValueError saying what is wrong with what the brain passed."""
    try:
        return _line(make(**fields))
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in error['loc']) or 'value'}: {error['msg']}"
            for error in exc.errors()[:3]
        )
        raise ValueError(f"robotconf.brain: {problems}") from None


def stop_signal() -> threading.Event:
    """An Event set once SIGTERM (the agent stopping the brain) or SIGINT (Ctrl-C) arrives:
    wait on it between steps (`stop.wait(0.2)`). Call it once, from the main thread. The
    handler takes no lock: setting an Event in a handler of one's own can hang the brain for
    good, when the signal lands while the main thread is inside its own wait on that Event."""
    stop = threading.Event()
    on_stop_signals(stop, signals=(signal.SIGTERM, signal.SIGINT))
    return stop


def ready() -> None:
    """The brain is up and able to work: under an agent, healthy from now (not from process
    start). A brain that imports this library should say it once it has started."""
    _link().send(_line(Ready(type="ready")))


class Goal:
    """One goal of one task, from its start to one end: succeeded, failed or canceled. As a
    context manager, an exception fails it (code `exception`) and a plain exit succeeds it."""

    def __init__(self, task: str, link: Link) -> None:
        self.id = f"g{next(_ids)}"
        self.task = task
        self.ended: str | None = None
        self._link = link
        link.send(_checked(GoalLine, type="goal", id=self.id, task=task, state="started"))

    def progress(self, fraction: float, eta: float | None = None, note: str | None = None) -> None:
        """How far it is (0..1), optionally the seconds left and a short note."""
        if self.ended is None:
            self._say("progress", fraction=fraction, eta=eta, note=_cut(note))

    def succeeded(self) -> None:
        self._end("succeeded")

    def failed(self, code: str, message: str = "") -> None:
        """It failed: a code (letters, digits, `_.:-`, e.g. NAV2_TIMEOUT or nav2:104) and what
        happened."""
        self._end("failed", code=code, message=_cut(message) or None)

    def canceled(self) -> None:
        self._end("canceled")

    def _end(self, state: str, **more: Any) -> None:
        if self.ended is not None:
            return  # one end per goal: a second is a no-op
        line = _checked(GoalLine, type="goal", id=self.id, task=self.task, state=state, **more)
        self.ended = state
        self._link.send(line)

    def _say(self, state: str, **more: Any) -> None:
        self._link.send(
            _checked(GoalLine, type="goal", id=self.id, task=self.task, state=state, **more)
        )

    def __enter__(self) -> Goal:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        exc: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        if exc is None:
            self.succeeded()
        elif isinstance(exc, KeyboardInterrupt | SystemExit):
            self.canceled()
        else:
            self.failed("exception", f"{type(exc).__name__}: {exc}")


def goal(task: str) -> Goal:
    """A goal of `task` starts now; end it with `succeeded()`, `failed(code, message)` or
    `canceled()` (or use it as a context manager)."""
    return Goal(task, _link())


def vitals(values: Mapping[str, float | int | bool | str]) -> None:
    """A few named numbers or short strings (battery, pose, CPU, topic rates): at most 16 a
    call, names of letters, digits and `_.-`; strings cut to 200 characters."""
    cut = {
        name: value[:MAX_TEXT] if isinstance(value, str) else value
        for name, value in dict(values).items()
    }
    _link().send(_checked(VitalsLine, type="vitals", values=cut))


def event(severity: str, message: str) -> None:
    """Something worth an operator's look: severity info, warning, error or critical."""
    try:
        level = Severity(severity)
    except ValueError:
        raise ValueError(
            f"robotconf.brain: severity {severity!r}: one of info, warning, error, critical"
        ) from None
    _link().send(_checked(EventLine, type="event", severity=level, message=_cut(message)))


def line_fits(line: bytes) -> bool:
    """Every line this library makes fits the agent's bound (a test asks)."""
    return len(line) <= MAX_LINE_BYTES
