"""The control loop: on a commit, a reconnect or every interval, one reconcile step.

A step is Flux-shaped: observe (the branch's head and its build, the retained topics) ->
decide (pure, `reconciler.decide`) -> apply (publish and clear) -> report (the one status
writer). Level-triggered and stateless: what is published is learned from the broker at every
(re)connection, so a restart or a broker that lost its retained messages is harmless.

The controller's state is a few named parts, each with one owner: the builds
(`reconciler.builds`), the look at the robots (`reconciler.robot_watch`), the rollout memory
(`reconciler.rollout_memory`), the delivery (`reconciler.delivery`), the launch view and the
status writer (`readmodel.retained`, `reconciler.report`); the controller itself keeps only
what its steps learned.
"""

from __future__ import annotations

import enum
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from pydantic import ValidationError

from robotconf.configurator.rendered import RenderedRequest
from robotconf.configurator.source import SourceError
from robotconf.contract.backoff import Backoff
from robotconf.contract.mqtt import Connection
from robotconf.contract.notes import VerdictNote
from robotconf.contract.safejson import PayloadError
from robotconf.contract.topics import Role, subscriptions
from robotconf.contract.wire import ReconcilerStatus, StatusDiagnostic, Topics, short_rev
from robotconf.readmodel.commits import CommitBook, named_revisions
from robotconf.readmodel.observed import (
    RECONCILER_STATUS,
    LaunchDigests,
    summarise_launches,
)
from robotconf.readmodel.retained import Ignored, Presence, RetainedView, read_object
from robotconf.reconciler.builds import Builder, Builds
from robotconf.reconciler.decide import (
    HANDLING,
    Condition,
    Decision,
    Observation,
    Reason,
    Retry,
    decide,
    internal_error,
    retry_of,
)
from robotconf.reconciler.delivery import Delivery, Signer
from robotconf.reconciler.desired import Desired
from robotconf.reconciler.diff import Actions
from robotconf.reconciler.report import Followed, StatusWriter, one_line, status_of
from robotconf.reconciler.robot_watch import RobotWatch
from robotconf.reconciler.rollout_memory import RolloutMemory
from robotconf.reconciler.source import BranchSource

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

log = logging.getLogger("robotconf.reconciler")

BACKOFF_INITIAL, BACKOFF_MAX = 1.0, 30.0
LOCAL_POLL = 1.0  # when refs cannot be watched, look at the branch this often


@dataclass(frozen=True)
class Step:
    """What one step did, as its `on_step` observer (alerts, metrics) is told after its report."""

    status: ReconcilerStatus | None  # the status the step reported
    serving: Desired | None  # the last good revision, applied or being applied
    reason: Reason
    published: int  # launch requests handed to the broker
    cleared: int  # launch topics cleared
    seconds: float  # how long the step took, report included
    # The status the broker held when this reconciler started (a previous one's), if any.
    found: ReconcilerStatus | None = None
    # The rollout verdicts this step reached (as kept in git notes): metrics count each once.
    verdicts: tuple[VerdictNote, ...] = ()


class Outcome(enum.Enum):
    DONE = "done"  # the broker holds what the serving revision asks for
    WAIT = "wait"  # not connected: the next (re)connection wakes the loop
    RETRY = "retry"  # a failure worth retrying with backoff


