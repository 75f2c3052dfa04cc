"""The brain's state machine (docs/architecture.md#the-agents-states) as pure logic: events in,
effects and a status out.

No processes, no MQTT, no clock of its own: times are passed in, so every rule is unit-tested.
"""

from __future__ import annotations

import enum
import logging
import signal
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Literal

from robotconf.contract.backoff import exponential_delay
from robotconf.contract.launch import LaunchRequest
from robotconf.contract.wire import AgentState, AgentStatus

log = logging.getLogger("robotconf.agent.supervisor")

# ---------------------------------------------------------------- effects for the runtime


@dataclass(frozen=True)
class Spawn:
    """Write the request and start the brain; answer with `spawned` or `spawn_failed`."""

    request: LaunchRequest


@dataclass(frozen=True)
class Terminate:
    pid: int


@dataclass(frozen=True)
class Kill:
    pid: int


@dataclass(frozen=True)
class Reload:
    """Write the request over the running brain's and send `signal` to its process group;
    answer `reload_failed` when the request cannot be written."""

    pid: int
    signal: signal.Signals
    request: LaunchRequest


Effect = Spawn | Terminate | Kill | Reload
Restart = Literal["on-failure", "always", "never"]


@dataclass(frozen=True)
class Policy:
    restart: Restart = "on-failure"
    max_restarts: int = 5
    backoff_initial: float = 1.0
    backoff_max: float = 60.0
    reset_after: float = 60.0
    startsecs: float = 1.0
    ready_timeout: float = 120.0  # after a hello, seconds to say ready; 0: no limit
    stop_timeout: float = 10.0
    reload_signal: signal.Signals | None = None  # None: every new request restarts
    max_defer: float = 0.0  # seconds the hold file may defer a stop; 0: never deferred
    hold_poll: float = 0.25  # seconds between looks at the hold file while deferred

    def backoff(self, streak: int) -> float:
        """Delay before restart number `streak + 1` of a run of failures."""
        return exponential_delay(streak, self.backoff_initial, self.backoff_max)


# ---------------------------------------------------------------- the phases and their changes

_S = AgentState
# Every legal change of phase (docs/architecture.md#the-agents-states): what may follow what.
# Staying in a phase (a new message, a new pid) is no change and always legal; `rejected` and
# `offline` are never a phase (a rejection is shown over the phase; offline is the agent's).
TRANSITIONS: Mapping[AgentState, frozenset[AgentState]] = {
    _S.IDLE: frozenset({_S.STARTING}),
    # A brain that stays up, is stopped, defers, ends (per EXIT_RULES) or is unassigned before
    # its process started.
    _S.STARTING: frozenset(
        {_S.RUNNING, _S.STOPPING, _S.DEFERRED, _S.BACKOFF, _S.FAILED, _S.EXITED, _S.IDLE}
    ),
    # As starting; and starting again when it says hello after startsecs.
    _S.RUNNING: frozenset(
        {_S.STARTING, _S.STOPPING, _S.DEFERRED, _S.BACKOFF, _S.FAILED, _S.EXITED}
    ),
    # The exit: the next request starts, or none is assigned; one stopped for never saying
    # ready failed to start.
    _S.STOPPING: frozenset({_S.IDLE, _S.STARTING, _S.BACKOFF, _S.FAILED}),
    # What waited goes ahead (a stop, a reload), or nothing waits any more and it resumes.
    _S.DEFERRED: frozenset({_S.STOPPING, _S.RUNNING, _S.STARTING}),
    _S.BACKOFF: frozenset({_S.STARTING, _S.IDLE}),
    _S.EXITED: frozenset({_S.STARTING, _S.IDLE}),
    _S.FAILED: frozenset({_S.STARTING, _S.IDLE}),
}


def legal(before: AgentState, after: AgentState) -> bool:
    """Whether the supervisor's phase may change from `before` to `after`."""
    return before == after or after in TRANSITIONS.get(before, frozenset())


# ---------------------------------------------------------------- how a brain ended


class Ending(enum.Enum):
    """Why a brain is no longer up, as the restart policy sees it."""

    CRASHED = "crashed"  # exited non-zero, or killed by a signal
    CLEAN = "clean"  # exited with 0
    UNREADY = "unready"  # said hello, not ready within ready_timeout: stopped
    SPAWN_FAILED = "spawn-failed"  # could not even be started (missing executable, full disk)


