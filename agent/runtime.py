"""The agent's own thread: takes events from the inbox, drives the supervisor, runs its effects.

The only place where the state machine, the brain process and the broker link meet; one thread
drives one robot's agent or several (`run_agents`: a simulation host's robots). Each event has
one handler (`HANDLERS`); the brain (`BrainRunner`), the desk's requests, the status and the
interfaces report are collaborators of their own.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import selectors
import signal
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextvars import ContextVar
from types import FrameType
from typing import Any, TypeVar

from robotconf.agent import admission, process
from robotconf.agent.brain_runner import BrainRunner
from robotconf.agent.broker_link import BrokerLink
from robotconf.agent.config import AgentConfig
from robotconf.agent.desk_requests import DeskRequests
from robotconf.agent.events import (
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
from robotconf.agent.goals_report import GoalsReport
from robotconf.agent.interfaces_report import InterfacesReport
from robotconf.agent.logs import LogStream, Redactor
from robotconf.agent.status_report import StatusReport
from robotconf.agent.supervisor import Effect, Policy, Supervisor
from robotconf.agent.workdir import (
    HOLD_FILE,
    ISSUED_FILE,
    LOG_FILE,
    PID_FILE,
    SEQ_FILE,
    IssuedStore,
    SeqStore,
    hold_exists,
)

log = logging.getLogger("robotconf.agent")
# The robot whose agent runs right now on this thread: one process may host several, and each
# log line names its robot (`RobotIdFilter`), whichever module logged it.
_acting_for: ContextVar[str | None] = ContextVar("robotconf_agent_robot", default=None)

IDLE_WAKEUP = 60.0  # an upper bound on sleeping, so that no missed wake-up can hang the agent
BUSY_LOOK = 1.0  # seconds between looks at the brain's hold file, for the status's `busy`


def policy_of(config: AgentConfig) -> Policy:
    return Policy(
        restart=config.restart.policy,
        max_restarts=config.restart.max_restarts,
        backoff_initial=config.restart.backoff_initial,
        backoff_max=config.restart.backoff_max,
        reset_after=config.restart.reset_after,
        startsecs=config.startsecs,
        ready_timeout=config.ready_timeout,
        stop_timeout=config.stop_timeout,
        reload_signal=None if config.reload is None else signal.Signals[config.reload.signal],
        max_defer=config.max_defer,
    )


def verifier_of(config: AgentConfig) -> admission.Verifier | None:
    """How signed requests are verified, when agent.yaml names a public key."""
    if config.public_key is None:
        return None
    from robotconf.contract.signing import load_public_key, verify_object

    key = load_public_key(config.public_key)
    return lambda data: verify_object(data, key)


class Agent:
    """One robot's agent; `run()` returns once a signal has stopped the brain and the link."""

    def __init__(self, config: AgentConfig) -> None:
        self.config = config
        self.workdir = workdir = config.workdir
        self.description = config.description.to_wire()
        self.inbox = Inbox()
        self.seq = SeqStore(workdir / SEQ_FILE)
        self.issued = IssuedStore(workdir / ISSUED_FILE)
        self.hold_file = workdir / HOLD_FILE
        self._busy_look = 0.0  # monotonic time of the next look at it (`supervisor.look_busy`)
        # A signed request refused only for being dated ahead of this robot's clock, and the
        # monotonic time to look at it again: time passing, or NTP setting the clock right,
        # admits it without another publish (a retained request is not sent again).
        self._ahead: tuple[bytes, float] | None = None
        self.supervisor = Supervisor(
            config.robot_id, policy_of(config), held=lambda: hold_exists(self.hold_file)
        )
        self.brain_log = process.BrainLog(
            workdir / LOG_FILE, config.log.max_bytes, config.log.backups
        )
        self.logs = LogStream(
            workdir / LOG_FILE, config.robot_id, redactor_of(config), backups=config.log.backups
        )
        self.runner = BrainRunner(
            config, self.supervisor, self.inbox, self.brain_log, self.logs, self.hold_file
        )
        self.link = BrokerLink(
            config.connection(),
            config.prefix,
            config.robot_id,
            config.keepalive,
            self.inbox,
            self.seq,
        )
        self.verify = verifier_of(config)
        self.interfaces = InterfacesReport.of(
            config, self.runner.introspection_env, redactor_of(config), self.link
        )
        self.goals = GoalsReport(config, self.link, self.supervisor)
        self.status = StatusReport(self.link, self.supervisor, self.seq, self._interfaces_error)
        self.desk = DeskRequests(
            config.robot_id,
            workdir,
            self.verify,
            self.supervisor,
            self.logs,
            self.brain_log,
            self.link,
        )
        self._last_connect_problem: str | None = None

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
        self.goals.begin()  # before any brain starts: it finds its socket there
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
        goals_ready: set[int] = set()
        for fd, mask in ready.items():
            if fd == self.inbox.fileno():
                self.inbox.clear_wakeups()
            elif fd in self.runner.exit_fds:
                brain = self.runner.exit_fds.pop(fd)
                self.inbox.put_local(BrainExited(brain.pid, brain.reap()))
            elif fd in probe_fds:
                probe_ready.append(fd)
            elif self.goals.owns(fd):
                goals_ready.add(fd)
            else:
                readable = bool(mask & selectors.EVENT_READ)
                writable = bool(mask & selectors.EVENT_WRITE)
        self.link.service(readable, writable, time.monotonic())
        handled = self._goals_read(goals_ready) if goals_ready else False
        # Everything that arrived together is handled before one status goes out.
        while (event := self.inbox.pop()) is not None:
            self._handle_guarded(event, time.monotonic())
            handled = True
        now = time.monotonic()
        handled |= self._look_ahead_again(now)
        deadline = self.supervisor.deadline
        if deadline is not None and now >= deadline:
            self._apply(self.supervisor.tick(now))
            handled = True
        if self.interfaces is not None and (probe_ready or now >= self.interfaces.due()):
            handled |= self.interfaces.read(probe_ready, now, self.status.connected)
        if now >= self._busy_look:
            self._busy_look = now + BUSY_LOOK
            handled |= self.supervisor.look_busy()
        self.runner.rotate_log_if_due(now)
        if self.status.connected:
            self.desk.send_logs(now)
        self.runner.tell_deferral()
        self._goals_publish(now)
        report = self.status.held_until
        if handled or (report is not None and now >= report):
            # The status changes with events and deadlines, nothing else.
            self.status.publish(force=False)

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
        for fd, exiting in self.runner.exit_fds.items():
            wanted[fd] = (selectors.EVENT_READ, ("brain", exiting.pid))
        if self.interfaces is not None:
            for fd, identity in self.interfaces.watches().items():
                wanted[fd] = (selectors.EVENT_READ, identity)
        for fd, identity in self.goals.watches(time.monotonic()).items():
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
        if self.supervisor.pid is not None and self.supervisor.policy.max_defer > 0:
            due = min(due, self._busy_look)
        log_check = self.runner.log_check_due()
        if log_check is not None:
            due = min(due, log_check)
        if self.status.held_until is not None:
            due = min(due, self.status.held_until)
        if self._ahead is not None:
            due = min(due, self._ahead[1])
        if self.interfaces is not None:
            due = min(due, self.interfaces.due())
        logs = self.logs.due(now)
        if logs is not None and self.status.connected:
            due = min(due, logs)
        link = self.link.wait_limit(now)
        if link is not None:
            due = min(due, now + link)
        goals = self.goals.due(now, self.status.connected)
        if goals is not None:
            due = min(due, goals)
        return due

    def end(self) -> None:
        self._goals_publish(time.monotonic(), final=True)
        self.goals.close()
        final = self.status.final()
        if self.interfaces is not None:
            self.interfaces.close()
        self.link.close(final)
        self.inbox.close()
        log.info("agent stopped")

    # ------------------------------------------------------------ events: one handler each

    def _handle_guarded(self, event: Event, now: float) -> None:
        """One event; a bug in handling it is logged and reported, and the loop goes on: no
        payload may stop the agent (a retained one would stop every restart, too)."""
        try:
            HANDLERS[type(event)](self, event, now)
        except Exception as exc:
            log.exception("internal error while handling %s", type(event).__name__)
            self.supervisor.message = f"internal error ({type(exc).__name__}); see the agent log"

    def _on_connected(self, event: Connected, now: float) -> None:
        self.status.connected = True
        self.status.conn_seq = event.seq
        self._last_connect_problem = None
        log.info("connected (seq %d)", event.seq)
        self.link.publish_description(self.description)
        self.goals.connected()
        if self.interfaces is not None:
            self.interfaces.republish()
        self.status.publish(force=True)

    def _on_disconnected(self, event: Disconnected, now: float) -> None:
        if self.status.connected:
            log.warning("disconnected from the broker (%s); reconnecting", event.reason)
        self.status.connected = False
        self.logs.stop()  # followers ask again once they can; nothing waits for the link

    def _on_connect_failed(self, event: ConnectFailed, now: float) -> None:
        self.status.connected = False
        if event.reason != self._last_connect_problem:
            log.warning("%s; retrying with backoff", event.reason)
            self._last_connect_problem = event.reason

    def _on_status(self, event: StatusMessage, now: float) -> None:
        self.status.seen(event.payload)

    def _on_restart(self, event: RestartMessage, now: float) -> None:
        self._apply(self.desk.restart(event, now))

    def _on_logs(self, event: LogsMessage, now: float) -> None:
        self.desk.ask_logs(event.payload, now)

    def _on_shutdown(self, event: Shutdown, now: float) -> None:
        log.info("%s received: stopping", event.signal_name)
        self._apply(self.supervisor.shutdown(now))

    def _on_launch(self, event: LaunchMessage, now: float) -> None:
        self._ahead = None  # a newer request replaces one that waited for the clock
        self._admit(event.payload, now)

    def _look_ahead_again(self, now: float) -> bool:
        """The request refused as dated ahead, once its time has come: admitted now, or still
        ahead (then looked at again later, without a second rejection said)."""
        if self._ahead is None or now < self._ahead[1]:
            return False
        payload = self._ahead[0]
        self._ahead = None
        self._admit(payload, now, again=True)
        return True

    def _admit(self, payload: bytes, now: float, again: bool = False) -> None:
        desired = self.supervisor.desired
        wall = time.time()
        freshness = admission.Freshness(
            self.issued.newest, desired.request.digest if desired is not None else None, wall
        )
        outcome = admission.interpret(payload, self.description, self.verify, freshness)
        sup = self.supervisor
        wait = admission.look_again_in(outcome, wall)
        if wait is not None:
            self._ahead = (payload, now + wait)
            if again:
                return  # still ahead: said when it came
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
            self._accept(outcome, payload, now)

    def _accept(self, outcome: admission.Accept, payload: bytes, now: float) -> None:
        sup = self.supervisor
        warnings = [*outcome.warnings, *self.runner.environment(outcome.request)[1]]
        for warning in warnings:
            log.warning("%s", warning)
        if self.verify is not None:
            self.issued.accepted(outcome.request.issued_at)
        # The brain gets the bytes as published (validated above), not a re-serialisation.
        self.runner.accepted_payload = (outcome.request.digest, payload)
        desired = sup.desired
        if desired is None or desired.request.digest != outcome.request.digest:
            problem = self.runner.stage(payload)
            if problem is not None:
                log.error("%s", problem)
                self._apply(sup.reject(problem, now))
                return
        self._apply(sup.accept(outcome.request, warnings, now))

    def _on_brain_exit(self, event: BrainExited, now: float) -> None:
        self._apply(self.runner.exited(event, now))

    def _apply(self, effects: list[Effect]) -> None:
        """The supervisor's effects, each carried out with what it answers, in order."""
        for effect in effects:
            self._apply(self.runner.carry_out(effect))

    # ------------------------------------------------------------ the brain's goals
    # Guarded like an event: whatever a brain writes, a bug in relaying it is logged and the
    # loop goes on.

    def _goals_read(self, ready: set[int]) -> bool:
        """Reads the brain's socket; True when its readiness changed the supervisor."""
        try:
            now = time.monotonic()
            signals = self.goals.read(ready, now)
            if not signals:
                return False
            self._apply(self.goals.tell(signals, now))
            return True
        except Exception:
            log.exception("internal error while reading the brain's socket")
            return False

    def _goals_publish(self, now: float, final: bool = False) -> None:
        try:
            self.goals.follow(now)
            self.goals.publish(now, self.status.connected, final)
        except Exception:
            log.exception("internal error while relaying the brain's goals")

    def _interfaces_error(self) -> str | None:
        return self.interfaces.error if self.interfaces is not None else None


# A table entry names an event type and the method that takes it; through `_route`, a method
# that takes another type is a type error.
E = TypeVar("E", bound=Event)
EventHandler = Callable[[Agent, Any, float], None]


def _route(
    kind: type[E], handler: Callable[[Agent, E, float], None]
) -> tuple[type[object], EventHandler]:
    return kind, handler


# Every event the inbox carries, and what handles it; a new event is one handler and one line here
# (tests/unit/agent/test_dispatch.py fails for an event without one).
HANDLERS: dict[type[object], EventHandler] = dict(
    [
        _route(Connected, Agent._on_connected),
        _route(Disconnected, Agent._on_disconnected),
        _route(ConnectFailed, Agent._on_connect_failed),
        _route(LaunchMessage, Agent._on_launch),
        _route(StatusMessage, Agent._on_status),
        _route(RestartMessage, Agent._on_restart),
        _route(LogsMessage, Agent._on_logs),
        _route(BrainExited, Agent._on_brain_exit),
        _route(Shutdown, Agent._on_shutdown),
    ]
)


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
