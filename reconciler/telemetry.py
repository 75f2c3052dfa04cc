"""Alerts and metrics of `robotconf reconcile`, off the reconcile loop, on a thread of their own.

Fed by the controller's `on_step` hook and by a view of the robots' statuses: it judges
transitions (`events`), tells the receivers (`notify`), hands every event to the timeline
(`keep`: the ledger's, `readmodel/timeline.py` notes the timeline's own kinds) and sets the
gauges (`metrics`).
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

from robotconf.configurator.drift import Drift, DriftMemo
from robotconf.contract.mqtt import Connection
from robotconf.contract.topics import Role, subscriptions
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from robotconf.readmodel.events import Event, Seen, Told, WaveRun, resumed, resumers, transitions
from robotconf.readmodel.observed import ReadMemo, Retained, RobotSeen, parse_retained
from robotconf.readmodel.retained import RetainedView
from robotconf.readmodel.timeline import Noted, noted_at_start, timeline_transitions
from robotconf.readmodel.verdicts import (
    DesiredRobot,
    Verdict,
    desired_from_fleet,
    robot_drift,
    verdict,
)
from robotconf.reconciler import heap
from robotconf.reconciler.controller import Step
from robotconf.reconciler.decide import state_of

if TYPE_CHECKING:
    from robotconf.reconciler.metrics import Metrics
    from robotconf.reconciler.notify import Notifier

log = logging.getLogger("robotconf.reconciler")


class Telemetry:
    """Started before the controller runs, stopped after; `on_step` is its hook."""

    def __init__(
        self,
        connection: Connection,
        prefix: str,
        *,
        notifier: Notifier | None = None,
        metrics: Metrics | None = None,
        keep: Callable[[Sequence[Event]], None] | None = None,
    ) -> None:
        self.topics = Topics(prefix)
        self.notifier = notifier
        self.metrics = metrics
        self.keep = keep  # the timeline's: every event told or noted (set before `start`)
        # Told each new serving revision's desired robots, made here anyway (set before
        # `start`): `robotconf status` and the browser view read them back rather than build.
        self.keep_desired: Callable[[str, Mapping[str, DesiredRobot]], None] | None = None
        self._noted = Noted()
        self._started = time.time()  # a desk restart asked before it was noted by another
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._step: Step | None = None
        self._told = Told()
        self._resumed = False  # the status found at start is read into `_told` once
        # wave run -> who resumed it: from each step's verdicts, which `_look` may not all see
        self._resumers: dict[WaveRun, str] = {}
        # robot -> ((digest, the agent's since), first seen running it by our clock)
        self._running_since: dict[str, tuple[tuple[str, float], float]] = {}
        self._desired: tuple[str | None, dict[str, DesiredRobot]] = (None, {})
        self._memo = ReadMemo()  # each payload read once while it stays the same
        self._drift = DriftMemo()  # each robot's drift, again only when request or report move
        self.view = RetainedView(
            connection,
            subscriptions(Role.RECONCILER, prefix, "status", "interfaces"),
            self.topics.sync,
            role="reconciler-alerts",
            on_change=self._wake.set,
            on_synced=self._wake.set,
        )
        self._thread = threading.Thread(target=self._run, name="telemetry", daemon=True)

    def start(self) -> None:
        if self.notifier is not None:
            self.notifier.start()
        self.view.start()
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        self._thread.join(5)
        self.view.stop()
        if self.notifier is not None:
            self.notifier.stop()
        if self.metrics is not None:
            self.metrics.close()

    def on_step(self, step: Step) -> None:
        """The reconcile loop's hook: counts the step and hands it over, never waiting."""
        if self.metrics is not None:
            self.metrics.step(
                step.seconds,
                applied=step.serving.revision if step.serving is not None else None,
                ready=step.status is not None and step.status.ready,
                published=step.published,
                cleared=step.cleared,
                error=step.reason.value if state_of(step.reason) == "Stalled" else None,
            )
            # Here, not in `_look`: each step's verdicts are counted, though `_look` may see
            # only the last of several steps.
            rollout = step.status.rollout if step.status is not None else None
            self.metrics.rollout(rollout, step.verdicts)
        with self._lock:
            if not self._resumed:
                # The first step's: a later step may be all `_look` sees.
                self._resumed = True
                self._told = resumed(self._told, step.found)
                self._noted = noted_at_start(self._noted, step.found)
            self._step = step
            if step.verdicts:
                self._resumers = resumers(self._resumers, step.verdicts)
        self._wake.set()

    def _run(self) -> None:
        while not self._stop.is_set():
            # A robot told degraded or offline may settle back in sync with nothing arriving.
            self._wake.wait(1.0 if self._told.alerting else None)
            self._wake.clear()
            if self._stop.is_set():
                return
            try:
                self._look()
            except Exception:  # a bug here must not end alerting for good
                log.exception("internal error in alerts or metrics; ignored")

    def _look(self) -> None:
        with self._lock:
            step, resumed_by = self._step, self._resumers
        if step is None:  # robots are judged against what the reconciler serves
            return
        now = time.time()  # events carry it, so unix time; runs settle by it too
        seen = parse_retained(self.view.snapshot(), self.topics, memo=self._memo)
        robots = self._robots(seen, now) if self.view.synced else None
        desired = self._desired_of(step)
        drift = self._drifts(desired, seen) if robots is not None else None
        if self.notifier is not None or self.keep is not None:
            digests = {r: d.digest for r, d in desired.items() if not d.suspended}
            since = {r: seen for r, (_, seen) in self._running_since.items()}
            self._told, events = transitions(
                self._told, Seen(step.status, robots, digests, since, drift, resumed_by), now
            )
            if self.notifier is not None:
                self.notifier.tell(events)
            self._noted, noted = timeline_transitions(
                self._noted, step.status, robots, now, self._started
            )
            if self.keep is not None:
                self.keep(noted + events)
        if self.metrics is not None and robots is not None and drift is not None:
            self.metrics.verdicts(verdict_counts(desired, robots, self.view.lost is not None))
            self.metrics.drift(drift)

    def _drifts(self, desired: Mapping[str, DesiredRobot], seen: Retained) -> dict[str, Drift]:
        """Each assigned, unsuspended robot's drift against what it should run."""
        found = {
            robot_id: robot_drift(
                robot_id, want, seen.robots.get(robot_id, RobotSeen()), self._drift
            )
            for robot_id, want in desired.items()
            if not want.suspended
        }
        self._drift.keep_only(found)
        return found

    def _robots(self, seen: Retained, now: float) -> dict[str, AgentStatus]:
        """The robots' statuses, and when each was first seen running."""
        statuses = {r: robot.status for r, robot in seen.robots.items() if robot.status}
        # A run is known by its digest and the agent's time of entering it: a brain that
        # crashed and runs again between two looks is a new run, not a settled one.
        previous, self._running_since = self._running_since, {}
        for robot_id, status in statuses.items():
            if status.state is AgentState.RUNNING and status.digest:
                run = (status.digest, status.since)
                known = previous.get(robot_id)
                self._running_since[robot_id] = (
                    known if known is not None and known[0] == run else (run, now)
                )
        return statuses

    def _desired_of(self, step: Step) -> dict[str, DesiredRobot]:
        serving = step.serving
        revision = serving.revision if serving is not None else None
        if revision != self._desired[0]:
            fleet = serving.fleet if serving is not None else None
            self._desired = (revision, desired_from_fleet(fleet) if fleet is not None else {})
            if self.keep_desired is not None and revision is not None and fleet is not None:
                self.keep_desired(revision, self._desired[1])
                heap.release()  # what writing 10,000 robots freed goes back, as after a build
        return self._desired[1]


def verdict_counts(
    desired: Mapping[str, DesiredRobot], robots: Mapping[str, AgentStatus], lost: bool = False
) -> dict[Verdict, int]:
    """Robots per verdict as `robotconf status` judges them, from their statuses alone: a
    desired request counts as published (the launch topics are the reconciler's own view).
    `lost`: the read is known to lack statuses the broker dropped; a robot without one is
    Unknown, not Offline, as `status` has it."""
    counts: collections.Counter[Verdict] = collections.Counter()
    for robot_id in set(desired) | set(robots):
        want = desired.get(robot_id)
        seen = RobotSeen(
            launch_digest=want.digest if want is not None else None,
            launch_retained=want is not None,
            status=robots.get(robot_id),
        )
        judged = verdict(want, seen)[0]
        if lost and judged is Verdict.OFFLINE and robot_id not in robots:
            judged = Verdict.UNKNOWN
        counts[judged] += 1
    return dict(counts)