@dataclass(frozen=True)
class EndingRule:
    """Retry or terminal, as data: the restart policies under which an ending is retried (in
    backoff, up to max_restarts), and the phase it ends in when it is not."""

    retried_under: frozenset[Restart]
    terminal: AgentState


_ON_FAILURE: frozenset[Restart] = frozenset({"on-failure", "always"})
ENDING_RULES: Mapping[Ending, EndingRule] = {
    Ending.CRASHED: EndingRule(_ON_FAILURE, AgentState.FAILED),
    Ending.UNREADY: EndingRule(_ON_FAILURE, AgentState.FAILED),  # a failed start
    Ending.CLEAN: EndingRule(frozenset({"always"}), AgentState.EXITED),
    # Nothing ran: a retry would fail the same way until a new request or a restart.
    Ending.SPAWN_FAILED: EndingRule(frozenset(), AgentState.FAILED),
}


def retried(ending: Ending, restart: Restart) -> bool:
    return restart in ENDING_RULES[ending].retried_under


@dataclass
class _Assignment:
    request: LaunchRequest
    warnings: list[str] = field(default_factory=list)


def _clock(at: float) -> str:
    """A wall-clock time as a status message shows it: `21:04:05 UTC`."""
    return time.strftime("%H:%M:%S UTC", time.gmtime(at))


def describe_exit(code: int) -> str:
    """Popen's convention: a negative code is the signal that ended the process."""
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exited with code {code}"


# ---------------------------------------------------------------- the supervisor's parts


@dataclass
class _Readiness:
    """Readiness (docs/architecture.md#the-agents-states): a brain that said hello on its
    socket is `starting` until it says ready, not until startsecs have passed; one that does
    not say it within ready_timeout is stopped, and that counts as a failed start."""

    started_at: float = 0.0
    hello: bool = False
    hello_at: float = 0.0
    ready: bool = False
    unready_stop: bool = False  # stopped for not saying ready, and nothing else asked since

    def started(self, now: float) -> None:
        self.started_at = now
        self.hello = self.ready = self.unready_stop = False

    def deadline(self, policy: Policy) -> float | None:
        """When `tick` looks at a starting brain: startsecs after its start, or, once it said
        hello, ready_timeout after the hello (never, with ready_timeout 0)."""
        if not self.hello:
            return self.started_at + policy.startsecs
        if policy.ready_timeout <= 0:
            return None
        return self.hello_at + policy.ready_timeout

    def message(self, pid: int | None, policy: Policy) -> str:
        if not self.hello:
            return f"started pid {pid}"
        limit = policy.ready_timeout
        within = f" (ready_timeout {limit:g} s)" if limit > 0 else ""
        return f"brain pid {pid} said hello; starting until it says ready{within}"


@dataclass
class _Deferral:
    """While DEFERRED (the hold file): the phase it interrupted, the monotonic time it proceeds
    anyway, since when (wall clock), and a restart from the desk that waits (who asked, issued
    when)."""

    phase_before: AgentState = AgentState.RUNNING
    until: float | None = None
    since: float | None = None
    pending_restart: tuple[str, float] | None = None

    def end(self) -> None:
        self.until = None
        self.since = None
        self.pending_restart = None

    def waiting(
        self, desired: _Assignment | None, brain: _Assignment | None, policy: Policy
    ) -> str | None:
        """What the hold file defers, in words; None when nothing does any more."""
        if desired is None:
            return "stop (no launch request for this robot)"
        if self.pending_restart is not None:
            return f"restart requested by {self.pending_restart[0]}"
        if brain is not None and brain.request.digest == desired.request.digest:
            return None
        if self.reload_would_do(policy, brain, desired.request):
            return f"reload to request {desired.request.digest}"
        return f"restart for request {desired.request.digest}"

    def reload_would_do(
        self, policy: Policy, brain: _Assignment | None, request: LaunchRequest
    ) -> bool:
        return (
            policy.reload_signal is not None
            and self.phase_before == AgentState.RUNNING
            and brain is not None
            and brain.request.restart_digest is not None
            and brain.request.restart_digest == request.restart_digest
        )

    def message(self, what: str, policy: Policy) -> str:
        since = self.since or 0.0
        return (
            f"{what} deferred by the brain's hold file since {_clock(since)}; proceeds at "
            f"{_clock(since + policy.max_defer)} at the latest (max_defer "
            f"{policy.max_defer:g} s)"
        )

    def next_look(self, now: float, policy: Policy) -> float:
        """When `tick` looks at the hold file again."""
        assert self.until is not None
        return min(now + policy.hold_poll, self.until)


