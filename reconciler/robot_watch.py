"""The controller's look at the robots (one owner: `RobotWatch`): their statuses, followed live
while the head has a rollout policy (the waves are gated by them) and otherwise sampled now and
then; their interfaces, followed while fleet.yaml says `drift: hold`.

A part of `reconciler.controller`'s state, kept apart so that the controller is a loop over
named parts rather than one class holding all of them.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from robotconf.contract.interfaces import Reported
from robotconf.contract.mqtt import Connection
from robotconf.contract.topics import Role, subscriptions
from robotconf.contract.wire import AgentState, AgentStatus, ReconcilerStatus, Topics, is_online
from robotconf.readmodel.observed import ReadMemo, parse_retained
from robotconf.readmodel.retained import Ignored, RetainedView, take_snapshot_said

log = logging.getLogger("robotconf.reconciler")
SAMPLE_TIMEOUT = 10.0  # seconds to wait for a sample of the robots' statuses


class RobotWatch:
    """The robots as the reconciler sees them: on the loop, but for the network threads'
    `_on_health` and `_on_interfaces`, which only wake the loop. `status` is the reconciler's
    status last written: a change matters at once only to a rollout in progress, or to robots
    held for drift."""

    def __init__(
        self,
        connection: Connection,
        topics: Topics,
        ignored: Ignored,
        wake: Callable[[], None],
        stopped: threading.Event,
        status: Callable[[], ReconcilerStatus | None],
    ) -> None:
        self._connection = connection
        self._topics = topics
        self._ignored = ignored
        self._wake = wake
        self._stopped = stopped
        self._status = status
        # The robots' statuses, followed live only while the head has a rollout policy: the
        # waves are gated by them. Without one they are only sampled (`sample_active`).
        self.health: RetainedView | None = None
        self._health_memo = ReadMemo()
        # The robots' interfaces, followed only while fleet.yaml says `drift: hold`.
        self.interfaces: RetainedView | None = None
        self._interfaces_memo = ReadMemo()
        # robot -> (its run, first seen running so): a run is a digest in one brain process
        # entered at one time (the agent's, compared only with itself), so a brain that crashed
        # and runs again between two looks is a new run, not a settled one.
        self._running_since: dict[str, tuple[tuple[str, int | None, float], float]] = {}
        self._watched = 0  # the health view's connection whose statuses were learned last
        self.watching_since = 0.0  # when they were: a rollout's clock counts from then
        # robot -> when first seen dark (offline, or its status gone) on that connection
        self._dark_since: dict[str, float] = {}
        self._had_status: set[str] = set()  # robots with a status on that connection
        self._sampled_connection = 0  # the view connection the last status sample was taken on

    @property
    def running_since(self) -> dict[str, float]:
        """robot -> when first seen running its current run."""
        return {robot: seen for robot, (_, seen) in self._running_since.items()}

    @property
    def dark_since(self) -> dict[str, float]:
        return dict(self._dark_since)

    def views(self) -> list[RetainedView]:
        return [v for v in (self.health, self.interfaces) if v is not None]

    def stop(self) -> None:
        self.follow_health(False)
        self.follow_interfaces(False)

    def follow_health(self, wanted: bool, now: float = 0.0) -> dict[str, AgentStatus] | None:
        """The robots' statuses while a rollout policy is in force (None until they are
        known), and when each robot was first seen running its digest."""
        if wanted and self.health is None:
            self.health = RetainedView(
                self._connection,
                subscriptions(Role.RECONCILER, self._topics.prefix, "status"),
                self._topics.sync,
                role="reconciler-health",
                on_synced=self._wake,
                on_change=self._on_health,
            )
            self.health.start()
        elif not wanted and self.health is not None:
            self.health.stop()
            self.health = None
            self._running_since.clear()
            self._dark_since.clear()
            self._had_status.clear()
        if self.health is None or not self.health.synced:
            return None
        if self.health.connections != self._watched:
            self._watched = self.health.connections
            self.watching_since = now
            self._dark_since.clear()
            self._had_status.clear()
        seen = parse_retained(
            self.health.snapshot(), self._topics, ignored=self._ignored, memo=self._health_memo
        )
        statuses = {r: robot.status for r, robot in seen.robots.items() if robot.status}
        self._had_status |= statuses.keys()
        for robot in self._had_status:
            if is_online(statuses.get(robot)):
                self._dark_since.pop(robot, None)
            else:  # its Last Will, or its status gone
                self._dark_since.setdefault(robot, now)
        for robot, status in statuses.items():
            if status.state is AgentState.RUNNING and status.digest:
                run = (status.digest, status.pid, status.since)
                known = self._running_since.get(robot)
                if known is None or known[0] != run:
                    self._running_since[robot] = (run, now)
            else:
                self._running_since.pop(robot, None)
        return statuses

    def _on_health(self) -> None:
        """Network thread: a robot's status changed; a rollout in progress looks at once."""
        status = self._status()
        rollout = status.rollout if status is not None else None
        if rollout is not None and rollout.state == "Progressing" and not self._stopped.is_set():
            self._wake()

    def follow_interfaces(self, wanted: bool) -> dict[str, Reported] | None:
        """The robots' readable interfaces reports, followed only while fleet.yaml says
        `drift: hold` (None until they are known, or when not followed)."""
        if wanted and self.interfaces is None:
            self.interfaces = RetainedView(
                self._connection,
                subscriptions(Role.RECONCILER, self._topics.prefix, "interfaces"),
                self._topics.sync,
                role="reconciler-interfaces",
                on_synced=self._wake,
                on_change=self._on_interfaces,
            )
            self.interfaces.start()
        elif not wanted and self.interfaces is not None:
            self.interfaces.stop()
            self.interfaces = None
            self._interfaces_memo = ReadMemo()
        if self.interfaces is None or not self.interfaces.synced:
            return None
        seen = parse_retained(
            self.interfaces.snapshot(),
            self._topics,
            ignored=self._ignored,
            memo=self._interfaces_memo,
        )
        return {r: robot.interfaces for r, robot in seen.robots.items() if robot.interfaces}

    def _on_interfaces(self) -> None:
        """Network thread: a robot's interfaces changed; a robot held for drift may fit now."""
        status = self._status()
        if status is not None and status.held and not self._stopped.is_set():
            self._wake()

    def sample_active(self, resync: bool, connection: int) -> set[str]:
        """Robots whose agent says a brain is up or about to be, sampled at each resync and
        after each (re)connection of the launch view (`connection`: its count), when the broker
        may have lost the clears; empty otherwise.

        Only a robot that is running but no longer assigned is acted on (cleared again), so
        a sample is used once: between samples, a commit never clears anything twice."""
        if not resync and connection == self._sampled_connection:
            return set()
        self._sampled_connection = connection
        statuses, lost = take_snapshot_said(
            self._connection,
            subscriptions(Role.RECONCILER, self._topics.prefix, "status"),
            self._topics.sync,
            role="reconciler-sample",
            timeout=SAMPLE_TIMEOUT,
        )
        if statuses is None:
            log.info("no status sample from the broker this time")
            return set()
        if lost is not None:
            # What it lacks may be a robot still running: act on what arrived, say the rest.
            log.warning(
                "the status sample lacks messages the broker dropped (%s); raise its "
                "max_queued_messages (robotconf broker-config sets it for the fleet)",
                lost,
            )
        return parse_retained(statuses, self._topics, ignored=self._ignored).active()
