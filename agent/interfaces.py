"""The robot's ROS interfaces for `<prefix>/robots/<id>/interfaces`: the source run as a child
process that the agent's loop watches (no thread), its output parsed strictly and bounded.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import shlex
import shutil
import signal
import subprocess
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from robotconf.agent import process
from robotconf.agent.config import InterfacesConfig
from robotconf.contract.clock import now as now_wall
from robotconf.contract.interfaces import (
    MAX_INTERFACE_NAME,
    MAX_INTERFACES,
    MAX_INTERFACES_BYTES,
    Interface,
    RobotInterfaces,
)
from robotconf.contract.safejson import PayloadError, parse_object
from robotconf.contract.textsafe import printable

log = logging.getLogger("robotconf.agent.interfaces")

KINDS = ("topics", "services", "actions")
# `ros2 <verb> list -t` for each kind of the message, as ros2cli's list verbs print them.
ROS2_VERBS = {"topics": "topic", "services": "service", "actions": "action"}
ROS2 = "ros2"
MAX_OUTPUT = 4 * 1024 * 1024  # bytes of one command's stdout: 2,000 interfaces are ~120 KB
MAX_STDERR = 4096  # the tail of stderr kept, for the reason of a failure
MAX_REASON = 300  # characters of a reason in the message and the status
READ_CHUNK = 256 * 1024
REAP_RECHECK = 0.05  # seconds between looks at a child that closed its output but lives on
# What the JSON and the ROS 2 CLI may call an interface: fully qualified names and
# `pkg/msg/Type`-like types, printable and unquoted (JSON needs no escape for them).
_NAME = re.compile(r"/[A-Za-z0-9_/~{}.:-]*")
_TYPE = re.compile(r"[A-Za-z0-9_]+(?:/[A-Za-z0-9_]+)+")
# ros2cli: print(f'{name} [{", ".join(types)}]') for topics, services and actions alike.
_CLI_LINE = re.compile(r"(\S+) \[([^\[\]]*)\]")
# `{"name":"","type":""},` around each entry in the published JSON; the rest of the message
# (keys, source, error, at) is far below this reserve.
_ENTRY_OVERHEAD = 23
_MESSAGE_RESERVE = 8 * 1024

Entries = dict[str, list[tuple[str, str]]]  # kind -> (name, type), as read


class SourceError(ValueError):
    """The source failed or printed something else than interfaces; the one-line reason."""


def _shown(text: str, limit: int = 60) -> str:
    """Quoted and printable (escapes written once: `\\x1b`), cut to `limit` characters."""
    text = printable(text)
    return "'" + (text if len(text) <= limit else text[:limit] + "...") + "'"


# ---------------------------------------------------------------- parsing (pure)


def parse_cli_list(text: str, what: str) -> list[tuple[str, str]]:
    """The (name, type) pairs of `ros2 topic|service|action list -t` output: one line per
    name, `/chatter [std_msgs/msg/String]`, several types comma-separated. Blank lines are
    skipped; any other line is garbage, and the whole output is refused."""
    found: list[tuple[str, str]] = []
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        match = _CLI_LINE.fullmatch(line.strip())
        if match is None:
            raise SourceError(
                f"`{what}` printed {_shown(line)} on line {number}, not NAME [TYPE, ...]"
            )
        types = [t.strip() for t in match[2].split(",")]
        found += [(match[1], t) for t in types if t]
    return found


def parse_command_json(raw: bytes, what: str) -> Entries:
    """The entries of a command's JSON object: `topics`, `services`, `actions` (a missing one
    is empty), each a list of {"name": TEXT, "type": TEXT}; other keys are ignored."""
    try:
        data = parse_object(raw, max_bytes=MAX_OUTPUT)
    except PayloadError as exc:
        raise SourceError(f"`{what}` printed no usable JSON object: {exc}") from None
    entries: Entries = {}
    for kind in KINDS:
        listed = data.get(kind, [])
        if not isinstance(listed, list):
            raise SourceError(f"`{what}` printed {kind} that is not a list")
        pairs: list[tuple[str, str]] = []
        for i, item in enumerate(listed):
            name = item.get("name") if isinstance(item, dict) else None
            kind_type = item.get("type") if isinstance(item, dict) else None
            if not isinstance(name, str) or not isinstance(kind_type, str):
                raise SourceError(
                    f'`{what}` printed {kind}[{i}], which is not {{"name": TEXT, "type": TEXT}}'
                )
            pairs.append((name, kind_type))
        entries[kind] = pairs
    return entries


def check_names(entries: Entries, what: str) -> tuple[Entries, int]:
    """Entries whose name or type is over MAX_INTERFACE_NAME are left out and counted; a name
    or type that is no ROS name or type at all is garbage (SourceError)."""
    kept: Entries = {}
    cut = 0
    for kind in KINDS:
        ok: list[tuple[str, str]] = []
        for name, kind_type in entries.get(kind, []):
            if len(name) > MAX_INTERFACE_NAME or len(kind_type) > MAX_INTERFACE_NAME:
                cut += 1
            elif _NAME.fullmatch(name) is None:
                raise SourceError(f"`{what}` named a {kind[:-1]} {_shown(name)}: not a ROS name")
            elif _TYPE.fullmatch(kind_type) is None:
                raise SourceError(
                    f"`{what}` gave {name} the type {_shown(kind_type)}: not pkg/msg/Type"
                )
            else:
                ok.append((name, kind_type))
        kept[kind] = ok
    return kept, cut


def bound(entries: Entries) -> tuple[Entries, int]:
    """Sorted, without duplicates, and within MAX_INTERFACES entries and MAX_INTERFACES_BYTES
    of JSON: kinds are filled in order (topics, services, actions), and what does not fit is
    left out and counted."""
    budget = MAX_INTERFACES_BYTES - _MESSAGE_RESERVE
    room = MAX_INTERFACES
    kept: Entries = {}
    cut = 0
    for kind in KINDS:
        unique = sorted(set(entries.get(kind, [])))
        taken: list[tuple[str, str]] = []
        for name, kind_type in unique:
            size = len(name) + len(kind_type) + _ENTRY_OVERHEAD
            if room == 0 or size > budget:
                cut += len(unique) - len(taken)
                break
            taken.append((name, kind_type))
            room -= 1
            budget -= size
        kept[kind] = taken
    return kept, cut


def report_of(entries: Entries, truncated: int, source: str, at: float) -> RobotInterfaces:
    def listed(kind: str) -> list[Interface]:
        return [Interface(name=n, type=t) for n, t in entries.get(kind, [])]

    return RobotInterfaces(
        topics=listed("topics"),
        services=listed("services"),
        actions=listed("actions"),
        source=source,
        at=at,
        truncated=truncated,
    )


# ---------------------------------------------------------------- the child process


def one_line(text: str) -> str:
    """The last non-blank line of `text`, printable, cut to MAX_REASON characters."""
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    last = printable(lines[-1]) if lines else ""
    return last if len(last) <= MAX_REASON else last[: MAX_REASON - 3] + "..."


@dataclass
class Child:
    """One run of a source command: its own session (its group is killed on a timeout), stdout
    read up to MAX_OUTPUT, the tail of stderr kept."""

    what: str
    popen: subprocess.Popen[bytes]
    deadline: float
    out: bytearray = field(default_factory=bytearray)
    err: bytearray = field(default_factory=bytearray)
    open_fds: dict[int, str] = field(default_factory=dict)  # fd -> "out" | "err"
    recheck_at: float | None = None

    @classmethod
    def start(
        cls, what: str, argv: Sequence[str], env: Mapping[bytes, bytes], cwd: Path, timeout: float
    ) -> Child:
        """Raises OSError (no such program, not executable)."""
        popen = subprocess.Popen(
            list(argv),
            cwd=cwd,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=env,
            start_new_session=True,
            close_fds=True,
            preexec_fn=process.brain_preexec,  # under `up`: dies with the agent, as a brain
        )
        child = cls(what, popen, time.monotonic() + timeout)
        for stream, name in ((popen.stdout, "out"), (popen.stderr, "err")):
            assert stream is not None
            os.set_blocking(stream.fileno(), False)
            child.open_fds[stream.fileno()] = name
        return child

    def read(self, fd: int) -> None:
        """What `fd` has now; raises SourceError when stdout passes MAX_OUTPUT."""
        name = self.open_fds.get(fd)
        if name is None:
            return
        while True:
            try:
                chunk = os.read(fd, READ_CHUNK)
            except BlockingIOError:
                return
            except OSError:
                chunk = b""
            if not chunk:
                del self.open_fds[fd]
                return
            if name == "err":
                self.err = (self.err + chunk)[-MAX_STDERR:]
            else:
                self.out += chunk
                if len(self.out) > MAX_OUTPUT:
                    raise SourceError(f"`{self.what}` printed more than {MAX_OUTPUT:,} bytes")

    def finished(self, now: float) -> int | None:
        """The exit code once the output is closed and the process has exited; None before.
        A process that closed its output but lives on is looked at again soon (`recheck_at`).
        What the source left behind in its group (a daemon it forked, its output elsewhere)
        is killed with it: a reading never leaves a process, success or not."""
        if self.open_fds:
            return None
        if not self._exited():
            self.recheck_at = now + REAP_RECHECK
            return None
        self.recheck_at = None
        # The leader is a zombie until polled: its pid, and so its group's id, is still ours.
        process.signal_group(self.popen.pid, signal.SIGKILL)
        return self.popen.wait()

    def _exited(self) -> bool:
        """Whether the leader has exited, looked at without reaping it (WNOWAIT)."""
        if self.popen.returncode is not None:
            return True
        try:
            found = os.waitid(os.P_PID, self.popen.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
        except ChildProcessError:
            return True  # reaped elsewhere: `wait` gives its code
        return found is not None

    def kill(self) -> None:
        """The whole session's group, then the leader reaped (bounded: a process stuck in the
        kernel is left to `poll()` later)."""
        process.signal_group(self.popen.pid, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.popen.wait(timeout=2)
        self.close()

    def close(self) -> None:
        for stream in (self.popen.stdout, self.popen.stderr):
            if stream is not None:
                with contextlib.suppress(OSError):
                    stream.close()
        self.open_fds.clear()


def exit_reason(what: str, code: int, err: bytes) -> str:
    how = f"was killed by {_signal_name(-code)}" if code < 0 else f"exited with code {code}"
    said = one_line(err.decode("utf-8", errors="replace"))
    return f"`{what}` {how}" + (f": {said}" if said else "")


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"


# ---------------------------------------------------------------- the probe


@dataclass(frozen=True)
class Step:
    """One command of a reading: the kind it lists (None: the command's JSON gives all)."""

    kind: str | None
    argv: tuple[str, ...]
    what: str


class InterfaceProbe:
    """Reads the interfaces every `interval` seconds (from the end of one reading to the start
    of the next: readings never overlap), one child at a time, driven by the agent's loop:
    `watches()` and `due()` say what to wait for, `service()` does the work and returns a
    report whose content changed (never `at` alone), else None.

    A failed reading keeps the last good lists (and their `at`) with `error` set: a robot whose
    tooling broke is not reported as having lost its interfaces."""

    def __init__(
        self,
        config: InterfacesConfig,
        env: Callable[[], Mapping[bytes, bytes]],
        cwd: Path,
        redact: Callable[[str], str] = lambda text: text,
    ) -> None:
        self.config = config
        self.env = env
        self.cwd = cwd
        self.redact = redact
        self.source = ROS2 if config.command is None else redact(shlex.join(config.command))
        self.source = self.source[:MAX_INTERFACE_NAME]
        self.report: RobotInterfaces | None = None
        self.error: str | None = None
        self._good: tuple[Entries, int, float] | None = None  # last good entries, cut, at
        self._content: object = None  # what the last report said, `at` aside
        self._steps: list[Step] = []
        self._read: Entries = {}
        self._cut = 0
        self._child: Child | None = None
        self._env: Mapping[bytes, bytes] = {}
        self._next_at = time.monotonic()

    # ------------------------------------------------------------ for the loop

    def watches(self) -> dict[int, object]:
        """fd -> identity (the child's pid and stream): the output pipes of the running child."""
        child = self._child
        if child is None:
            return {}
        return {fd: ("interfaces", child.popen.pid, name) for fd, name in child.open_fds.items()}

    def due(self) -> float:
        child = self._child
        if child is None:
            return self._next_at
        if child.recheck_at is not None:
            return min(child.deadline, child.recheck_at)
        return child.deadline

    def service(self, ready: Iterable[int], now: float) -> RobotInterfaces | None:
        """Reads what is ready, finishes or times out the child, starts the next step or
        reading; a report when the content changed."""
        try:
            return self._service(ready, now)
        except SourceError as exc:
            return self._failed(str(exc), now)

    def close(self) -> None:
        if self._child is not None:
            self._child.kill()
            self._child = None

    def postpone(self, now: float) -> None:
        """After an internal error: this reading is given up, the next one an interval on."""
        self.close()
        self._steps, self._read = [], {}
        self._next_at = now + self.config.interval

    # ------------------------------------------------------------ a reading, step by step

    def _service(self, ready: Iterable[int], now: float) -> RobotInterfaces | None:
        child = self._child
        if child is None:
            if now < self._next_at:
                return None
            self._begin()
            return self._next_step(now)
        for fd in ready:
            child.read(fd)
        code = child.finished(now)
        if code is None:
            if now >= child.deadline:
                child.kill()
                self._child = None
                raise SourceError(f"`{child.what}` did not finish in {self.config.timeout:g} s")
            return None
        child.close()
        self._child = None
        if code != 0:
            raise SourceError(exit_reason(child.what, code, bytes(child.err)))
        self._take(self._steps.pop(0), bytes(child.out))
        return self._next_step(now)

    def _begin(self) -> None:
        self._read, self._cut = {}, 0
        self._env = self.env()  # once per reading: the brain's environment may have changed
        command = self.config.command
        if command is not None:
            self._steps = [Step(None, tuple(command), self.source)]
            return
        ros2 = shutil.which(ROS2, path=os.fsdecode(self._env.get(b"PATH", b"")))
        if ros2 is None:
            raise SourceError(
                "no `ros2` on the brain's PATH: run the agent with ROS 2's environment "
                "(or set PATH in agent.yaml's env), or give interfaces.command"
            )
        self._steps = [
            Step(kind, (ros2, verb, "list", "-t"), f"ros2 {verb} list -t")
            for kind, verb in ROS2_VERBS.items()
        ]

    def _next_step(self, now: float) -> RobotInterfaces | None:
        if not self._steps:
            return self._succeeded(now)
        step = self._steps[0]
        try:
            self._child = Child.start(
                step.what, step.argv, self._env, self.cwd, self.config.timeout
            )
        except OSError as exc:
            raise SourceError(f"cannot start {step.argv[0]!r}: {exc.strerror or exc}") from None
        return None

    def _take(self, step: Step, out: bytes) -> None:
        if step.kind is None:
            entries = parse_command_json(out, step.what)
        else:
            try:
                text = out.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise SourceError(f"`{step.what}` printed no UTF-8 (byte {exc.start})") from None
            entries = {step.kind: parse_cli_list(text, step.what)}
        checked, cut = check_names(entries, step.what)
        for kind, pairs in checked.items():
            self._read.setdefault(kind, []).extend(pairs)
        self._cut += cut

    # ------------------------------------------------------------ outcomes

    def _succeeded(self, now: float) -> RobotInterfaces | None:
        self._next_at = now + self.config.interval
        entries, cut = bound(self._read)
        cut += self._cut
        self._read = {}
        self.error = None
        content = (entries, cut, None)
        if content == self._content:
            return None
        self._content = content
        self._good = (entries, cut, now_wall())
        self.report = report_of(entries, cut, self.source, self._good[2])
        return self.report

    def _failed(self, reason: str, now: float) -> RobotInterfaces | None:
        self._next_at = now + self.config.interval
        self._steps, self._read = [], {}
        if self._child is not None:
            self._child.kill()
            self._child = None
        reason = self.redact(reason)
        if reason != self.error:
            log.warning("interfaces not read: %s", reason)
        self.error = reason
        entries, cut, at = self._good if self._good is not None else ({}, 0, None)
        content = (entries, cut, reason)
        if content == self._content:
            return None
        self._content = content
        report = report_of(entries, cut, self.source, at or now_wall())
        self.report = report.model_copy(update={"at": at, "error": reason})
        return self.report