class _SupervisorState:
    """The supervisor's state and the ways it changes: every change of `phase` through `_move`,
    which refuses one TRANSITIONS does not list; starts, stops, reloads and the hold file's
    deferral; readiness and deferral are parts of their own (`_Readiness`, `_Deferral`).
    `Supervisor` adds the events that drive it."""

    def __init__(
        self,
        robot_id: str,
        policy: Policy,
        wall_clock: Callable[[], float] = time.time,
        held: Callable[[], bool] = lambda: False,
    ) -> None:
        self.robot_id = robot_id
        self.policy = policy
        self._wall = wall_clock
        # Whether the brain's hold file exists: like the wall clock, the one look at the world
        # this state machine takes, and only when a running brain would be stopped or reloaded.
        self._held = held
        self.busy = False  # the hold file seen at the last look (`look_busy`), while running
        self._phase = AgentState.IDLE  # changed only by `_move`
        self.desired: _Assignment | None = None  # the accepted request, if any
        self.brain: _Assignment | None = None  # the request the brain runs / last ran
        self.pid: int | None = None
        self.exit_code: int | None = None
        self.restarts = 0  # restarts of the current request, shown in the status
        self.reloads = 0  # reloads of the running brain since it started for a new capability
        self._before_reload: _Assignment | None = None  # what a failed reload goes back to
        self.streak = 0  # failures in a row, drives the backoff and `failed`
        self.deadline: float | None = None  # monotonic time at which `tick` has work
        self.message = "waiting for a launch request"
        self.rejection: str | None = None
        self.shutting_down = False
        # The last restart asked for from the desk and carried out (or deferred by the hold
        # file, and so carried out by max_defer): who asked, issued when.
        self.restart_requested_by: str | None = None
        self.restart_requested_at: float | None = None
        self._killed = False
        self._readiness = _Readiness()
        self._deferral = _Deferral()
        self._since = round(self._wall(), 3)
        self._reported = self.state

    # ------------------------------------------------------------ queries

    @property
    def phase(self) -> AgentState:
        """Where the brain's life stands; a rejection is shown over it (`state`)."""
        return self._phase

    @property
    def state(self) -> AgentState:
        return AgentState.REJECTED if self.rejection is not None else self.phase

    @property
    def finished(self) -> bool:
        """Shutting down and nothing left to wait for."""
        return self.shutting_down and self.pid is None

    def status(self, seq: int = 0) -> AgentStatus:
        """The status to publish; `seq` is the connection's business, given by the caller."""
        brain = self.brain
        message = self.message
        if self.rejection is not None:
            message = f"rejected: {self.rejection}"
            if self.pid is not None and brain is not None:
                message += f" (still running {brain.request.digest}, pid {self.pid})"
        deferred_since = self._deferral.since
        return AgentStatus(
            robot_id=self.robot_id,
            seq=seq,
            state=self.state,
            digest=brain.request.digest if brain else None,
            revision=brain.request.revision if brain else None,
            pid=self.pid,
            exit_code=self.exit_code,
            restarts=self.restarts,
            reloads=self.reloads,
            since=self._since,
            message=message,
            warnings=list(brain.warnings) if brain else [],
            restart_requested_by=self.restart_requested_by,
            restart_requested_at=self.restart_requested_at,
            deferred_since=deferred_since,
            max_defer=(self.policy.max_defer if deferred_since is not None or self.busy else None),
            busy=self.busy,
        )

    def look_busy(self) -> bool:
        """Looks at the hold file while a brain runs and holds may defer (max_defer > 0);
        True when what the status says about it changed."""
        running = self.pid is not None and not self.shutting_down
        busy = running and self.policy.max_defer > 0 and self._held()
        if busy == self.busy:
            return False
        self.busy = busy
        self._touch()
        return True

    # ------------------------------------------------------------ internals

    def _reloadable(self, request: LaunchRequest) -> bool:
        """A reload instead of a restart: asked for in agent.yaml, only the reloadable part
        changed (both requests carry a restart digest, and it is the same), and the brain is
        RUNNING. Not while STARTING: it may not yet have set up its handler, and the default
        action of SIGHUP and SIGUSR1/2 is to terminate; a restart is the safe answer there.
        In BACKOFF, EXITED or FAILED no brain runs, and STOPPING ends in a start anyway."""
        brain = self.brain
        return (
            self.policy.reload_signal is not None
            and self.phase == AgentState.RUNNING
            and self.pid is not None
            and brain is not None
            and brain is self.desired
            and brain.request.restart_digest is not None
            and brain.request.restart_digest == request.restart_digest
        )

    def _reload(self, assignment: _Assignment) -> list[Effect]:
        assert self.pid is not None and self.brain is not None
        assert self.policy.reload_signal is not None
        request = assignment.request
        self._before_reload = self.brain
        self.desired = self.brain = assignment
        self.reloads += 1
        # The state stays `running` (and so does `since`): the same process runs on.
        self.message = (
            f"reloaded {request.digest} (pid {self.pid}, {self.policy.reload_signal.name})"
        )
        return [Reload(self.pid, self.policy.reload_signal, request)]

    # ------------------------------------------------------------ deferral (the hold file)

    def _holds(self) -> bool:
        """A running brain, not yet being stopped, asks for time with its hold file."""
        return (
            self.policy.max_defer > 0
            and self.pid is not None
            and self.phase in (AgentState.STARTING, AgentState.RUNNING)
            and self._held()
        )

    def _defer(self, now: float) -> list[Effect]:
        """Into DEFERRED: the brain runs on; `tick` looks at the hold file until it is gone
        or max_defer has passed, whichever comes first."""
        self._deferral.phase_before = self.phase
        self._deferral.until = now + self.policy.max_defer
        self._enter(AgentState.DEFERRED, "")
        self._deferral.since = self._since
        return self._still_deferred(now)

    def _still_deferred(self, now: float) -> list[Effect]:
        """Something changed what waits (the newest ask wins); nothing left waiting resumes."""
        what = self._deferral.waiting(self.desired, self.brain, self.policy)
        if what is None:
            self._resume()
            return []
        self.message = self._deferral.message(what, self.policy)
        self.deadline = self._deferral.next_look(now, self.policy)
        return []

    def _look_at_hold(self, now: float) -> list[Effect]:
        assert self._deferral.until is not None
        if not self._held():
            return self._proceed(now, "the brain removed its hold file")
        if now >= self._deferral.until:
            return self._proceed(
                now,
                f"deferral ran out after {self.policy.max_defer:g} s (max_defer) with the "
                "hold file still there",
            )
        self.deadline = self._deferral.next_look(now, self.policy)
        return []

    def _proceed(self, now: float, why: str) -> list[Effect]:
        """What waited goes ahead: a stop, the desk's restart, a reload or a restart."""
        deferral = self._deferral
        what = deferral.waiting(self.desired, self.brain, self.policy)
        restart = deferral.pending_restart
        deferral.end()
        desired, brain = self.desired, self.brain
        if what is None or brain is None or self.pid is None:
            self._resume()
            return []
        if desired is None:
            return self._begin_stop(now, f"stopping: no launch request for this robot ({why})")
        if restart is None and deferral.reload_would_do(self.policy, brain, desired.request):
            self._move(AgentState.RUNNING)  # the same process runs on, signalled
            effects = self._reload(desired)
            self.message += f" ({why})"
            self._touch()
            return effects
        self.restarts = 0
        self.streak = 0
        if brain.request.digest != desired.request.digest:
            self.reloads = 0
        return self._begin_stop(now, f"{what} ({why}): stopping the brain")

    def _resume(self) -> None:
        """Back to what the brain was doing: nothing waits any more."""
        self._deferral.end()
        if self._deferral.phase_before == AgentState.STARTING and self.pid is not None:
            self.deadline = self._readiness.deadline(self.policy)
            self._enter(AgentState.STARTING, self._readiness.message(self.pid, self.policy))
        else:
            self.deadline = None
            self._enter(AgentState.RUNNING, f"running (pid {self.pid})")

    # ------------------------------------------------------------ the rest

    def _forget_desk_restart(self) -> None:
        """A restart from the desk is shown (`restart: ROBOT by WHO at WHEN`) only while it is
        the brain's latest start for another reason than a crash: a new request or none ends
        it. A reload does not (the same process runs on), nor a crash restart (RESTARTS counts
        those since)."""
        self.restart_requested_by = None
        self.restart_requested_at = None

    def _spawn(self, now: float) -> list[Effect]:
        assert self.desired is not None
        self.brain = self.desired
        self.pid = None
        self.deadline = None
        self._enter(AgentState.STARTING, f"starting {self.desired.request.digest}")
        return [Spawn(self.desired.request)]

    def _begin_stop(self, now: float, why: str) -> list[Effect]:
        assert self.pid is not None
        self._killed = False
        self.deadline = now + self.policy.stop_timeout
        self._enter(AgentState.STOPPING, why)
        return [Terminate(self.pid)]

    def _move(self, phase: AgentState) -> bool:
        """The one change of `phase`: one TRANSITIONS does not list is refused (logged; the
        phase stays), never raised: an agent must outlive a bug in its own rules."""
        if not legal(self._phase, phase):
            log.error(
                "illegal phase change of %s refused: %s -> %s (agent/supervisor.py TRANSITIONS)",
                self.robot_id,
                self._phase.value,
                phase.value,
            )
            return False
        self._phase = phase
        return True

    def _enter(self, phase: AgentState, message: str) -> None:
        if self._move(phase):
            self.message = message
        self._touch()

    def _set_rejection(self, reason: str | None) -> None:
        self.rejection = reason
        self._touch()

    def _touch(self) -> None:
        # `since` marks the last change of the reported state, not every message edit.
        if self.state != self._reported:
            self._reported = self.state
            self._since = round(self._wall(), 3)


