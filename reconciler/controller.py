"""The control loop: on a commit, a reconnect or every interval, one reconcile step.

A step is Flux-shaped: observe (the branch's head and its build, the retained topics) ->
decide (pure, `reconciler.decide`) -> apply (publish and clear) -> report (the one status
writer). Level-triggered and stateless: what is published is learned from the broker at every
(re)connection, so a restart or a broker that lost its retained messages is harmless.
"""

from __future__ import annotations

import collections
import enum
import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from pydantic import ValidationError

from configurator.render import FleetRender
from configurator.rendered import RenderedRequest
from configurator.source import SourceError
from contract.backoff import Backoff
from contract.interfaces import Reported
from contract.launch import LaunchRequest, StopRequest
from contract.mqtt import Connection
from contract.notes import VerdictNote
from contract.safejson import MAX_PAYLOAD_BYTES, PayloadError
from contract.signing import Signed
from contract.topics import Role, subscriptions
from contract.wire import (
    AgentState,
    AgentStatus,
    OperatorAnswer,
    ReconcilerStatus,
    StatusDiagnostic,
    Topics,
    is_commit,
    is_online,
    short_rev,
)
from reconciler import heap
from reconciler.commits import CommitBook, named_revisions
from reconciler.decide import Condition, Decision, Observation, Reason, decide, internal_error
from reconciler.desired import FLEET_FILE, Desired, DesiredBuilder
from reconciler.diff import Actions
from reconciler.evidence import Counts, WaveEvidence
from reconciler.evidence_feed import EvidenceCounter
from reconciler.notes_store import NotesError, NotesStore
from reconciler.observed import (
    RECONCILER_STATUS,
    WAVE_RECORD,
    LaunchDigests,
    ReadMemo,
    launch_summary,
    parse_retained,
    summarise_launches,
)
from reconciler.operator_actions import Refused, judge_action
from reconciler.report import Followed, StatusWriter, one_line, status_of
from reconciler.retained import (
    Ignored,
    Payload,
    Presence,
    RetainedView,
    read_object,
    take_snapshot_said,
)
from reconciler.rollout import stage_bases
from reconciler.source import BranchSource
from reconciler.wave_memory import WaveRecord

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

log = logging.getLogger("robotconf.reconciler")
ROLLOUT_ACTION = "rollout-action"  # an operator's rollout action (reconciler.operator_actions)
MAX_WAITING_ACTIONS = 16  # operator actions waiting for the loop; a flood beyond is dropped

BACKOFF_INITIAL, BACKOFF_MAX = 1.0, 30.0
LOCAL_POLL = 1.0  # when refs cannot be watched, look at the branch this often
SAMPLE_TIMEOUT = 10.0  # seconds to wait for a sample of the robots' statuses
# A request the agents would refuse for its size is a build error, not a publish: the echo of
# an oversized message is dropped on arrival and would be republished at every pass. The
# margin leaves room for the signature.
MAX_REQUEST_BYTES = MAX_PAYLOAD_BYTES - 4096

Builder = Callable[[Path, str], Desired]


