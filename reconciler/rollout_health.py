"""The wave judge, pure: the health of a rollout's current wave, robot by robot, judged only on
what each reports about the new request and on what the wave established (`WaveMemory`) —
who was seen online, healthy or failed, who defers, which group waits for a busy member —
and when a judgment changes with no new message."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from enum import Enum

from robotconf.configurator.types import RolloutPolicy
from robotconf.contract.wire import AgentState, AgentStatus, is_online
from robotconf.reconciler.rollout_scope import RolloutInput, RolloutScope
from robotconf.reconciler.wave_memory import WaveMemory, memory_of

# An agent reporting these about the new request has failed it.
FAILED_STATES = {AgentState.FAILED, AgentState.BACKOFF, AgentState.EXITED}
# Seconds a robot stays dark, watched without a break, before it counts as gone: a broker that
# shuts down publishes every client's Last Will just before it drops the reconciler too.
DARK_GRACE = 2.0


class Health(str, Enum):
    """A robot of the current wave, judged only on what it reports about the new request."""

    HEALTHY = "healthy"  # ran the new request for healthy_after seconds
    FAILED = "failed"  # failed, backed off, exited or refused it; went dark; timed out
    PENDING = "pending"  # on its way
    ABSENT = "absent"  # never seen online with it: pending, never failed; waited for until timeout
    # Offline (dark for DARK_GRACE) and never seen online since its wave published its request,
    # under `offline: skip`: the wave goes on without it; it gets the request when it is back.
    OFFLINE = "offline"


def status_unknown(seen: RolloutInput, robot: str, statuses: Mapping[str, AgentStatus]) -> bool:
    """A robot without any status while the read is known to lack messages the broker
    dropped: its status may be one of them. It is waited for (absent: until wave_timeout,
    never failed for it), not taken for offline or dark."""
    return seen.statuses_lost is not None and robot not in statuses


class WaveJudge:
    """Judges the wave a step stands in; the one owner of what that judgment leaves for the
    rest of the step: the robots held while their group waits for a busy member (not sent the
    head's request), why, and the wave's robots whose status may have been dropped."""

    def __init__(self, scope: RolloutScope) -> None:
        self.scope = scope
        self.busy_held: set[str] = set()  # robots whose group waits for a busy member
        self.busy_why = ""  # which group waits for whom, for the status
        self.unknown: list[str] = []  # the wave's robots whose status may have been dropped

    def judge(
        self, wave: int, started_at: float, begins: bool
    ) -> tuple[dict[str, Health], float | None, float, WaveMemory | None]:
        """The health of the wave's changed robots; when a judgment changes with time; the
        wave's deadline; and what the wave has established, this step included."""
        scope = self.scope
        head, policy, now = scope.seen.head, scope.policy, scope.seen.now
        members = sorted(r for r in scope.changed if scope.waves.get(r) == wave)
        statuses = scope.seen.statuses
        if statuses is None:  # not known yet: nothing is judged, nothing is forgotten
            memory = memory_of(scope.seen.record, head.revision, wave, started_at, members)
            return {r: Health.PENDING for r in members}, None, math.inf, memory
        memory = self._memory(wave, started_at, members, statuses, begins)
        # The wave's clock runs while the reconciler watches: restarted, or back from a lost
        # broker, it gives the robots the whole wave_timeout again rather than blame them for
        # what it could not see.
        deadline = max(started_at, memory.watching_since) + policy.wave_timeout
        deadline = deferral_deadline(memory, members, statuses, now, deadline, policy)
        deadline, held_until = self._hold_busy_groups(members, statuses, memory, deadline)
        judged: dict[str, Health] = {}
        times: list[float] = []  # when a judgment changes with time
        for robot in members:
            judged[robot] = self._judge_robot(robot, statuses, memory, deadline, times.append)
        self.unknown = [r for r in members if status_unknown(scope.seen, r, statuses)]
        self._fail_groups(judged, memory)
        if held_until is not None:
            times.append(held_until)  # the group goes at its max_defer at the latest
        return judged, min(times, default=None), deadline, memory

    def _judge_robot(
        self,
        robot: str,
        statuses: Mapping[str, AgentStatus],
        memory: WaveMemory,
        deadline: float,
        soon: Callable[[float], None],
    ) -> Health:
        """One robot of the wave, and (`soon`) when its judgment may change with time."""
        seen, policy, now = self.scope.seen, self.scope.policy, self.scope.seen.now
        digest = seen.head.requests[robot].digest
        since = seen.running_since.get(robot)
        dark_at = seen.dark_since.get(robot, memory.watching_since) + DARK_GRACE
        unknown = status_unknown(seen, robot, statuses)
        health = (
            Health.ABSENT
            if robot in seen.held
            else _health(
                robot,
                statuses.get(robot),
                digest,
                seen.launches.get(robot) == digest,
                since,
                now >= dark_at and not unknown,
                now,
                policy.healthy_after,
                memory,
            )
        )
        if health is Health.ABSENT and robot not in seen.held and not unknown:
            health = self._offline(robot, now >= dark_at, memory)
            if health is Health.ABSENT and policy.offline != "wait":
                soon(dark_at)  # dark a moment ago (a reconnecting agent): offline once it lasts
        dark = robot in memory.seen and not is_online(statuses.get(robot))
        if health is Health.PENDING and dark and now < dark_at and robot not in memory.doubted:
            soon(dark_at)  # dark a moment ago: gone once it has lasted
        if health is Health.PENDING and since is not None:
            soon(since + policy.healthy_after)
        if health is Health.PENDING and now >= deadline:
            health = Health.FAILED  # not healthy by wave_timeout
            memory.failed.add(robot)
        if health in (Health.PENDING, Health.ABSENT) and now < deadline:
            soon(deadline)
        return health

    def _hold_busy_groups(
        self,
        members: list[str],
        statuses: Mapping[str, AgentStatus],
        memory: WaveMemory,
        deadline: float,
    ) -> tuple[float, float | None]:
        """A group changes restart-class content only when all its robots can: while one of
        the wave's groups has a busy robot (its brain's hold file) and the change restarts a
        brain of it, none of the group is sent its request — for the robots' `max_defer` at
        most, from the first look that held it (kept in the wave's record); then they are sent
        it and each agent defers as usual. The wave's deadline gives them wave_timeout after.
        Returns the deadline and when the hold ends (None: nothing held)."""
        scope = self.scope
        group_of, now = scope.plan.group_of, scope.seen.now
        self.busy_held, self.busy_why = set(), ""
        if not group_of:
            return deadline, None
        groups: dict[str, list[str]] = {}
        for robot in members:
            if robot in group_of:
                groups.setdefault(group_of[robot], []).append(robot)
        waiting: dict[str, tuple[str, float]] = {}  # group -> (a busy robot, its max_defer)
        for group, robots in groups.items():
            restarts = any(self._restarts(r) for r in robots)
            if not restarts or all(scope.seen.launches.get(r) == scope.digest(r) for r in robots):
                continue  # nothing to restart, or already sent
            for robot in robots:
                status = statuses.get(robot)
                if status is not None and status.busy and is_online(status):
                    waiting[group] = (robot, status.max_defer or 0.0)
                    break
        if not waiting:
            return deadline, None
        if memory.held_since is None:
            memory.held_since = now
        until = memory.held_since + max(defer for _, defer in waiting.values())
        if now >= until:
            return deadline, None  # held for max_defer: sent now, each agent defers as usual
        for group in waiting:
            self.busy_held.update(groups[group])
        self.busy_why = (
            "; ".join(
                f"group '{group}' waits while {robot} is busy"
                for group, (robot, _) in waiting.items()
            )
            + f" (until {until - now:.0f} s from now at most)"
        )
        return max(deadline, until + scope.policy.wave_timeout), until

    def _restarts(self, robot: str) -> bool:
        """Whether the head's request restarts the robot's brain (not a reload)."""
        old = self.scope.stable_requests.get(robot)
        new = self.scope.seen.head.requests[robot]
        return old is None or old.restart_digest != new.restart_digest

    def _fail_groups(self, judged: dict[str, Health], memory: WaveMemory) -> None:
        """A group moves as one: a member that failed fails the others of the wave too (the
        thesis' cooperation: a delivery robot without its guide has not done its work)."""
        group_of = self.scope.plan.group_of
        failing = {group_of[r] for r, h in judged.items() if h is Health.FAILED and r in group_of}
        for robot, health in judged.items():
            if health is not Health.FAILED and group_of.get(robot) in failing:
                judged[robot] = Health.FAILED
                memory.failed.add(robot)

    def _offline(self, robot: str, lasted: bool, memory: WaveMemory) -> Health:
        """A robot never seen online since its wave published its request, dark now: what
        `rollout.offline` makes of it once it has been dark for DARK_GRACE. One seen since (online
        as the wave was published, or later) is never this: gone dark, it failed (_health)."""
        policy = self.scope.policy
        if not lasted or policy.offline == "wait":
            return Health.ABSENT
        if policy.offline == "fail":
            memory.failed.add(robot)
            return Health.FAILED
        return Health.OFFLINE

    def _memory(
        self,
        wave: int,
        started_at: float,
        members: list[str],
        statuses: Mapping[str, AgentStatus],
        begins: bool,
    ) -> WaveMemory:
        """The wave's memory: its record when it is about this wave, else a new one whose
        baseline is what is true now."""
        seen = self.scope.seen
        head, watching_since = seen.head, seen.watching_since
        memory = memory_of(seen.record, head.revision, wave, started_at, members)
        if memory is None:
            memory = WaveMemory(head.revision, wave, started_at, members, watching_since)
            memory.rejecting = {
                r for r in members if (s := statuses.get(r)) and s.state is AgentState.REJECTED
            }
            if begins:  # published in this step: those online now are sent it at once
                memory.seen = {r for r in members if is_online(statuses.get(r))}
        elif memory.watching_since != watching_since:
            # The statuses were learned anew (a restart, a reconnection): a robot dark now may
            # have died meanwhile, or only be one whose broker restarted (which publishes every
            # Last Will as it stops, or forgets them all): it has until the deadline to be back.
            memory.doubted = {r for r in memory.seen if not is_online(statuses.get(r))}
            memory.watching_since = watching_since
        return memory


def deferral_deadline(
    memory: WaveMemory,
    members: list[str],
    statuses: Mapping[str, AgentStatus],
    now: float,
    deadline: float,
    policy: RolloutPolicy,
) -> float:
    """The wave's deadline with its busy robots: a robot whose brain holds off the new request
    (state `deferred`) is neither healthy nor failed while it defers — its agent proceeds by
    its max_defer at the latest — and the wave gives it wave_timeout again from the last look
    that saw it deferring, or just done deferring, to start and settle. Going dark still fails
    it (`_health`): it may have died of the new request."""
    for robot in members:
        status = statuses.get(robot)
        if status is not None and status.state is AgentState.DEFERRED:
            memory.deferring.add(robot)
            memory.deferred_at = now
        elif robot in memory.deferring:
            memory.deferring.discard(robot)
            memory.deferred_at = now
    if memory.deferred_at is None:
        return deadline
    return max(deadline, memory.deferred_at + policy.wave_timeout)


def _health(
    robot: str,
    status: AgentStatus | None,
    digest: str,
    delivered: bool,
    running_since: float | None,
    gone: bool,
    now: float,
    healthy_after: float,
    memory: WaveMemory,
) -> Health:
    """One robot of the current wave, judged on what the reconciler saw and remembers — never
    on a robot's clock. A status about another digest never counts as health (the trap of
    judging a wave by robots still reporting the previous request)."""
    if robot in memory.failed:
        return Health.FAILED  # a failure is not undone by what comes after, in this wave
    if not is_online(status):
        if robot not in memory.seen:
            return Health.ABSENT
        if gone and robot not in memory.doubted:
            # Dark (its Last Will, or no status at all) after it was sent the new request,
            # for DARK_GRACE: it may have died of it, whatever times its Will carries.
            memory.failed.add(robot)
            return Health.FAILED
        return Health.PENDING  # failed at the wave's deadline if it is not back by then
    assert status is not None
    memory.doubted.discard(robot)
    if status.state is not AgentState.REJECTED:
        memory.rejecting.discard(robot)
    if not delivered:
        return Health.PENDING
    memory.seen.add(robot)
    if status.state is AgentState.REJECTED:
        if robot in memory.rejecting:
            return Health.PENDING  # a rejection from before the wave, not of its request
        memory.failed.add(robot)
        return Health.FAILED  # it refused the new request
    if status.digest != digest:
        return Health.PENDING
    if status.state in FAILED_STATES:
        memory.failed.add(robot)
        return Health.FAILED
    if robot in memory.healthy:
        return Health.HEALTHY
    settled = running_since is not None and now - running_since >= healthy_after
    if status.state is AgentState.RUNNING and settled:
        memory.healthy.add(robot)
        return Health.HEALTHY
    return Health.PENDING
