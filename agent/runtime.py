"""The agent's own thread: takes events from the inbox, drives the supervisor, runs its effects.

The only place where the state machine, the brain process and the broker link meet; one thread
drives one robot's agent or several (`run_agents`: a simulation host's robots).
"""

from __future__ import annotations

import contextlib
import errno
import gc
import logging
import os
import selectors
import signal
import time
from collections.abc import Iterator, Mapping, Sequence
from contextvars import ContextVar
from types import FrameType

from pydantic import ValidationError

from agent import admission, process
from agent.broker_link import MAX_STATUS_BYTES, BrokerLink
from agent.config import AgentConfig
from agent.events import (
    BrainExited,
    Connected,
    ConnectFailed,
    Disconnected,
    Event,
    Inbox,
    LaunchMessage,
    LogsMessage,
    RestartMessage,
    Shutdown,
    StatusMessage,
)
from agent.interfaces import InterfaceProbe
from agent.logs import LogStream, Redactor
from agent.supervisor import (
    Effect,
    Kill,
    Policy,
    Reload,
    Spawn,
    Supervisor,
    Terminate,
    describe_exit,
)
from agent.workdir import (
    HOLD_FILE,
    ISSUED_FILE,
    LOG_FILE,
    PID_FILE,
    REQUEST_FILE,
    SEQ_FILE,
    STAGED_FILE,
    IssuedStore,
    RestartLedger,
    SeqStore,
    hold_exists,
    remove_hold,
    write_atomic,
)
from contract.interfaces import RobotInterfaces
from contract.launch import LaunchRequest
from contract.safejson import PayloadError, parse_object
from contract.throttle import Throttle
from contract.wire import AgentState, AgentStatus
from contract.wire import now as now_wall

log = logging.getLogger("robotconf.agent")
# The robot whose agent runs right now on this thread: one process may host several, and each
# log line names its robot (`RobotIdFilter`), whichever module logged it.
_acting_for: ContextVar[str | None] = ContextVar("robotconf_agent_robot", default=None)

LOG_CHECK_INTERVAL = 2.0  # seconds between brain log size checks
IDLE_WAKEUP = 60.0  # an upper bound on sleeping, so that no missed wake-up can hang the agent
STOPPING_QUIET = 0.05  # seconds a brain may take to stop before `stopping` is published
REFUSAL_LOG_EVERY = 10.0  # seconds: at most a few lines per this about refused desk requests


def policy_of(config: AgentConfig) -> Policy:
    return Policy(
        restart=config.restart.policy,
        max_restarts=config.restart.max_restarts,
        backoff_initial=config.restart.backoff_initial,
        backoff_max=config.restart.backoff_max,
        reset_after=config.restart.reset_after,
        startsecs=config.startsecs,
        stop_timeout=config.stop_timeout,
        reload_signal=None if config.reload is None else signal.Signals[config.reload.signal],
        max_defer=config.max_defer,
    )