class Signer(Protocol):
    """Signs a launch or a stop request (contract.signing.sign with the reconciler's key)."""

    def __call__(self, request: Signed, /) -> Signed: ...


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
    # in place (the rest of the state, containers and views, is made in __init__).
    serving: Desired | None = None  # the last good revision, applied or being applied
    _head: str | None = None
    _last_log: str | None = None
    _waiting_logged = False
    _recovered = False
    _found: ReconcilerStatus | None = None  # the retained status found at start
    _fetch_error: str | None = None

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
        self._sign = signer
        self._builder = builder if builder is not None else DesiredBuilder()
        self._on_step = on_step  # must return at once: it runs on the reconcile loop
        self._wake = threading.Event()
        self._resync_asked = threading.Event()  # a push announced (webhook): fetch now
        self._stop = threading.Event()
        self.ignored = Ignored(log)  # unreadable payloads skipped, shown in the status
        self.view = self._launch_view(no_local)
        self.writer = self._status_writer(on_reconciled)
        self.followed = Followed(source.branch, source.description, interval)
        # The robots' statuses, followed live only while the head has a rollout policy: the
        # waves are gated by them. Without one they are only sampled (`_sample_active`).
        self.health: RetainedView | None = None
        # The robots' interfaces, followed only while fleet.yaml says `drift: hold`.
        self.interfaces: RetainedView | None = None
        self._interfaces_memo = ReadMemo()
        # robot -> (its run, first seen running so): a run is a digest in one brain process
        # entered at one time (the agent's, compared only with itself), so a brain that crashed
        # and runs again between two looks is a new run, not a settled one.
        self._running_since: dict[str, tuple[tuple[str, int | None, float], float]] = {}
        self._watched = 0  # the health view's connection whose statuses were learned last
        self._watching_since = 0.0  # when they were: a rollout's clock counts from then
        # robot -> when first seen dark (offline, or its status gone) on that connection
        self._dark_since: dict[str, float] = {}
        self._had_status: set[str] = set()  # robots with a status on that connection
        # What a rollout's current wave established: this process's, or the retained one
        # found at start; and what the broker holds of it.
        self._wave_record: WaveRecord | None = None
        self._wave_record_held: bytes | None = None
        self._recheck_at: float | None = None  # unix time a rollout's health judgment changes
        self._sampled_connection = 0  # the view connection the last status sample was taken on
        self._built: OrderedDict[str, Desired] = OrderedDict()
        # What the retained launch requests' digests are, while they stay the same: a step
        # reads only the requests that changed since the step before.
        self._launches = LaunchDigests(self.topics)
        self._sizes = RequestSizes()
        self._health_memo = ReadMemo()
        self._crashed: set[str] = set()  # revisions whose build raised: retried at each resync
        self._verification_state(ledger, verifier)

    def _verification_state(self, ledger: Path | None, verifier: Ed25519PublicKey | None) -> None:
        """What a rollout's evidence and decisions need: the outcome ledger's rows counted into
        the current wave's evidence, the verdicts kept as git notes on the commits rolled out,
        and operators' actions as they arrive (bounded: a flood is dropped, counted), judged
        on the loop, the answer to the last one in the rollout's status."""
        self._stage_built: dict[str, Desired] = {}  # revisions a stage keeps (_stage_builds)
        self._commits = CommitBook(self.source.root)  # what the status's revisions are
        self._evidence = EvidenceCounter(ledger) if ledger is not None else None
        self.notes = NotesStore(self.source.root)
        self._notes_failed = False
        self._verifier = verifier
        self._actions: collections.deque[bytes] = collections.deque(maxlen=MAX_WAITING_ACTIONS)
        self._actions_lock = threading.Lock()
        self._answer: OperatorAnswer | None = None
        self._verdicts: tuple[VerdictNote, ...] = ()  # reached by the current step

    def _launch_view(self, no_local: bool) -> RetainedView:
        """The retained launch topics and the reconciler's own, mirrored. Statuses are not:
        during a rollout every robot reports several times, and they matter only for the
        repair (`_sample_active`), sampled now and then."""
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
            self._follow_health(False)
            self._follow_interfaces(False)
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
        self._verdicts = ()  # a step that raised reached none
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
                    self._verdicts,
                )
            )
        except Exception:
            log.exception("the on_step observer failed; ignored")

    def _on_topic(self, topic: str) -> None:
        """Network thread: an Offline status while we run (the Last Will of one of our
        connections that dropped, or of a broker shutting down) is replaced at once. Only
        Offline: two reconcilers on one prefix must not answer each other in a loop."""
        if topic == self.topics.rollout_request:
            self._action_arrived(self.view.get(topic))
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

    def _action_arrived(self, payload: bytes | None) -> None:
        """Network thread: an operator's rollout action, kept for the loop to judge."""
        if not payload:
            return
        with self._actions_lock:
            if len(self._actions) == self._actions.maxlen:
                self.ignored.note(
                    ROLLOUT_ACTION, self.topics.rollout_request, payload, "too many at once"
                )
                return
            self._actions.append(payload)
        self._wake.set()

    def _take_actions(self) -> None:
        """Judges the operators' actions that arrived, against the rollout as it stands; one
        carried out is a git note on the revision, read by the step that follows."""
        with self._actions_lock:
            waiting = list(self._actions)
            self._actions.clear()
        status = self.writer.status
        for payload in waiting:
            found = judge_action(
                payload, status.rollout if status else None, time.time(), self._verifier
            )
            if isinstance(found, Refused):
                if found.answer is None:
                    self.ignored.note(
                        ROLLOUT_ACTION, self.topics.rollout_request, payload, found.why
                    )
                else:
                    log.warning(
                        "refused %s by %s: %s",
                        found.answer.action,
                        found.answer.requested_by,
                        found.why,
                    )
                    self._answer = found.answer
                continue
            try:
                self.notes.append([found.note])
            except NotesError as exc:
                why = f"cannot keep the decision as a git note: {exc}"
                log.warning("%s", why)
                self._answer = found.answer.model_copy(update={"accepted": False, "message": why})
                continue
            log.info("%s", found.note.message)
            self._answer = found.answer

    # ------------------------------------------------------------------ one step

    def reconcile_once(
        self, *, fetch: bool = False
    ) -> tuple[Outcome, Condition | None, Actions[RenderedRequest] | None]:
        """Observe (source, broker) -> decide (pure) -> apply, once: what happened and the
        condition to report (none while the broker's retained messages are not known)."""
        seen = self._observe(fetch)
        if seen is None:
            return Outcome.WAIT, None, None
        if self._actions:
            self._take_actions()
            seen = self._observe(False)  # with the notes they added
            if seen is None:
                return Outcome.WAIT, None, None
        decision = decide(seen)
        self._keep_wave_record(decision.wave_record)
        self._keep_verdicts(decision.verdicts)
        self._verdicts = decision.verdicts
        condition = self._answered(decision.condition)
        if decision.changes:
            condition = self._apply(decision)
        self._recheck_at = decision.recheck_at
        if condition.reason is Reason.BROKER_UNAVAILABLE:
            return Outcome.RETRY, condition, decision.actions
        if decision.stable is not None:
            self.serving = decision.stable
        return (Outcome.RETRY if seen.head is None else Outcome.DONE), condition, decision.actions

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
        policy = build.fleet if build.fleet is not None else self._serving_fleet()
        hold = policy is not None and policy.drift == "hold"
        interfaces = self._follow_interfaces(hold)
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
        stage_builds = self._stage_builds(build, previous)
        evidence, baseline, notes = self._verification(build, previous, head, stage_builds)
        return Observation(
            head=head,
            build=build,
            build_crashed=head in self._crashed,
            fetch_error=self._fetch_error,
            serving=self.serving,
            launches=self._launches.update(self.view.snapshot(), self.ignored),
            active=self._sample_active(fetch),
            previous_rollout=previous.rollout if previous is not None else None,
            statuses=self._follow_health(rollout, now),
            statuses_lost=self.health.lost if self.health is not None else None,
            running_since={robot: seen for robot, (_, seen) in self._running_since.items()},
            now=now,
            wave_record=self._wave_record,
            watching_since=self._watching_since,
            dark_since=dict(self._dark_since),
            interfaces=interfaces,
            evidence=evidence,
            baseline=baseline,
            notes=notes,
            stage_builds=stage_builds,
        )

    def _stage_builds(
        self, build: Desired, previous: ReconcilerStatus | None
    ) -> dict[str, FleetRender]:
        """fleet.yaml stages: the builds of the revisions the stages' robots keep
        (`stage_bases`, read from the retained rollout) other than the serving one; each built
        once and kept while a stage keeps it. One that cannot be built is left out: its stage
        keeps the serving revision."""
        fleet, rollout = build.fleet, previous.rollout if previous is not None else None
        if fleet is None or fleet.rollout is None or not fleet.stages or rollout is None:
            self._stage_built.clear()
            return {}
        serving = self.serving.revision if self.serving is not None else None
        wanted = {
            base
            for base in stage_bases(fleet, rollout, serving)
            if base is not None and base != serving and is_commit(base)
        }
        for gone in self._stage_built.keys() - wanted:
            del self._stage_built[gone]
        found: dict[str, FleetRender] = {}
        for revision in wanted:
            made = build if revision == build.revision else self._stage_built.get(revision)
            if made is None:
                made = self._stage_built[revision] = self._build_safely(revision)
            if made.fleet is not None:
                found[revision] = made.fleet
        return found

    def _verification(
        self,
        build: Desired,
        previous: ReconcilerStatus | None,
        head: str | None,
        stage_builds: dict[str, FleetRender],
    ) -> tuple[WaveEvidence | None, dict[str, Counts], list[VerdictNote]]:
        """What a rollout of the head is judged on beyond health: its wave's goal outcomes
        (rollout.verify) and the notes on its commit (an operator's resume or abort)."""
        fleet = build.fleet
        rollout = previous.rollout if previous is not None else None
        if fleet is None or fleet.rollout is None or head is None:
            return None, {}, []
        notes: list[VerdictNote] = []
        if rollout is not None and rollout.revision == head:
            try:
                notes = self.notes.read(head)
                self._notes_failed = False
            except NotesError as exc:
                if not self._notes_failed:
                    log.warning("%s", exc)
                    self._notes_failed = True
        judged = fleet.rollout.verify is not None or any(s.soak for s in fleet.stages)
        if self._evidence is None or not judged:
            return None, {}, notes
        stable = self.serving.fleet if self.serving is not None else None
        counted = self._evidence.count(fleet, stable, rollout, stage_builds)
        return counted.evidence, counted.baseline, notes

    def _answered(self, condition: Condition) -> Condition:
        """The condition with the answer to the last operator action about its rollout."""
        rollout, answer = condition.rollout, self._answer
        if rollout is None or answer is None:
            return condition
        return replace(condition, rollout=rollout.model_copy(update={"answer": answer}))

    def _keep_verdicts(self, verdicts: tuple[VerdictNote, ...]) -> None:
        """The step's verdicts, as git notes on their commits; a failure is said and the
        verdict noted again at a later step (a verdict is recomputed the same from the ledger)."""
        if not verdicts:
            return
        try:
            self.notes.append(verdicts)
        except NotesError as exc:
            log.warning("cannot keep the rollout's verdict as a git note: %s", exc)
            return
        for note in verdicts:
            if note.verdict is not None:
                log.info(
                    "wave %s of %s: %s%s (%s)",
                    note.wave_name,
                    short_rev(note.revision),
                    note.verdict,
                    " [dry run]" if note.dry_run else "",
                    note.message,
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
        return head, self._build(head)

    def _serving_fleet(self) -> FleetRender | None:
        return self.serving.fleet if self.serving is not None else None

    def _follow_interfaces(self, wanted: bool) -> dict[str, Reported] | None:
        """The robots' readable interfaces reports, followed only while fleet.yaml says
        `drift: hold` (None until they are known, or when not followed)."""
        if wanted and self.interfaces is None:
            self.interfaces = RetainedView(
                self.connection,
                subscriptions(Role.RECONCILER, self.topics.prefix, "interfaces"),
                self.topics.sync,
                role="reconciler-interfaces",
                on_synced=self._wake.set,
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
            self.topics,
            ignored=self.ignored,
            memo=self._interfaces_memo,
        )
        return {r: robot.interfaces for r, robot in seen.robots.items() if robot.interfaces}

    def _lost(self) -> str | None:
        """Why one of this reconciler's reads is known to lack retained messages, or None."""
        views = [self.view, self.health, self.interfaces]
        return next((v.lost for v in views if v is not None and v.lost is not None), None)

    def _on_interfaces(self) -> None:
        """Network thread: a robot's interfaces changed; a robot held for drift may fit now."""
        status = self.writer.status
        if status is not None and status.held and not self._stop.is_set():
            self._wake.set()

    def _follow_health(self, wanted: bool, now: float = 0.0) -> dict[str, AgentStatus] | None:
        """The robots' statuses while a rollout policy is in force (None until they are
        known), and when each robot was first seen running its digest."""
        if wanted and self.health is None:
            self.health = RetainedView(
                self.connection,
                subscriptions(Role.RECONCILER, self.topics.prefix, "status"),
                self.topics.sync,
                role="reconciler-health",
                on_synced=self._wake.set,
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
            self._watching_since = now
            self._dark_since.clear()
            self._had_status.clear()
        seen = parse_retained(
            self.health.snapshot(), self.topics, ignored=self.ignored, memo=self._health_memo
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
        status = self.writer.status
        rollout = status.rollout if status is not None else None
        if rollout is not None and rollout.state == "Progressing" and not self._stop.is_set():
            self._wake.set()

    def _keep_wave_record(self, record: WaveRecord | None) -> None:
        """Remembers what the wave established, and has the broker keep it (retained) before
        anything of the step is published: a reconciler killed after this step finds it."""
        self._wave_record = record
        payload = record.model_dump_json().encode() if record is not None else b""
        if payload == (self._wave_record_held or b""):
            return
        if self.view.publish_retained(
            [(self.topics.reconciler_rollout, payload)], self.publish_timeout
        ):
            self._wave_record_held = payload
        else:  # kept here all the same; the broker is told at the next step
            log.warning("the broker did not take the rollout's wave record; trying again")

    def _apply(self, decision: Decision) -> Condition:
        """Publishes what differs and clears what is no longer assigned; the outcome."""
        actions, target = decision.actions, decision.target
        assert actions is not None and target is not None
        self._report(decision.progressing(), actions)
        started = time.monotonic()
        # Signed at publish time: issued_at is when the robot was told, not when it was built.
        # Each payload is made as it is sent (`Payload`): 10,000 are never held at once.
        sign = self._sign
        items: list[tuple[str, Payload]] = [
            (self.topics.launch(r), _signed(sign, req) if sign else req.payload)
            for r, req in actions.publish.items()
        ]
        # What the view keeps of each request is known without reading it back; a Stop's,
        # the view's own `keep` works out.
        kept: list[bytes | None] = [
            launch_summary("LaunchRequest", req.digest) for req in actions.publish.values()
        ]
        for r in actions.clear:
            items.append((self.topics.launch(r), self._stop_payload(r, target.revision)))
            kept.append(None)
        publishing = time.monotonic()
        acknowledged = self.view.publish_retained(items, self.publish_timeout, kept)
        done = time.monotonic()
        del items, kept  # 10,000 payloads: freed, then given back to the system
        heap.release()
        if not acknowledged:
            return decision.unacknowledged(self.view.last_error)
        log.info(
            "applied %s: %d published, %d cleared, %d unchanged%s (%.3f s; publishing, first "
            "message to last PUBACK, %.3f s)",
            short_rev(target.revision),
            len(actions.publish),
            len(actions.clear),
            actions.unchanged,
            f", {len(actions.held)} suspended left as they are" if actions.held else "",
            done - started,
            done - publishing,
        )
        return decision.condition

    # ------------------------------------------------------------------ helpers

    def _refresh(self) -> None:
        try:
            self.source.refresh()
            self._fetch_error = None
        except SourceError as exc:
            # Keep going with what the cache holds; the status says it is stale.
            self._fetch_error = str(exc)
            self._say(f"source: {exc}", logging.WARNING)
        for revision in self._crashed:  # a build that raised is tried again, once an interval
            self._built.pop(revision, None)
        self._crashed.clear()

    def _build(self, revision: str) -> Desired:
        """A commit never changes: build each one once (the last few are kept)."""
        built = self._built.get(revision)
        if built is None:
            started = time.monotonic()
            built = self._build_safely(revision)
            heap.release()  # what the build parsed and dropped
            log.info("built %s in %.3f s", short_rev(revision), time.monotonic() - started)
            self._built[revision] = built
            # The head and the revision served (a rollout's stable one): each kept build holds
            # a fleet's requests, and an incremental build of any other is cheap.
            while len(self._built) > 2:
                self._built.popitem(last=False)
        return built

    def _build_safely(self, revision: str) -> Desired:
        """Whatever the commit holds, a Desired: a bug in the build makes it one with errors."""
        try:
            built = self._builder(self.source.root, revision)
        except Exception as exc:
            log.exception("internal error while building %s", short_rev(revision))
            self._crashed.add(revision)
            message = f"internal error while building {short_rev(revision)}: {type(exc).__name__}"
            problem = StatusDiagnostic(
                code=Reason.INTERNAL_ERROR.value, message=f"{message}: {exc}"[:500]
            )
            return Desired(revision, None, [problem])
        if built.fleet is None:
            return built
        # As kept: 10,000 requests are not stamped with the revision to be measured.
        requests, revision = built.fleet.requests.as_kept(), built.fleet.requests.revision
        measure = self._sizes.size
        over = [
            (robot_id, size)
            for robot_id, request in requests
            if (size := measure(request, revision)) > MAX_REQUEST_BYTES
        ]
        problems = [
            StatusDiagnostic(
                path=FLEET_FILE,
                code=Reason.BUILD_FAILED.value,
                message=f"the launch request of {robot_id} is {size:,} bytes, over the "
                f"{MAX_REQUEST_BYTES:,} an agent accepts; make its settings or environment "
                "knowledge smaller",
            )
            for robot_id, size in sorted(over)
        ]
        self._sizes.keep_only(request for _, request in requests)
        return Desired(revision, None, problems) if problems else built

    def _sample_active(self, resync: bool) -> set[str]:
        """Robots whose agent says a brain is up or about to be, sampled at each resync and
        after each (re)connection (when the broker may have lost the clears); empty otherwise.

        Only a robot that is running but no longer assigned is acted on (cleared again), so
        a sample is used once: between samples, a commit never clears anything twice."""
        connection = self.view.connections
        if not resync and connection == self._sampled_connection:
            return set()
        self._sampled_connection = connection
        statuses, lost = take_snapshot_said(
            self.connection,
            subscriptions(Role.RECONCILER, self.topics.prefix, "status"),
            self.topics.sync,
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
        return parse_retained(statuses, self.topics, ignored=self.ignored).active()

    def _recover_serving(self, head: str | None) -> None:
        """After a restart, the last good revision is the one the retained status names."""
        if self._recovered:
            return
        self._recovered = True
        self._wave_record, self._wave_record_held = self._retained_wave_record()
        previous = self.writer.retained()
        if previous is None:
            return
        self._found = previous
        if self.writer.status is None:
            self.writer.status = previous
        revision = previous.last_applied_revision
        if self.serving is None and revision and revision != head:
            candidate = self._build(revision)
            if candidate.ok:
                self.serving = candidate

    def _retained_wave_record(self) -> tuple[WaveRecord | None, bytes | None]:
        """The wave record the broker holds (a reconciler before this one left it), and its
        payload; an unreadable one is skipped, counted, and replaced at the next change."""
        topic = self.topics.reconciler_rollout
        payload = self.view.get(topic)
        if not payload:
            return None, None
        try:
            return WaveRecord.model_validate(read_object(payload)), payload
        except (PayloadError, ValidationError) as exc:
            self.ignored.note(WAVE_RECORD, topic, payload, one_line(exc))
            return None, payload

    def _stop_payload(self, robot_id: str, revision: str) -> bytes:
        """Empty (docs/architecture.md#the-mqtt-contract), or a signed StopRequest when requests
        are signed: an agent that verifies requests stops only for a stop it can verify."""
        if self._sign is None:
            return b""
        return self._sign(StopRequest(robot_id=robot_id, revision=revision)).payload()

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
            self._say(condition.message, logging.WARNING)
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


def _signed(sign: Signer, request: RenderedRequest) -> Callable[[], bytes]:
    """What makes the request's signed payload when it is sent."""
    return lambda: sign(request.model()).payload()


class RequestSizes:
    """The published size of each request, worked out once per content: requests with one
    digest differ only in their revision (a commit id: letters and digits, written as they are
    in JSON), so a commit that changes ten robots serialises ten requests to check their size,
    not the whole fleet."""

    def __init__(self) -> None:
        self._without_revision: dict[str, int] = {}

    def size(self, request: RenderedRequest | LaunchRequest, revision: str | None = None) -> int:
        """`revision`: the one the request is published with, when not its own (a request a
        fleet kept from an earlier commit: FleetRequests)."""
        own = request.revision
        target = own if revision is None else revision
        if not (_plain(own) and _plain(target)):  # escapes would make its length another
            if target != own:
                assert isinstance(request, RenderedRequest)
                request = request.with_revision(target)
            return len(request.payload())
        base = self._without_revision.get(request.digest)
        if base is None:
            base = len(request.payload()) - len(own)
            self._without_revision[request.digest] = base
        return base + len(target)

    def keep_only(self, requests: Iterable[RenderedRequest | LaunchRequest]) -> None:
        digests = {r.digest for r in requests}
        self._without_revision = {d: n for d, n in self._without_revision.items() if d in digests}


def _plain(revision: str) -> bool:
    """Written in JSON as it is (a commit id: letters and digits)."""
    return revision.isascii() and revision.isalnum()
