"""The supervisor's effects carried out on the brain: started, signalled, reloaded, reaped.

Also what the brain is given: its request file (staged before anything is stopped), its
environment, its log (rotated, and told of deferrals). Each effect has one handler (`EFFECTS`);
what the supervisor answers to one (spawned, spawn_failed, reload_failed) is returned.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from robotconf.agent import process
from robotconf.agent.config import AgentConfig
from robotconf.agent.events import BrainExited, Inbox
from robotconf.agent.logs import LogStream
from robotconf.agent.supervisor import (
    Effect,
    Kill,
    Reload,
    Spawn,
    Supervisor,
    Terminate,
    describe_exit,
)
from robotconf.agent.workdir import (
    PID_FILE,
    REQUEST_FILE,
    SOCKET_FILE,
    STAGED_FILE,
    remove_hold,
    write_atomic,
)
from robotconf.contract.launch import LaunchRequest
from robotconf.contract.wire import AgentState

log = logging.getLogger("robotconf.agent")

LOG_CHECK_INTERVAL = 2.0  # seconds between brain log size checks


class BrainRunner:
    """One robot's brain process, as its supervisor asks for it."""

    def __init__(
        self,
        config: AgentConfig,
        supervisor: Supervisor,
        inbox: Inbox,
        brain_log: process.BrainLog,
        logs: LogStream,
        hold_file: Path,
    ) -> None:
        self.config = config
        self.workdir = config.workdir
        self.supervisor = supervisor
        self.inbox = inbox
        self.brain_log = brain_log
        self.logs = logs
        self.hold_file = hold_file
        # agent.yaml's `env` reaches the brain only (never a log or a status: it may hold
        # secrets); the agent's own ROBOTCONF_* variables, which it refuses to override, last.
        # The request's part is added per request (`environment`).
        self.brain_env = process.brain_environment(
            {
                **config.env,
                "ROBOTCONF_LAUNCH_REQUEST": str(self.workdir / REQUEST_FILE),
                "ROBOTCONF_ROBOT_ID": config.robot_id,
                "ROBOTCONF_HOLD_FILE": str(hold_file),
                "ROBOTCONF_BRAIN_SOCKET": str(self.workdir / SOCKET_FILE),
            }
        )
        self.brain: process.Brain | None = None
        self.exit_fds: dict[int, process.Brain] = {}  # exit descriptors watched, until reaped
        self.accepted_payload: tuple[str, bytes] = ("", b"")  # digest, bytes as received
        self._next_log_check = 0.0
        self._was_deferred = False

    # ------------------------------------------------------------ for the loop

    def log_check_due(self) -> float | None:
        return self._next_log_check if self.brain is not None else None

    def rotate_log_if_due(self, now: float) -> None:
        if self.brain is None or now < self._next_log_check:
            return
        self._next_log_check = now + LOG_CHECK_INTERVAL
        if self.brain_log.rotate_if_needed():
            log.info("rotated %s", self.brain_log.path)
            self.logs.rotated()

    def tell_deferral(self) -> None:
        """A line in the agent's and the brain's log as a deferral begins and as it ends."""
        deferred = self.supervisor.phase is AgentState.DEFERRED
        if deferred == self._was_deferred:
            return
        self._was_deferred = deferred
        line = self.supervisor.message
        (log.warning if "ran out" in line else log.info)("%s", line)
        self.brain_log.note(line)

    # ------------------------------------------------------------ what the brain is given

    def environment(self, request: LaunchRequest) -> tuple[dict[bytes, bytes], list[str]]:
        """The brain's environment for `request`, and the conflicts it has (warnings)."""
        return process.request_environment(self.brain_env, self.config.env, request)

    def introspection_env(self) -> dict[bytes, bytes]:
        """The environment the interfaces source runs with, asked for at every reading: the
        brain's for the request it runs (or is to run), so that the request's ROS domain,
        agent.yaml's override of it and its RMW apply; before any request, the agent's own."""
        sup = self.supervisor
        assignment = sup.brain or sup.desired
        if assignment is None:
            return self.brain_env
        return self.environment(assignment.request)[0]

    def stage(self, payload: bytes) -> str | None:
        """Writes the next request beside the current one before anything is stopped: a full
        or read-only disk must leave the running brain running. None when it is written."""
        staged = self.workdir / STAGED_FILE
        try:
            write_atomic(staged, payload, mode=0o600, durable=False)
        except OSError as exc:
            with contextlib.suppress(OSError):
                staged.unlink()
            return (
                f"cannot write the new request to {staged}: {_os_error(exc)}; "
                "the running brain is left as it is"
            )
        return None

    def _install(self, request: LaunchRequest) -> None:
        """Puts `request` in place of the request file, atomically; raises OSError."""
        path = self.workdir / REQUEST_FILE
        digest, payload = self.accepted_payload
        staged = self.workdir / STAGED_FILE
        if digest == request.digest and staged.exists():
            os.replace(staged, path)  # a rename needs no space: staged before the stop
            return
        if digest != request.digest:
            payload = request.payload()
        # Not durable: after a power cut the retained request arrives again.
        write_atomic(path, payload, mode=0o600, durable=False)

    # ------------------------------------------------------------ effects: one handler each

    def carry_out(self, effect: Effect) -> list[Effect]:
        """One effect; what the supervisor answers to it, to be carried out next."""
        return EFFECTS[type(effect)](self, effect)

    def terminate(self, effect: Terminate) -> list[Effect]:
        log.info("stopping brain pid %d (SIGTERM to its process group)", effect.pid)
        process.signal_group(effect.pid, signal.SIGTERM)
        return []

    def kill(self, effect: Kill) -> list[Effect]:
        log.warning("killing brain pid %d (SIGKILL to its process group)", effect.pid)
        process.signal_group(effect.pid, signal.SIGKILL)
        return []

    def reload(self, effect: Reload) -> list[Effect]:
        """The new request over the old one, then the signal: the brain re-reads a whole
        file, never a half-written one, and finds the new one when it is told to look."""
        request = effect.request
        try:
            self._install(request)
        except OSError as exc:
            problem = (
                f"cannot write the new request to {exc.filename or REQUEST_FILE}: "
                f"{_os_error(exc)}; the running brain is left as it is"
            )
            log.error("%s", problem)
            return self.supervisor.reload_failed(request, problem, time.monotonic())
        name = effect.signal.name
        log.info("reloading brain pid %d with %s (%s)", effect.pid, request.digest, name)
        self.brain_log.note(
            f"reloading pid {effect.pid} with {request.digest} ({request.revision}): {name}"
        )
        process.signal_group(effect.pid, effect.signal)
        self._write_pidfile(effect.pid, request)
        return []

    def spawn(self, effect: Spawn) -> list[Effect]:
        request = effect.request
        now = time.monotonic()
        argv = process.substitute(self.config.command, self.workdir / REQUEST_FILE)
        problem = remove_hold(self.hold_file)
        if problem is not None:
            log.warning("%s; it defers this brain's stops until it is gone", problem)
        try:
            self._install(request)
            log_fd = self.brain_log.open_for_child()
        except OSError as exc:
            problem = f"cannot write {exc.filename}: {exc.strerror}"
            return self.supervisor.spawn_failed(problem, now)
        try:
            brain = process.spawn(
                argv,
                cwd=self.workdir,
                log_fd=log_fd,
                env=self.environment(request)[0],
                on_exit=lambda pid, code: self.inbox.put(BrainExited(pid, code)),
            )
        except OSError as exc:
            reason = exc.strerror or str(exc)
            message = f"cannot start {argv[0]!r}: {reason}"
            log.error("%s", message)
            self.brain_log.note(message)
            return self.supervisor.spawn_failed(message, now)
        finally:
            os.close(log_fd)
        self.brain = brain
        if brain.exit_fd is not None:
            self.exit_fds[brain.exit_fd] = brain
        self._write_pidfile(brain.pid, request)
        self.brain_log.note(f"started pid {brain.pid} for {request.digest} ({request.revision})")
        log.info("started brain pid %d for %s", brain.pid, request.digest)
        self._next_log_check = now + LOG_CHECK_INTERVAL
        return self.supervisor.spawned(brain.pid, now)

    def exited(self, event: BrainExited, now: float) -> list[Effect]:
        """A brain was reaped (this one, or one from before a restart of the agent's)."""
        if self.brain is not None and self.brain.pid == event.pid:
            self.brain = None
            self._remove(PID_FILE)
        how = describe_exit(event.code)
        self.brain_log.note(f"brain pid {event.pid} {how}")
        log.info("brain pid %d %s", event.pid, how)
        return self.supervisor.exited(event.pid, event.code, now)

    def _write_pidfile(self, pid: int, request: LaunchRequest) -> None:
        try:
            process.write_pidfile(self.workdir / PID_FILE, pid, request.digest)
        except OSError as exc:
            log.warning("cannot write the pidfile: %s", exc)

    def _remove(self, name: str) -> None:
        try:
            (self.workdir / name).unlink()
        except FileNotFoundError:
            pass
        except OSError as exc:
            log.warning("cannot remove %s: %s", name, exc)


def _os_error(exc: OSError) -> str:
    """`[Errno 28] No space left on device` as `ENOSPC: No space left on device`."""
    name = errno.errorcode.get(exc.errno or 0, "error")
    return f"{name}: {exc.strerror or exc}"


# A table entry names an effect type and the method that takes it; through `_carry`, a method
# that takes another type is a type error.
F = TypeVar("F", bound=Effect)
EffectHandler = Callable[[BrainRunner, Any], list[Effect]]


def _carry(
    kind: type[F], handler: Callable[[BrainRunner, F], list[Effect]]
) -> tuple[type[object], EffectHandler]:
    return kind, handler


# Every effect the supervisor asks for, and what carries it out; a new effect is one method and
# one line here (tests/unit/agent/test_dispatch.py fails for an effect without one).
EFFECTS: dict[type[object], EffectHandler] = dict(
    [
        _carry(Spawn, BrainRunner.spawn),
        _carry(Terminate, BrainRunner.terminate),
        _carry(Kill, BrainRunner.kill),
        _carry(Reload, BrainRunner.reload),
    ]
)