class Agent:
    """One robot's agent; `run()` returns once a signal has stopped the brain and the link."""

    def __init__(self, config: AgentConfig) -> None:
        self.config = config
        self.workdir = config.workdir
        self.description = config.description.to_wire()
        self.inbox = Inbox()
        self.seq = SeqStore(self.workdir / SEQ_FILE)
        self.issued = IssuedStore(self.workdir / ISSUED_FILE)
        self.restarts = RestartLedger(self.workdir)
        self.refusals = Throttle(REFUSAL_LOG_EVERY, limit=5)
        self.hold_file = self.workdir / HOLD_FILE
        self.supervisor = Supervisor(
            config.robot_id, policy_of(config), held=lambda: hold_exists(self.hold_file)
        )
        self._was_deferred = False
        self.brain_log = process.BrainLog(
            self.workdir / LOG_FILE, config.log.max_bytes, config.log.backups
        )
        self.logs = LogStream(
            self.workdir / LOG_FILE,
            config.robot_id,
            redactor_of(config),
            backups=config.log.backups,
        )
        self.link = BrokerLink(
            config.connection(),
            config.prefix,
            config.robot_id,
            config.keepalive,
            self.inbox,
            self.seq,
        )
        self.verify: admission.Verifier | None = None
        if config.public_key is not None:
            from contract.signing import load_public_key, verify_object

            key = load_public_key(config.public_key)
            self.verify = lambda data: verify_object(data, key)
        self.brain: process.Brain | None = None
        self._exit_fds: dict[int, process.Brain] = {}  # exit descriptors watched, until reaped
        self._accepted_payload: tuple[str, bytes] = ("", b"")  # digest, bytes as received
        self._held_until: float | None = None  # when a status held back is published
        # agent.yaml's `env` reaches the brain only (never a log or a status: it may hold
        # secrets); the agent's own ROBOTCONF_* variables, which it refuses to override, last.
        self._brain_env = process.brain_environment(
            {
                **config.env,
                "ROBOTCONF_LAUNCH_REQUEST": str(self.workdir / REQUEST_FILE),
                "ROBOTCONF_ROBOT_ID": config.robot_id,
                "ROBOTCONF_HOLD_FILE": str(self.hold_file),
            }
        )
        self.interfaces: InterfaceProbe | None = None
        if config.interfaces is not None:
            redactor = redactor_of(config)
            self.interfaces = InterfaceProbe(
                config.interfaces,
                self.introspection_env,
                self.workdir,
                redact=lambda text: redactor.fresh().line(text),
            )
        self.connected = False
        self.conn_seq = 0
        self._last_published: AgentStatus | None = None
        self._last_connect_problem: str | None = None
        self._next_log_check = 0.0

    # ------------------------------------------------------------ lifecycle

    def install_signal_handlers(self) -> None:
        install_signal_handlers([self])

    def run(self) -> int:
        """Runs until a signal (or a Shutdown event) has stopped the brain and the link."""
        run_agents([self])
        return 0

    # ------------------------------------------------------------ the loop, in steps
    # `run_agents` drives these: one robot's agent, or a simulation host's several.

    def begin(self) -> None:
        # Before connecting: a request must never start a second brain next to an orphan.
        recovered = process.stop_orphan(self.workdir / PID_FILE, self.config.stop_timeout)
        if recovered:
            log.warning("%s", recovered)
            self.supervisor.message = recovered
        url = self.config.connection().address.url
        log.info("agent for %s connecting to %s", self.config.robot_id, url)
        self.link.start()

    @property
    def finished(self) -> bool:
        return self.supervisor.finished

    def step(self, ready: Mapping[int, int]) -> None:
        """One pass: what became ready (fd -> selector events), then events, deadlines, status."""
        readable = writable = False
        probe_fds = self.interfaces.watches() if self.interfaces is not None else {}
        probe_ready: list[int] = []
        for fd, mask in ready.items():
            if fd == self.inbox.fileno():
                self.inbox.clear_wakeups()
            elif fd in self._exit_fds:
                brain = self._exit_fds.pop(fd)
                self.inbox.put_local(BrainExited(brain.pid, brain.reap()))
            elif fd in probe_fds:
                probe_ready.append(fd)
            else:
                readable = bool(mask & selectors.EVENT_READ)
                writable = bool(mask & selectors.EVENT_WRITE)
        self.link.service(readable, writable, time.monotonic())
        # Everything that arrived together is handled before one status goes out.
        handled = False
        while (event := self.inbox.pop()) is not None:
            self._handle_guarded(event, time.monotonic())
            handled = True
        now = time.monotonic()
        deadline = self.supervisor.deadline
        if deadline is not None and now >= deadline:
            self._apply(self.supervisor.tick(now))
            handled = True
        if self.interfaces is not None and (probe_ready or now >= self.interfaces.due()):
            handled |= self._read_interfaces(probe_ready, now)
        self._maybe_rotate_log(now)
        self._send_logs(now)
        self._tell_deferral()
        report = self._held_until
        if handled or (report is not None and now >= report):
            # The status changes with events and deadlines, nothing else.
            self._publish_if_changed()

    def _tell_deferral(self) -> None:
        """A line in the agent's and the brain's log as a deferral begins and as it ends."""
        deferred = self.supervisor.phase is AgentState.DEFERRED
        if deferred == self._was_deferred:
            return
        self._was_deferred = deferred
        line = self.supervisor.message
        (log.warning if "ran out" in line else log.info)("%s", line)
        self.brain_log.note(line)

    def watches(self) -> dict[int, tuple[int, object]]:
        """fd -> (selector events, identity): the inbox, the broker socket, the brain's exit.

        A closed descriptor's number may come back for a new socket or brain at once: the
        identity (socket generation, brain pid) tells them apart."""
        wanted: dict[int, tuple[int, object]] = {
            self.inbox.fileno(): (selectors.EVENT_READ, "inbox")
        }
        link = self.link.watch()
        if link is not None:
            generation, fd, writing = link
            events = selectors.EVENT_READ | (selectors.EVENT_WRITE if writing else 0)
            wanted[fd] = (events, ("link", generation))
        for fd, exiting in self._exit_fds.items():
            wanted[fd] = (selectors.EVENT_READ, ("brain", exiting.pid))
        if self.interfaces is not None:
            for fd, identity in self.interfaces.watches().items():
                wanted[fd] = (selectors.EVENT_READ, identity)
        return wanted

    def due(self) -> float:
        """The monotonic time by which `step` must run even if nothing becomes ready."""
        if self.inbox:
            return 0.0
        now = time.monotonic()
        due = now + IDLE_WAKEUP
        if self.supervisor.deadline is not None:
            due = min(due, self.supervisor.deadline)
        if self.brain is not None:
            due = min(due, self._next_log_check)
        if self._held_until is not None:
            due = min(due, self._held_until)
        if self.interfaces is not None:
            due = min(due, self.interfaces.due())
        logs = self.logs.due(now)
        if logs is not None and self.connected:
            due = min(due, logs)
        link = self.link.wait_limit(now)
        if link is not None:
            due = min(due, now + link)
        return due

    def end(self) -> None:
        final = self.supervisor.status(self.conn_seq).model_copy(
            update={
                "state": AgentState.OFFLINE,
                "since": now_wall(),
                "message": "agent stopped",
            }
        )
        if self.interfaces is not None:
            self.interfaces.close()
        self.link.close(final if self.connected else None)
        self.inbox.close()
        log.info("agent stopped")

    # ------------------------------------------------------------ events

    def _handle_guarded(self, event: Event, now: float) -> None:
        """One event; a bug in handling it is logged and reported, and the loop goes on: no
        payload may stop the agent (a retained one would stop every restart, too)."""
        try:
            self._handle(event, now)
        except Exception as exc:
            log.exception("internal error while handling %s", type(event).__name__)
            self.supervisor.message = f"internal error ({type(exc).__name__}); see the agent log"

    def _handle(self, event: Event, now: float) -> None:
        sup = self.supervisor
        if isinstance(event, Connected):
            self.connected = True
            self.conn_seq = event.seq
            self._last_connect_problem = None
            log.info("connected (seq %d)", event.seq)
            self.link.publish_description(self.description)
            if self.interfaces is not None and self.interfaces.report is not None:
                self._publish_interfaces(self.interfaces.report)
            self._publish(force=True)
        elif isinstance(event, Disconnected):
            if self.connected:
                log.warning("disconnected from the broker (%s); reconnecting", event.reason)
            self.connected = False
            self.logs.stop()  # followers ask again once they can; nothing waits for the link
        elif isinstance(event, ConnectFailed):
            self.connected = False
            if event.reason != self._last_connect_problem:
                log.warning("%s; retrying with backoff", event.reason)
                self._last_connect_problem = event.reason
        elif isinstance(event, LaunchMessage):
            self._on_launch(event.payload, now)
        elif isinstance(event, StatusMessage):
            self._on_own_status(event.payload)
        elif isinstance(event, RestartMessage):
            self._on_restart(event, now)
        elif isinstance(event, LogsMessage):
            self._on_logs(event.payload, now)
        elif isinstance(event, BrainExited):
            self._on_brain_exit(event, now)
        elif isinstance(event, Shutdown):
            log.info("%s received: stopping", event.signal_name)
            self._apply(sup.shutdown(now))

    def _on_launch(self, payload: bytes, now: float) -> None:
        desired = self.supervisor.desired
        freshness = admission.Freshness(
            self.issued.newest, desired.request.digest if desired is not None else None
        )
        outcome = admission.interpret(payload, self.description, self.verify, freshness)
        sup = self.supervisor
        if isinstance(outcome, admission.Clear):
            log.info("launch request cleared")
            if outcome.issued_at is not None:
                self.issued.accepted(outcome.issued_at)
            self._apply(sup.clear(now))
        elif isinstance(outcome, admission.Reject):
            log.warning("launch request rejected: %s", outcome.reason)
            self.brain_log.note(f"launch request rejected: {outcome.reason}")
            self._apply(sup.reject(outcome.reason, now))
        else:
            warnings = [*outcome.warnings, *self._environment(outcome.request)[1]]
            for warning in warnings:
                log.warning("%s", warning)
            if self.verify is not None:
                self.issued.accepted(outcome.request.issued_at)
            # The brain gets the bytes as published (validated above), not a re-serialisation.
            self._accepted_payload = (outcome.request.digest, payload)
            desired = sup.desired
            if desired is None or desired.request.digest != outcome.request.digest:
                problem = self._stage(payload)
                if problem is not None:
                    log.error("%s", problem)
                    self._apply(sup.reject(problem, now))
                    return
            self._apply(sup.accept(outcome.request, warnings, now))

    def _environment(self, request: LaunchRequest) -> tuple[dict[bytes, bytes], list[str]]:
        """The brain's environment for `request`, and the conflicts it has (warnings)."""
        return process.request_environment(self._brain_env, self.config.env, request)

    def _stage(self, payload: bytes) -> str | None:
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

    def _on_own_status(self, payload: bytes) -> None:
        try:
            seen = AgentStatus.model_validate(parse_object(payload, max_bytes=MAX_STATUS_BYTES))
        except (PayloadError, ValidationError):
            return  # not ours: anything else on this topic is no reason to act
        self.seq.observe(seen.seq)
        if seen.state != AgentState.OFFLINE or not self.connected or self.supervisor.shutting_down:
            return
        # Alive and connected, yet the topic says offline: a Last Will from an older connection
        # (or a previous agent's) arrived after this connection's status. Say again who is live.
        log.warning(
            "overwriting a stale offline status (seq %d; this connection is seq %d)",
            seen.seq,
            self.conn_seq,
        )
        self._publish(force=True)

    def _on_restart(self, event: RestartMessage, now: float) -> None:
        """A restart from the desk: carried out once verified, fresh and addressed here;
        anything else does nothing but a (throttled) line in the agent's and the brain's log."""
        if event.retained:
            self._refused(
                "restart refused: it came retained, and a retained restart would fire at "
                "every reconnect; publish it without the retain flag"
            )
            return
        memory = admission.RestartMemory.of(self.restarts.watermark, self.restarts.ahead)
        wall = now_wall()
        outcome = admission.interpret_restart(
            event.payload, self.config.robot_id, self.verify, memory, wall
        )
        if isinstance(outcome, admission.Reject):
            self._refused(f"restart refused: {outcome.reason}")
            return
        # Remembered before it is carried out: whatever follows, it is not carried out twice.
        done = memory.carried_out(outcome, wall)
        self.restarts.record(done.watermark, done.ahead_entries())
        effects, problem = self.supervisor.restart(outcome.requested_by, outcome.issued_at, now)
        if problem is not None:
            self._refused(f"restart requested by {outcome.requested_by} not carried out: {problem}")
            return
        log.info("restart requested by %s", outcome.requested_by)
        self.brain_log.note(f"restart requested by {outcome.requested_by}")
        self._apply(effects)

    def _on_logs(self, payload: bytes, now: float) -> None:
        request = admission.interpret_logs_request(payload)
        if isinstance(request, admission.Reject):
            self._refused(f"logs request refused: {request.reason}")
            return
        if not self.logs.following and request.follow:
            log.info("streaming the brain's log to the desk while asked")
        refusal = self.logs.ask(request, now)
        if refusal is not None:
            self._refused(f"logs request ignored: {refusal}")

    def _refused(self, line: str) -> None:
        """A desk request that does nothing: said in the agent's log and, for the operator
        (`robotconf logs`), in the brain's; a few times per REFUSAL_LOG_EVERY at most, since
        anyone who may publish on this robot's topics could otherwise fill its disk."""
        said = self.refusals.admit(line, time.monotonic())
        if said is not None:
            log.warning("%s", said)
            self.brain_log.note(said)

    def _send_logs(self, now: float) -> None:
        """The log answers due now; a bug here stops the stream, never the agent."""
        if not self.connected:
            return
        try:
            self.logs.poll(now)
            for chunk in self.logs.take(now):
                self.link.publish_logs(chunk.model_dump_json().encode("utf-8"))
        except Exception:
            log.exception("internal error while sending the brain's log; the stream stops")
            self.logs.stop()

    def _on_brain_exit(self, event: BrainExited, now: float) -> None:
        if self.brain is not None and self.brain.pid == event.pid:
            self.brain = None
            self._remove(PID_FILE)
        how = describe_exit(event.code)
        self.brain_log.note(f"brain pid {event.pid} {how}")
        log.info("brain pid %d %s", event.pid, how)
        self._apply(self.supervisor.exited(event.pid, event.code, now))

    # ------------------------------------------------------------ effects

    def _apply(self, effects: list[Effect]) -> None:
        for effect in effects:
            if isinstance(effect, Spawn):
                self._spawn(effect.request)
            elif isinstance(effect, Terminate):
                log.info("stopping brain pid %d (SIGTERM to its process group)", effect.pid)
                process.signal_group(effect.pid, signal.SIGTERM)
            elif isinstance(effect, Kill):
                log.warning("killing brain pid %d (SIGKILL to its process group)", effect.pid)
                process.signal_group(effect.pid, signal.SIGKILL)
            elif isinstance(effect, Reload):
                self._reload(effect)

    def _install(self, request: LaunchRequest) -> None:
        """Puts `request` in place of the request file, atomically; raises OSError."""
        path = self.workdir / REQUEST_FILE
        digest, payload = self._accepted_payload
        staged = self.workdir / STAGED_FILE
        if digest == request.digest and staged.exists():
            os.replace(staged, path)  # a rename needs no space: staged before the stop
            return
        if digest != request.digest:
            payload = request.payload()
        # Not durable: after a power cut the retained request arrives again.
        write_atomic(path, payload, mode=0o600, durable=False)

    def _reload(self, effect: Reload) -> None:
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
            self._apply(self.supervisor.reload_failed(request, problem, time.monotonic()))
            return
        name = effect.signal.name
        log.info("reloading brain pid %d with %s (%s)", effect.pid, request.digest, name)
        self.brain_log.note(
            f"reloading pid {effect.pid} with {request.digest} ({request.revision}): {name}"
        )
        process.signal_group(effect.pid, effect.signal)
        try:
            process.write_pidfile(self.workdir / PID_FILE, effect.pid, request.digest)
        except OSError as exc:
            log.warning("cannot write the pidfile: %s", exc)

    def _spawn(self, request: LaunchRequest) -> None:
        now = time.monotonic()
        path = self.workdir / REQUEST_FILE
        argv = process.substitute(self.config.command, path)
        problem = remove_hold(self.hold_file)
        if problem is not None:
            log.warning("%s; it defers this brain's stops until it is gone", problem)
        try:
            self._install(request)
            log_fd = self.brain_log.open_for_child()
        except OSError as exc:
            problem = f"cannot write {exc.filename}: {exc.strerror}"
            self._apply(self.supervisor.spawn_failed(problem, now))
            return
        try:
            brain = process.spawn(
                argv,
                cwd=self.workdir,
                log_fd=log_fd,
                env=self._environment(request)[0],
                on_exit=lambda pid, code: self.inbox.put(BrainExited(pid, code)),
            )
        except OSError as exc:
            reason = exc.strerror or str(exc)
            message = f"cannot start {argv[0]!r}: {reason}"
            log.error("%s", message)
            self.brain_log.note(message)
            self._apply(self.supervisor.spawn_failed(message, now))
            return
        finally:
            os.close(log_fd)
        self.brain = brain
        if brain.exit_fd is not None:
            self._exit_fds[brain.exit_fd] = brain
        try:
            process.write_pidfile(self.workdir / PID_FILE, brain.pid, request.digest)
        except OSError as exc:
            log.warning("cannot write the pidfile: %s", exc)
        self.brain_log.note(f"started pid {brain.pid} for {request.digest} ({request.revision})")
        log.info("started brain pid %d for %s", brain.pid, request.digest)
        self._next_log_check = now + LOG_CHECK_INTERVAL
        self._apply(self.supervisor.spawned(brain.pid, now))

    def _maybe_rotate_log(self, now: float) -> None:
        if self.brain is None or now < self._next_log_check:
            return
        self._next_log_check = now + LOG_CHECK_INTERVAL
        if self.brain_log.rotate_if_needed():
            log.info("rotated %s", self.brain_log.path)
            self.logs.rotated()

    # ------------------------------------------------------------ interfaces

    def introspection_env(self) -> dict[bytes, bytes]:
        """The environment the interfaces source runs with, asked for at every reading: the
        brain's for the request it runs (or is to run), so that the request's ROS domain,
        agent.yaml's override of it and its RMW apply; before any request, the agent's own."""
        sup = self.supervisor
        assignment = sup.brain or sup.desired
        if assignment is None:
            return self._brain_env
        return self._environment(assignment.request)[0]

    def _read_interfaces(self, ready: list[int], now: float) -> bool:
        """One look at the interfaces source; True when its error (in the status) changed.
        A bug here is logged and the reading given up: it never stops the agent."""
        probe = self.interfaces
        assert probe is not None
        before = probe.error
        try:
            report = probe.service(ready, now)
        except Exception:
            log.exception("internal error while reading the interfaces; trying again later")
            probe.postpone(now)
            return False
        if report is not None and self.connected:
            self._publish_interfaces(report)
        return probe.error != before

    def _publish_interfaces(self, report: RobotInterfaces) -> None:
        self.link.publish_interfaces(report.model_dump_json(exclude_none=True).encode("utf-8"))

    def _remove(self, name: str) -> None:
        try:
            (self.workdir / name).unlink()
        except FileNotFoundError:
            pass
        except OSError as exc:
            log.warning("cannot remove %s: %s", name, exc)

    # ------------------------------------------------------------ status

    def current_status(self) -> AgentStatus:
        status = self.supervisor.status(self.conn_seq)
        if self.interfaces is not None and self.interfaces.error is not None:
            status.interfaces_error = self.interfaces.error
        return status

    def _publish_if_changed(self) -> None:
        self._publish(force=False)

    def _publish(self, force: bool) -> None:
        if not self.connected:
            self._held_until = None  # the connection's first status is published in full
            return
        status = self.current_status()
        if not force and status == self._last_published:
            return
        delay = 0.0 if force else publish_delay(status, self._last_published)
        if delay > 0:
            now = time.monotonic()
            if self._held_until is None:
                self._held_until = now + delay
            if now < self._held_until:
                return  # `due()` wakes the loop then, should nothing newer come first
        self._held_until = None
        self.link.publish_status(status)
        self._last_published = status