class Supervisor(_SupervisorState):
    """One robot's brain: what should run, what runs, and what to do about the difference:
    events in (a request, an exit, time passing...), effects out."""

    # ------------------------------------------------------------ events

    def accept(self, request: LaunchRequest, warnings: list[str], now: float) -> list[Effect]:
        """A valid request for this robot arrived."""
        self._set_rejection(None)
        if self.shutting_down:
            return []
        if self.desired is not None and self.desired.request.digest == request.digest:
            return []  # same content: a retained redelivery or a commit that changed nothing
        assignment = _Assignment(request, list(warnings))
        if self.phase == AgentState.DEFERRED:
            self.desired = assignment  # the newest request replaces the one that waited
            return self._still_deferred(now)
        reloadable = self._reloadable(request)
        if self._holds():
            self.desired = assignment
            return self._defer(now)
        if reloadable:
            return self._reload(assignment)
        self.desired = assignment
        self.restarts = 0
        self.reloads = 0
        self.streak = 0
        self._forget_desk_restart()  # this request restarts the brain: the latest restart
        if self.pid is not None:
            if self.phase == AgentState.STOPPING:
                return []  # the exit will start the newest desired request
            return self._begin_stop(now, f"stopping for new request {request.digest}")
        return self._spawn(now)

    def reload_failed(self, request: LaunchRequest, error: str, now: float) -> list[Effect]:
        """The reloaded request could not be written: the brain was not signalled and runs
        what it ran, and that is what is reported (with the reason), as when a request
        cannot be staged for a restart. The same request arriving again is tried again."""
        before = self._before_reload
        brain = self.brain
        if before is not None and brain is not None and brain.request is request:
            self._before_reload = None
            self.brain = self.desired = before
            self.reloads -= 1
            self.message = f"running (pid {self.pid})"
        self._set_rejection(error)
        return []

    def reject(self, reason: str, now: float) -> list[Effect]:
        """A request was refused; the brain, if any, is left as it is."""
        self._set_rejection(reason)
        return []

    def clear(self, now: float) -> list[Effect]:
        """The empty retained payload: nothing assigned, stop."""
        self._set_rejection(None)
        self.desired = None
        self._forget_desk_restart()
        if self.phase == AgentState.DEFERRED:
            return self._still_deferred(now)
        if self.pid is not None:
            if self.phase == AgentState.STOPPING:
                return []
            if self._holds():
                return self._defer(now)
            return self._begin_stop(now, "stopping: no launch request for this robot")
        self.deadline = None
        self.brain = None
        self.exit_code = None
        self.restarts = 0
        self.reloads = 0
        self._enter(AgentState.IDLE, "no launch request for this robot")
        return []

    def spawned(self, pid: int, now: float) -> list[Effect]:
        self.pid = pid
        self._killed = False
        self._readiness.started(now)
        self.exit_code = None
        if self.policy.startsecs <= 0:
            self.deadline = None
            self._enter(AgentState.RUNNING, f"running (pid {pid})")
        else:
            self.deadline = now + self.policy.startsecs
            self._enter(AgentState.STARTING, f"started pid {pid}")
        return []

    def spawn_failed(self, error: str, now: float) -> list[Effect]:
        """The command could not even be started (missing executable, unwritable request)."""
        self.pid = None
        self.deadline = None
        self._enter(ENDING_RULES[Ending.SPAWN_FAILED].terminal, error)
        return []

    def exited(self, pid: int, code: int, now: float) -> list[Effect]:
        if pid != self.pid:
            return []  # a stale report about an earlier process
        self.pid = None
        self.exit_code = code
        self.deadline = None
        how = describe_exit(code)
        if self.phase == AgentState.DEFERRED:
            # Nothing runs to protect any more: what waited goes ahead at once (a crash is
            # never deferred), as after a stop: the desired request starts, or none.
            self._deferral.end()
            self._move(AgentState.STOPPING)
        # Stopped because it never said ready, and nothing else asked for the stop since: a
        # failed start, which the restart policy answers as it answers a crash.
        unready = (
            self._readiness.unready_stop
            and self.phase == AgentState.STOPPING
            and not self.shutting_down
            and self.desired is self.brain
        )
        self._readiness.unready_stop = False
        if unready:
            how = f"was not ready within {self.policy.ready_timeout:g} s (ready_timeout)"
        elif self.phase == AgentState.STOPPING or self.shutting_down:
            return self._stopped(how, now)
        if not unready and now - self._readiness.started_at >= self.policy.reset_after:
            self.streak = 0  # a brain that never became ready was never healthy
        ending = Ending.UNREADY if unready else Ending.CRASHED if code != 0 else Ending.CLEAN
        return self._ended(ending, how, now)

    def _stopped(self, how: str, now: float) -> list[Effect]:
        """A brain that was asked to stop has: the desired request starts, or none."""
        if self.shutting_down:
            self._enter(AgentState.IDLE, f"brain stopped ({how})")
            return []
        if self.desired is not None:
            return self._spawn(now)
        self.brain = None
        self.restarts = 0
        self.reloads = 0
        self._enter(AgentState.IDLE, "no launch request for this robot")
        return []

    def _ended(self, ending: Ending, how: str, now: float) -> list[Effect]:
        """A brain ended on its own: restarted in backoff, or at rest, as ENDING_RULES say."""
        policy = self.policy
        if not retried(ending, policy.restart):
            self._enter(ENDING_RULES[ending].terminal, f"brain {how}")
            return []
        if self.streak >= policy.max_restarts:
            self._enter(
                AgentState.FAILED,
                f"brain {how}; gave up after {self.restarts} restarts (max_restarts "
                f"{policy.max_restarts})",
            )
            return []
        delay = policy.backoff(self.streak)
        self.streak += 1
        self.deadline = now + delay
        self._enter(AgentState.BACKOFF, f"brain {how}; restarting in {delay:g} s")
        return []

    def restart(
        self, requested_by: str, issued_at: float, now: float
    ) -> tuple[list[Effect], str | None]:
        """A restart asked for from the desk: the assigned request's brain starts again, with
        its restart count and backoff reset, so a `failed` brain gets a new chance and a
        wedged one is stopped first. Returns the effects, and why nothing happens when the
        restart cannot be carried out."""
        if self.shutting_down:
            return [], "the agent is shutting down"
        if self.desired is None:
            return [], "nothing to restart: no launch request is assigned to this robot"
        if self.phase == AgentState.DEFERRED or (
            self.phase != AgentState.STOPPING and self._holds()
        ):
            # Accepted, and carried out by max_defer at the latest: the status names it now,
            # so that the desk sees its restart taken (and `deferred`).
            self.restart_requested_by = requested_by
            self.restart_requested_at = issued_at
            self._deferral.pending_restart = (requested_by, issued_at)  # the newest ask waits
            if self.phase == AgentState.DEFERRED:
                return self._still_deferred(now), None
            return self._defer(now), None
        self.restart_requested_by = requested_by
        self.restart_requested_at = issued_at
        self.restarts = 0
        self.streak = 0
        self._readiness.unready_stop = False  # asked for: its exit starts the brain at once
        why = f"restart requested by {requested_by}"
        if self.pid is not None:
            if self.phase == AgentState.STOPPING:
                self.message = f"{why}: the brain is stopping, then starts again"
                return [], None  # its exit starts the assigned request
            return self._begin_stop(now, f"{why}: stopping the brain"), None
        return self._spawn(now), None

    def tick(self, now: float) -> list[Effect]:
        """Time passed; does something only once `deadline` is reached."""
        if self.deadline is None or now < self.deadline:
            return []
        self.deadline = None
        if self.phase == AgentState.DEFERRED:
            return self._look_at_hold(now)
        if self.phase == AgentState.STARTING and self.pid is not None:
            if not self._readiness.hello:
                self._enter(AgentState.RUNNING, f"running (pid {self.pid})")
            elif not self._readiness.ready:
                self._readiness.unready_stop = True
                return self._begin_stop(
                    now,
                    f"brain pid {self.pid} said hello but not ready within "
                    f"{self.policy.ready_timeout:g} s (ready_timeout): stopping it",
                )
        elif self.phase == AgentState.STOPPING and self.pid is not None and not self._killed:
            self._killed = True
            self.message = (
                f"brain pid {self.pid} ignored SIGTERM for {self.policy.stop_timeout:g} s: "
                "sent SIGKILL"
            )
            return [Kill(self.pid)]
        elif self.phase == AgentState.BACKOFF and self.desired is not None:
            self.restarts += 1
            return self._spawn(now)
        return []

    def hello(self, now: float) -> list[Effect]:
        """The running brain said hello on its socket: from now on it is healthy from its
        `ready`, not from startsecs. One that counted as running already (it took longer than
        startsecs to connect) is `starting` again until then."""
        readiness = self._readiness
        if self.pid is None or self.shutting_down or readiness.hello or readiness.ready:
            return []
        readiness.hello = True
        readiness.hello_at = now
        deferral = self._deferral
        if self.phase == AgentState.DEFERRED and deferral.phase_before == AgentState.RUNNING:
            deferral.phase_before = AgentState.STARTING
        if self.phase in (AgentState.RUNNING, AgentState.STARTING):
            self.deadline = readiness.deadline(self.policy)
            self._enter(AgentState.STARTING, readiness.message(self.pid, self.policy))
        return []

    def ready(self, now: float) -> list[Effect]:
        """The running brain said ready (as systemd's READY=1): it is `running`."""
        if self.pid is None or self.shutting_down or self._readiness.ready:
            return []
        self._readiness.ready = True
        self._readiness.hello = True
        if self.phase == AgentState.STARTING:
            self.deadline = None
            self._enter(AgentState.RUNNING, f"running (pid {self.pid}, ready)")
        elif (
            self.phase == AgentState.DEFERRED and self._deferral.phase_before == AgentState.STARTING
        ):
            self._deferral.phase_before = AgentState.RUNNING
        return []

    def shutdown(self, now: float) -> list[Effect]:
        """The agent is asked to stop; asked again, it stops waiting for the brain."""
        if self.shutting_down and self.pid is not None:
            self._killed = True
            return [Kill(self.pid)]
        self.shutting_down = True
        self.deadline = None
        self._deferral.end()  # the agent's own stop is never deferred (the hold file's how-to)
        if self.pid is not None:
            return self._begin_stop(now, "agent shutting down: stopping the brain")
        return []