class Controller:
    """Makes the retained launch topics equal to the branch's head commit, until stopped.

    `builder` turns a commit into what it asks for (by default a `DesiredBuilder`, whose
    cache lives as long as the controller; a seam for tests). `no_local` (for a broker that
    speaks MQTT 5) spares the reconciler the echo of every request it publishes."""

    # What the steps have learned, nothing before the first: each replaced, never changed
    # in place (the rest of the state, the parts, is made in __init__).
    serving: Desired | None = None  # the last good revision, applied or being applied
    _head: str | None = None
    _last_log: str | None = None
    _waiting_logged = False
    _recovered = False
    _found: ReconcilerStatus | None = None  # the retained status found at start
    _fetch_error: str | None = None
    _recheck_at: float | None = None  # unix time a rollout's health judgment changes

    def __init__(
        self,
        source: BranchSource,
        connection: Connection,
        prefix: str,
        interval: float,
        *,
        publish_timeout: float = 60.0,
        on_reconciled: Callable[[ReconcilerStatus], None] | None = None,
        signer: Signer | None = None,
        builder: Builder | None = None,
        on_step: Callable[[Step], None] | None = None,
        no_local: bool = False,
        ledger: Path | None = None,
        verifier: Ed25519PublicKey | None = None,
    ) -> None:
        self.source = source
        self.connection = connection
        self.topics = Topics(prefix)
        self.interval = interval
        self.publish_timeout = publish_timeout
        self._on_step = on_step  # must return at once: it runs on the reconcile loop
        self._wake = threading.Event()
        self._resync_asked = threading.Event()  # a push announced (webhook): fetch now
        self._stop = threading.Event()
        self.ignored = Ignored(log)  # unreadable payloads skipped, shown in the status
        self.view = self._launch_view(no_local)
        self.writer = self._status_writer(on_reconciled)
        self.followed = Followed(source.branch, source.description, interval)
        self.delivery = Delivery(self.view, self.topics, signer, publish_timeout)
        # The parts, each the one owner of its state.
        self.builds = Builds(source.root, builder)
        self.robots = RobotWatch(
            connection, self.topics, self.ignored, self._wake.set, self._stop, self._status
        )
        self.rollouts = RolloutMemory(source.root, self.topics, self.ignored, ledger, verifier)
        self._commits = CommitBook(source.root)  # what the status's revisions are
        # What the retained launch requests' digests are, while they stay the same: a step
        # reads only the requests that changed since the step before.
        self._launches = LaunchDigests(self.topics)

    def _status(self) -> ReconcilerStatus | None:
        return self.writer.status

    def _launch_view(self, no_local: bool) -> RetainedView:
        """The retained launch topics and the reconciler's own, mirrored. Statuses are not:
        during a rollout every robot reports several times, and they matter only for the
        repair (`RobotWatch.sample_active`), sampled now and then."""
        return RetainedView(
            self.connection,
            subscriptions(
                Role.RECONCILER,
                self.topics.prefix,
                "launch",
                "reconciler_status",
                "reconciler_rollout",
                "rollout_request",
            ),
            self.topics.sync,
            role="reconciler",
            on_synced=self._wake.set,
            on_topic=self._on_topic,
            no_local=no_local,
            keep=summarise_launches(self.topics),
        )

    def _status_writer(
        self, on_reconciled: Callable[[ReconcilerStatus], None] | None
    ) -> StatusWriter:
        """The one status writer. Its Last Will (state Offline) lives on a connection of its
        own: a will is fixed at connect time, and this one must name the revision applied
        last."""
        presence = Presence(self.connection, self.topics.reconciler_status, "reconciler-will")
        writer = StatusWriter(self.view, self.topics, presence, self.ignored, on_reconciled)
        writer.lost = self._lost
        return writer

    # ------------------------------------------------------------------ loop

    def wake(self) -> None:
        self._wake.set()

    def resync_now(self) -> None:
        """Any thread (a webhook's push): the next step fetches and resyncs, as at the end of an
        interval, and the interval starts again from it. Pushes faster than steps make one."""
        self._resync_asked.set()
        self._wake.set()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()

    def run(self) -> None:
        """Runs until `stop()`; never raises for broker or repository trouble, nor for a bug in
        one step: that is logged with its traceback, reported, and retried with backoff."""
        self.view.start()
        try:
            poll = None if self._watch_source() else LOCAL_POLL
            next_resync = 0.0
            backoff = Backoff(BACKOFF_INITIAL, BACKOFF_MAX)
            while not self._stop.is_set():
                self._wake.clear()
                now_ = time.monotonic()
                resync = now_ >= next_resync
                if self._resync_asked.is_set():
                    # Cleared before the fetch: a push told until then is fetched by this step,
                    # one told later wakes the next; none is lost.
                    self._resync_asked.clear()
                    resync = True
                if resync:
                    next_resync = now_ + self.interval
                outcome = self._step(resync)
                if outcome is None:  # a bug: wait it out whatever wakes us, not to spin
                    self._stop.wait(backoff.next())
                    continue
                waits = [max(0.0, next_resync - time.monotonic())]
                if poll is not None:
                    waits.append(poll)
                if self._recheck_at is not None:
                    waits.append(max(0.0, self._recheck_at - time.time()))
                if outcome is Outcome.RETRY:
                    waits.append(backoff.next())
                elif outcome is Outcome.DONE:
                    backoff.reset()
                self._wake.wait(min(waits))
        finally:
            self.writer.go_offline()
            self.robots.stop()
            self.view.stop()

    def _watch_source(self) -> bool:
        try:
            return self.source.watch(self.wake, self._stop)
        except Exception:
            log.exception("cannot watch %s; polling it instead", self.source.description)
            return False

    def _step(self, resync: bool) -> Outcome | None:
        """One reconcile step, then its report: the step's one status write, whatever happened.
        None when the step raised (a bug: logged with its traceback, reported, retried)."""
        started = time.monotonic()
        outcome: Outcome | None
        self.rollouts.new_step()
        try:
            outcome, condition, actions = self.reconcile_once(fetch=resync)
        except Exception as exc:
            log.exception("internal error while reconciling; retrying with backoff")
            outcome, condition, actions = None, internal_error(exc, self._head), None
        if condition is None:  # waiting for the broker: nothing can be written
            return outcome
        try:
            self._report(condition, actions, heartbeat=resync)
        except Exception:
            log.exception("cannot report the reconciler status")
            return None
        self._tell_step(condition, actions, time.monotonic() - started)
        return outcome

    def _tell_step(
        self, condition: Condition, actions: Actions[RenderedRequest] | None, seconds: float
    ) -> None:
        """The `on_step` observer learns what the step did; its failure is only logged."""
        if self._on_step is None:
            return
        try:
            self._on_step(
                Step(
                    self.writer.status,
                    self.serving,
                    condition.reason,
                    len(actions.publish) if actions else 0,
                    len(actions.clear) if actions else 0,
                    seconds,
                    self._found,
                    self.rollouts.verdicts,
                )
            )
        except Exception:
            log.exception("the on_step observer failed; ignored")

    def _on_topic(self, topic: str) -> None:
        """Network thread: an Offline status while we run (the Last Will of one of our
        connections that dropped, or of a broker shutting down) is replaced at once. Only
        Offline: two reconcilers on one prefix must not answer each other in a loop."""
        if topic == self.topics.rollout_request:
            if self.rollouts.action_arrived(self.view.get(topic)):
                self._wake.set()
            return
        if topic != self.topics.reconciler_status:
            return
        payload = self.view.get(topic)
        if not payload or self.writer.is_echo(payload):
            return
        try:
            offline = ReconcilerStatus.model_validate(read_object(payload)).state == "Offline"
        except (PayloadError, ValidationError) as exc:
            # Counted as it arrives: our next status may replace it before a step reads it.
            self.ignored.note(RECONCILER_STATUS, topic, payload, one_line(exc))
            return
        if offline and not self._stop.is_set():
            self._wake.set()

    # ------------------------------------------------------------------ one step

    def reconcile_once(
        self, *, fetch: bool = False
    ) -> tuple[Outcome, Condition | None, Actions[RenderedRequest] | None]:
        """Observe (source, broker) -> decide (pure) -> apply, once: what happened and the
        condition to report (none while the broker's retained messages are not known)."""
        seen = self._observe(fetch)
        if seen is None:
            return Outcome.WAIT, None, None
        if self.rollouts.actions_waiting:
            self.rollouts.take_actions(self.writer.status)
            seen = self._observe(False)  # with the notes they added
            if seen is None:
                return Outcome.WAIT, None, None
        decision = decide(seen)
        self.rollouts.keep_wave_record(decision.wave_record, self.view, self.publish_timeout)
        self.rollouts.keep_verdicts(decision.verdicts)
        condition = self.rollouts.answered(decision.condition)
        if decision.changes:
            condition = self._apply(decision)
        self._recheck_at = decision.recheck_at
        # Not acknowledged: not delivered, so not served.
        if decision.stable is not None and condition.reason is not Reason.BROKER_UNAVAILABLE:
            self.serving = decision.stable
        backoff = retry_of(condition.reason) is Retry.BACKOFF  # the table decides (HANDLING)
        return (Outcome.RETRY if backoff else Outcome.DONE), condition, decision.actions

    def _observe(self, fetch: bool) -> Observation | None:
        """The head commit and its build, and what the broker holds; None until the broker's
        retained messages are known (the next (re)connection wakes the loop)."""
        if fetch:
            self._refresh()
        head, build = self._head_and_build()
        self._head = head
        if not self.view.synced:
            if not self._waiting_logged:
                log.info("waiting for the broker at %s", self.connection.address.url)
                self._waiting_logged = True
            return None
        self._waiting_logged = False
        self._recover_serving(head)
        serving = self.serving.fleet if self.serving is not None else None
        policy = build.fleet if build.fleet is not None else serving
        hold = policy is not None and policy.drift == "hold"
        interfaces = self.robots.follow_interfaces(hold)
        if hold and interfaces is None:
            # Holding needs the robots' reports: nothing is published before they are known
            # (the view's sync wakes the loop), as no wave starts before the statuses are.
            if not self._waiting_logged:
                log.info("waiting for the robots' interfaces (drift: hold)")
                self._waiting_logged = True
            return None
        now = time.time()
        rollout = build.fleet is not None and build.fleet.rollout is not None
        previous = self.writer.status
        stage_builds = self.builds.stage_builds(build, previous, self.serving)
        evidence, baseline, notes = self.rollouts.verification(
            build, previous, head, stage_builds, self.serving
        )
        return Observation(
            head=head,
            build=build,
            build_crashed=self.builds.crashed(head),
            fetch_error=self._fetch_error,
            serving=self.serving,
            launches=self._launches.update(self.view.snapshot(), self.ignored),
            unsigned=self._launches.unsigned if self.delivery.signs else frozenset(),
            active=self.robots.sample_active(fetch, self.view.connections),
            previous_rollout=previous.rollout if previous is not None else None,
            statuses=self.robots.follow_health(rollout, now),
            statuses_lost=self.robots.health.lost if self.robots.health is not None else None,
            running_since=self.robots.running_since,
            now=now,
            wave_record=self.rollouts.wave_record,
            watching_since=self.robots.watching_since,
            dark_since=self.robots.dark_since,
            interfaces=interfaces,
            evidence=evidence,
            baseline=baseline,
            notes=notes,
            stage_builds=stage_builds,
        )

    def _head_and_build(self) -> tuple[str | None, Desired]:
        """The branch's head commit and its build; no head, and a build saying why, when the
        source cannot be read."""
        try:
            head = self.source.head()
        except SourceError as exc:
            self._say(f"source: {exc}", logging.WARNING)
            problem = StatusDiagnostic(code=Reason.SOURCE_UNAVAILABLE.value, message=str(exc))
            return None, Desired("", None, [problem])
        return head, self.builds.build(head)

    def _lost(self) -> str | None:
        """Why one of this reconciler's reads is known to lack retained messages, or None."""
        views = [self.view, *self.robots.views()]
        return next((v.lost for v in views if v.lost is not None), None)

    def _apply(self, decision: Decision) -> Condition:
        """Reports the step progressing, then delivers what differs; the outcome."""
        assert decision.actions is not None
        self._report(decision.progressing(), decision.actions)
        return self.delivery.publish(decision)

    # ------------------------------------------------------------------ helpers

    def _refresh(self) -> None:
        try:
            self.source.refresh()
            self._fetch_error = None
        except SourceError as exc:
            # Keep going with what the cache holds; the status says it is stale.
            self._fetch_error = str(exc)
            self._say(f"source: {exc}", logging.WARNING)
        self.builds.retry_crashed()  # a build that raised is tried again, once an interval

    def _recover_serving(self, head: str | None) -> None:
        """After a restart, the last good revision is the one the retained status names."""
        if self._recovered:
            return
        self._recovered = True
        self.rollouts.recover_wave_record(self.view)
        previous = self.writer.retained()
        if previous is None:
            return
        self._found = previous
        if self.writer.status is None:
            self.writer.status = previous
        revision = previous.last_applied_revision
        if self.serving is None and revision and revision != head:
            candidate = self.builds.build(revision)
            if candidate.ok:
                self.serving = candidate

    # ------------------------------------------------------------------ report

    @property
    def status(self) -> ReconcilerStatus | None:
        """The reconciler status last written (or found on the broker at start)."""
        return self.writer.status

    def _report(
        self,
        condition: Condition,
        actions: Actions[RenderedRequest] | None,
        *,
        heartbeat: bool = False,
    ) -> None:
        """The step's outcome, logged once and written to the retained status."""
        if condition.state == "Stalled" and condition.reason is not Reason.BROKER_UNAVAILABLE:
            self._say(f"{condition.message}; {HANDLING[condition.reason].says}", logging.WARNING)
        elif condition.reason is Reason.APPLIED:
            self._say(f"in sync with {short_rev(self._head)} ({self.source.branch})", logging.INFO)
        status = status_of(
            condition,
            actions,
            serving=self.serving,
            head=self._head,
            previous=self.writer.status,
            followed=self.followed,
        )
        commits = self._commits.lines(named_revisions(status))
        self.writer.write(status.model_copy(update={"commits": commits}), heartbeat=heartbeat)

    def _say(self, message: str, level: int) -> None:
        """Logs a line once, not at every resync."""
        if message != self._last_log:
            log.log(level, "%s", message)
            self._last_log = message