def redactor_of(config: AgentConfig) -> Redactor:
    """What must never leave the robot in a log line: the `env:` values (which may hold
    tokens) and the broker password, wherever it is configured."""
    secrets = list(config.env.values())
    connection = config.connection()
    try:
        password = connection.password()
    except (OSError, ValueError):
        password = None
    if password:
        secrets.append(password)
    return Redactor(secrets, config.env.keys())


def _os_error(exc: OSError) -> str:
    """`[Errno 28] No space left on device` as `ENOSPC: No space left on device`."""
    name = errno.errorcode.get(exc.errno or 0, "error")
    return f"{name}: {exc.strerror or exc}"


def publish_delay(status: AgentStatus, last: AgentStatus | None) -> float:
    """Seconds a changed status may wait before it is published; a newer one replaces it.

    A fresh `stopping` waits STOPPING_QUIET: most brains exit on SIGTERM within milliseconds,
    and then the next state (starting, idle) says all there is to say, without one more
    message per robot through the broker to every reader. Anything else goes at once."""
    fresh_stop = last is None or last.state != AgentState.STOPPING
    return STOPPING_QUIET if status.state == AgentState.STOPPING and fresh_stop else 0.0


class RobotIdFilter(logging.Filter):
    """Gives every log record a `robot_id`: the robot whose agent was running when it was
    logged, else `fallback` (start-up, shutdown of the process)."""

    def __init__(self, fallback: str) -> None:
        super().__init__()
        self.fallback = fallback

    def filter(self, record: logging.LogRecord) -> bool:
        record.robot_id = _acting_for.get() or self.fallback
        return True


@contextlib.contextmanager
def _acting(agent: Agent) -> Iterator[None]:
    token = _acting_for.set(agent.config.robot_id)
    try:
        yield
    finally:
        _acting_for.reset(token)


def install_signal_handlers(agents: Sequence[Agent]) -> None:
    """SIGTERM and SIGINT stop every agent of this process (and so their brains)."""

    def handler(signum: int, frame: FrameType | None) -> None:
        # A deque append and a pipe write per agent: safe wherever the signal lands.
        for agent in agents:
            agent.inbox.put(Shutdown(signal.Signals(signum).name))

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)


def run_agents(agents: Sequence[Agent]) -> None:
    """Drives agents on this thread, all their descriptors in one selector, until each has
    finished. A robot runs one; a simulation host (`robotconf agent --config a.yaml --config
    b.yaml`) runs several robots' agents, each with its own broker connection, Last Will,
    work directory and brain, without a process or a thread each."""
    # What is loaded by now (modules, schemas, the configuration) lives as long as the
    # process: frozen, the cyclic collector stops walking it at every collection, which
    # otherwise costs a large share of the CPU of each restart.
    gc.freeze()
    selector = selectors.DefaultSelector()
    registered: dict[Agent, dict[int, tuple[int, object]]] = {}
    due: dict[Agent, float] = {}
    try:
        for agent in agents:
            with _acting(agent):
                agent.begin()
            registered[agent] = {}
            _sync(selector, agent, registered)
            due[agent] = agent.due()
        while due:
            timeout = max(0.0, min(due.values()) - time.monotonic())
            ready: dict[Agent, dict[int, int]] = {}
            for key, mask in selector.select(timeout):
                ready.setdefault(key.data, {})[key.fd] = mask
            now = time.monotonic()
            for agent in [a for a, when in due.items() if when <= now or a in ready]:
                with _acting(agent):
                    agent.step(ready.get(agent, {}))
                    if agent.finished:
                        _sync(selector, agent, registered, stop=True)
                        del due[agent]
                        agent.end()
                    else:
                        _sync(selector, agent, registered)
                        due[agent] = agent.due()
    finally:
        selector.close()


def _sync(
    selector: selectors.BaseSelector,
    agent: Agent,
    registered: dict[Agent, dict[int, tuple[int, object]]],
    stop: bool = False,
) -> None:
    """Makes the selector watch exactly what the agent wants now (only a step changes that)."""
    wanted = {} if stop else agent.watches()
    have = registered[agent]
    if wanted == have:
        return
    for fd, watch in list(have.items()):
        if wanted.get(fd) != watch:
            # Already gone from the kernel's set if the descriptor was closed.
            with contextlib.suppress(KeyError, ValueError, OSError):
                selector.unregister(fd)
            del have[fd]
    for fd, (events, identity) in wanted.items():
        if fd not in have:
            selector.register(fd, events, agent)
            have[fd] = (events, identity)
