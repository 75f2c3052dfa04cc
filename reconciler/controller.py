"""The control loop: on a commit, a reconnect or every interval: source -> build -> diff -> apply.

Level-triggered and stateless: what is published is learned from the broker at every
(re)connection, so a restart or a broker that lost its retained messages is harmless.
"""

from __future__ import annotations

import enum
import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path
from typing import Literal, Protocol

from pydantic import ValidationError

from configurator.launch import LaunchRequest, StopRequest
from configurator.mqtt import Connection
from configurator.safejson import MAX_PAYLOAD_BYTES, PayloadError
from configurator.signing import Signed
from configurator.source import SourceError
from configurator.wire import ReconcilerReason, ReconcilerStatus, Topics, now
from reconciler.desired import Desired, load_desired
from reconciler.diff import Actions, diff
from reconciler.retained import Ignored, Presence, RetainedView, read_object, take_snapshot
from reconciler.source import BranchSource

log = logging.getLogger("robotconf.reconciler")

BACKOFF_INITIAL, BACKOFF_MAX = 1.0, 30.0
LOCAL_POLL = 1.0  # when refs cannot be watched, look at the branch this often
SAMPLE_TIMEOUT = 10.0  # seconds to wait for a sample of the robots' statuses
WILL_TIMEOUT = 10.0  # seconds to wait for the broker to take a new Last Will
# A request the agents would refuse for its size is a build error, not a publish: the echo of
# an oversized message is dropped on arrival and would be republished at every pass. The
# margin leaves room for the signature.
MAX_REQUEST_BYTES = MAX_PAYLOAD_BYTES - 4096

Builder = Callable[[Path, str], Desired]
Reason = ReconcilerReason


class Signer(Protocol):
    """Signs a launch or a stop request (configurator.signing.sign with the reconciler's key)."""

    def __call__(self, request: Signed, /) -> Signed: ...


class Outcome(enum.Enum):
    DONE = "done"  # the broker holds what the serving revision asks for
    WAIT = "wait"  # not connected: the next (re)connection wakes the loop
    RETRY = "retry"  # a failure worth retrying with backoff


def short(revision: str | None) -> str:
    return revision[:12] if revision else "none"


_BRAIN_STATES = {"starting", "running", "backoff", "stopping"}


def running_robots(
    retained: dict[str, bytes], topics: Topics, ignored: Ignored | None = None
) -> set[str]:
    """Robots whose retained status says a brain is up or about to be (online agents only)."""
    found = set()
    for topic, payload in retained.items():
        where = topics.robot_of(topic)
        if where is None or where[1] != "status" or not payload:
            continue
        try:
            state = read_object(payload).get("state")
        except PayloadError as exc:
            if ignored is not None:
                ignored.note("status", topic, payload, str(exc))
            continue
        if isinstance(state, str) and state in _BRAIN_STATES:
            found.add(where[0])
    return found


def observed_digests(
    retained: dict[str, bytes], topics: Topics, ignored: Ignored | None = None
) -> dict[str, str | None]:
    """robot -> digest of its retained launch request (None: retained but unreadable).

    A retained signed stop (a StopRequest for that robot) counts as nothing retained: the
    robot is cleared."""
    found: dict[str, str | None] = {}
    for topic, payload in retained.items():
        where = topics.robot_of(topic)
        if where is None or where[1] != "launch":
            continue
        try:
            raw = read_object(payload)
        except PayloadError as exc:
            if ignored is not None:
                ignored.note("launch", topic, payload, str(exc))
            found[where[0]] = None
            continue
        if _is_stop(raw, where[0]):
            continue
        digest = raw.get("digest")
        found[where[0]] = digest if isinstance(digest, str) else None
    return found


def _is_stop(raw: dict[str, object], robot_id: str) -> bool:
    if raw.get("kind") != "Stop":
        return False
    try:
        return StopRequest.model_validate(raw).robot_id == robot_id
    except ValidationError:
        return False


class Controller:
    """Makes the retained launch topics equal to the branch's head commit, until stopped.

    `builder` turns a commit into what it asks for (`load_desired`; a seam for tests)."""

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
        builder: Builder = load_desired,
    ) -> None:
        self.source = source
        self.connection = connection
        self.topics = Topics(prefix)
        self.interval = interval
        self.publish_timeout = publish_timeout
        self._on_reconciled = on_reconciled
        self._sign = signer
        self._builder = builder
        self._wake = threading.Event()
        self._stop = threading.Event()
        self.ignored = Ignored(log)  # unreadable payloads skipped, shown in the status
        # Statuses are not mirrored: during a rollout every robot reports several times, and
        # they matter only for the repair below (`_sample_running`), sampled now and then.
        self.view = RetainedView(
            connection,
            [self.topics.all_launch, self.topics.reconciler_status],
            f"{prefix}/sync",
            role="reconciler",
            on_synced=self._wake.set,
            on_topic=self._on_topic,
        )
        # The Last Will (state Offline) lives on a connection of its own: a will is fixed at
        # connect time, and this one must name the revision applied last.
        self.presence = Presence(connection, self.topics.reconciler_status, "reconciler-will")
        self._will_key: tuple[object, ...] | None = None
        self._sampled_connection = 0  # the view connection the last status sample was taken on
        self._built: OrderedDict[str, Desired] = OrderedDict()
        self._crashed: set[str] = set()  # revisions whose build raised: retried at each resync
        self.serving: Desired | None = None  # the last good revision, applied or being applied
        self.status: ReconcilerStatus | None = None
        self._status_payload: bytes | None = None  # what was published last, to know its echo
        self._head: str | None = None
        self._last_log: str | None = None
        self._waiting_logged = False
        self._recovered = False
        self._fetch_error: str | None = None

    # ------------------------------------------------------------------ loop

    def wake(self) -> None:
        self._wake.set()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()

    @property
    def stopped(self) -> bool:
        return self._stop.is_set()

    def run(self) -> None:
        """Runs until `stop()`; never raises for broker or repository trouble, nor for a bug in
        one step: that is logged with its traceback, reported, and retried with backoff."""
        self.view.start()
        try:
            poll = None if self._watch_source() else LOCAL_POLL
            next_resync = 0.0
            backoff = BACKOFF_INITIAL
            while not self._stop.is_set():
                self._wake.clear()
                now_ = time.monotonic()
                resync = now_ >= next_resync
                if resync:
                    next_resync = now_ + self.interval
                outcome = self._step(resync)
                if outcome is None:  # a bug: wait it out whatever wakes us, not to spin
                    self._stop.wait(backoff)
                    backoff = min(backoff * 2, BACKOFF_MAX)
                    continue
                waits = [max(0.0, next_resync - time.monotonic())]
                if poll is not None:
                    waits.append(poll)
                if outcome is Outcome.RETRY:
                    waits.append(backoff)
                    backoff = min(backoff * 2, BACKOFF_MAX)
                elif outcome is Outcome.DONE:
                    backoff = BACKOFF_INITIAL
                self._wake.wait(min(waits))
        finally:
            self._go_offline()
            self.view.stop()

    def _watch_source(self) -> bool:
        try:
            return self.source.watch(self.wake, self._stop)
        except Exception:
            log.exception("cannot watch %s; polling it instead", self.source.description)
            return False

    def _step(self, resync: bool) -> Outcome | None:
        """One reconcile step; None when it raised (a bug, logged and reported)."""
        try:
            return self.reconcile_once(fetch=resync)
        except Exception as exc:
            log.exception("internal error while reconciling; retrying with backoff")
            self._report_internal_error(exc)
            return None

    def _report_internal_error(self, exc: Exception) -> None:
        try:
            message = f"internal error: {type(exc).__name__}: {exc}"[:500]
            self._publish_status(
                self._status(
                    "Stalled",
                    Reason.INTERNAL_ERROR,
                    attempted=self._head,
                    failed=self._head,
                    message=f"{message} (see the reconciler's log); retrying",
                    errors=[message],
                )
            )
        except Exception:
            log.exception("cannot report the internal error either")

    def _on_topic(self, topic: str) -> None:
        """Network thread: an Offline status while we run (the Last Will of one of our
        connections that dropped, or of a broker shutting down) is replaced at once. Only
        Offline: two reconcilers on one prefix must not answer each other in a loop."""
        if topic != self.topics.reconciler_status:
            return
        payload = self.view.get(topic)
        if not payload or payload == self._status_payload:
            return
        try:
            offline = read_object(payload).get("state") == "Offline"
        except PayloadError:
            return
        if offline and not self._stop.is_set():
            self._wake.set()

    # ------------------------------------------------------------------ one step

    def reconcile_once(self, *, fetch: bool = False) -> Outcome:
        """Source -> build -> diff -> apply -> status, once."""
        if fetch:
            self._refresh()
        head: str | None = None
        try:
            resolved = self.source.head()
        except SourceError as exc:
            self._say(f"source: {exc}", logging.WARNING)
            desired = Desired("", None, [f"source unavailable: {exc}"])
        else:
            head = resolved
            desired = self._build(resolved)
        self._head = head
        if not self.view.synced:
            if not self._waiting_logged:
                log.info("waiting for the broker at %s", self.connection.address.url)
                self._waiting_logged = True
            return Outcome.WAIT
        self._waiting_logged = False
        self._recover_serving(head)

        snapshot = self.view.snapshot()
        observed = observed_digests(snapshot, self.topics, self.ignored)
        running = self._sample_running(fetch)
        errors = list(desired.errors)
        reason = self._failure(head)
        actions: Actions[LaunchRequest] | None = None
        if desired.fleet is not None:
            actions = diff(
                desired.fleet.requests,
                observed,
                desired.fleet.suspended,
                desired.fleet.allow_empty,
                running,
            )
            if actions.refused:
                errors = [actions.refused]
                reason = Reason.EMPTY_FLEET_REFUSED
                actions = None
        target = desired if actions is not None else self.serving
        if actions is None and target is not None and target.fleet is not None:
            # The head cannot be applied: keep serving (and refilling) the last good revision.
            actions = diff(target.fleet.requests, observed, target.fleet.suspended, True, running)
        if actions is not None and target is not None and not actions.empty:
            self._publish_status(
                self._status(
                    "Progressing",
                    Reason.PROGRESSING,
                    attempted=head,
                    failed=head if errors else None,
                    message=f"applying {short(target.revision)}",
                    errors=errors,
                )
            )
            started = time.monotonic()
            if not self._apply(actions, target.revision):
                self._publish_status(
                    self._status(
                        "Stalled",
                        Reason.BROKER_UNAVAILABLE,
                        attempted=head,
                        failed=target.revision,
                        message="the broker did not acknowledge every message; retrying: "
                        + (self.view.last_error or "timeout"),
                        errors=errors,
                    )
                )
                return Outcome.RETRY
            log.info(
                "applied %s: %d published, %d cleared, %d unchanged%s (%.3f s)",
                short(target.revision),
                len(actions.publish),
                len(actions.clear),
                actions.unchanged,
                f", {len(actions.held)} suspended left as they are" if actions.held else "",
                time.monotonic() - started,
            )
        if target is not None:
            self.serving = target
        self._publish_status(self._outcome(head, errors, reason, actions), heartbeat=fetch)
        return Outcome.RETRY if head is None else Outcome.DONE

    def _outcome(
        self,
        head: str | None,
        errors: list[str],
        reason: Reason,
        actions: Actions[LaunchRequest] | None,
    ) -> ReconcilerStatus:
        """The status after a step: stalled with why, stale after a failed fetch, or ready."""
        if errors:
            serving = f"; serving {short(self.serving.revision)}" if self.serving else ""
            what = f"revision {short(head)}" if head else "the branch"
            self._say(f"{what} is not applied ({len(errors)} error(s)){serving}", logging.WARNING)
            return self._status(
                "Stalled",
                reason,
                attempted=head,
                failed=head,
                message=f"{what} is not applied ({reason.value}){serving}",
                errors=errors,
                actions=actions,
            )
        if self._fetch_error:
            return self._status(
                "Stalled",
                Reason.SOURCE_UNAVAILABLE,
                attempted=head,
                message=f"applied {short(head)}, but the last fetch failed: it may be stale",
                errors=[self._fetch_error],
                actions=actions,
            )
        self._say(f"in sync with {short(head)} ({self.source.branch})", logging.INFO)
        return self._status(
            "Ready",
            Reason.APPLIED,
            attempted=head,
            message=f"applied {short(head)}",
            actions=actions,
        )

    def _failure(self, head: str | None) -> Reason:
        """Why the head is not applicable, if it is not."""
        if head is None:
            return Reason.SOURCE_UNAVAILABLE
        if head in self._crashed:
            return Reason.INTERNAL_ERROR
        return Reason.BUILD_FAILED

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
            log.info("built %s in %.3f s", short(revision), time.monotonic() - started)
            self._built[revision] = built
            while len(self._built) > 4:
                self._built.popitem(last=False)
        return built

    def _build_safely(self, revision: str) -> Desired:
        """Whatever the commit holds, a Desired: a bug in the build makes it one with errors."""
        try:
            built = self._builder(self.source.root, revision)
        except Exception as exc:
            log.exception("internal error while building %s", short(revision))
            self._crashed.add(revision)
            message = f"internal error while building {short(revision)}: {type(exc).__name__}"
            return Desired(revision, None, [f"{message}: {exc}"[:500]])
        if built.fleet is None:
            return built
        errors = [
            f"the launch request of {robot_id} is {size:,} bytes, over the {MAX_REQUEST_BYTES:,} "
            "an agent accepts; make its settings or environment knowledge smaller"
            for robot_id, request in sorted(built.fleet.requests.items())
            if (size := len(request.payload())) > MAX_REQUEST_BYTES
        ]
        return Desired(revision, None, errors) if errors else built

    def _sample_running(self, resync: bool) -> set[str]:
        """Robots whose agent says it runs a brain, sampled at each resync and after each
        (re)connection (when the broker may have lost the clears); empty otherwise.

        Only a robot that is running but no longer assigned is acted on (cleared again), so
        a sample is used once: between samples, a commit never clears anything twice."""
        connection = self.view.connections
        if not resync and connection == self._sampled_connection:
            return set()
        self._sampled_connection = connection
        statuses = take_snapshot(
            self.connection,
            [self.topics.all_status],
            f"{self.topics.prefix}/sync",
            role="reconciler-sample",
            timeout=SAMPLE_TIMEOUT,
        )
        if statuses is None:
            log.info("no status sample from the broker this time")
            return set()
        return running_robots(statuses, self.topics, self.ignored)

    def _recover_serving(self, head: str | None) -> None:
        """After a restart, the last good revision is the one the retained status names."""
        if self._recovered:
            return
        self._recovered = True
        previous = self._retained_status()
        if previous is None:
            return
        if self.status is None:
            self.status = previous
        revision = previous.last_applied_revision
        if self.serving is None and revision and revision != head:
            candidate = self._build(revision)
            if candidate.ok:
                self.serving = candidate

    def _retained_status(self) -> ReconcilerStatus | None:
        topic = self.topics.reconciler_status
        payload = self.view.get(topic)
        if not payload:
            return None
        try:
            return ReconcilerStatus.model_validate(read_object(payload))
        except (PayloadError, ValidationError) as exc:
            self.ignored.note("reconciler-status", topic, payload, _one_line(exc))
            return None

    def _apply(self, actions: Actions[LaunchRequest], revision: str) -> bool:
        # Signed at publish time: issued_at is when the robot was told, not when it was built.
        sign = self._sign
        items = [
            (self.topics.launch(r), (sign(req) if sign else req).payload())
            for r, req in actions.publish.items()
        ]
        items += [(self.topics.launch(r), self._stop_payload(r, revision)) for r in actions.clear]
        return self.view.publish_retained(items, self.publish_timeout)

    def _stop_payload(self, robot_id: str, revision: str) -> bytes:
        """Empty (DESIGN §7), or a signed StopRequest when requests are signed: an agent that
        verifies requests stops only for a stop it can verify."""
        if self._sign is None:
            return b""
        return self._sign(StopRequest(robot_id=robot_id, revision=revision)).payload()

    def _status(
        self,
        state: Literal["Ready", "Stalled", "Progressing"],
        reason: Reason,
        *,
        attempted: str | None,
        message: str,
        failed: str | None = None,
        errors: list[str] | None = None,
        actions: Actions[LaunchRequest] | None = None,
    ) -> ReconcilerStatus:
        previous = self.status
        serving = self.serving
        fleet = serving.fleet if serving is not None else None
        applied = serving.revision if serving is not None else None
        if applied is None and previous is not None:
            applied = previous.last_applied_revision
        published = len(actions.publish) if actions else 0
        cleared = len(actions.clear) if actions else 0
        quiet = not published and not cleared and state != "Progressing"
        if quiet and previous is not None and previous.last_applied_revision == applied:
            # A resync that changed nothing keeps the counts of the apply that did.
            published, cleared = previous.published, previous.cleared
        return ReconcilerStatus(
            state=state,
            ready=state == "Ready",
            reason=reason.value,
            branch=self.source.branch,
            source=self.source.description,
            last_applied_revision=applied,
            last_attempted_revision=attempted
            or (previous.last_attempted_revision if previous else None),
            failed_revision=failed,
            diagnostics=errors or [],
            message=message,
            robots=len(fleet.requests) if fleet is not None else 0,
            published=published,
            cleared=cleared,
            interval=self.interval,
        )

    def _publish_status(self, status: ReconcilerStatus, *, heartbeat: bool = False) -> None:
        """Retained; published when its content differs from what the broker holds, and at
        every resync (`heartbeat`) so that readers can tell a live reconciler from a dead one.
        `since` moves only when the content does."""
        status = status.model_copy(
            update={"heartbeat": now(), "ignored_payloads": self.ignored.counts()}
        )
        retained = self._retained_status()
        if retained is not None and _same(retained, status):
            status = status.model_copy(update={"since": retained.since})
            if not heartbeat and _same(retained, status, but={"heartbeat"}):
                self.status = retained
                self._notify(retained)
                return
        self._hold_will(status)
        self.status = status
        payload = status.model_dump_json().encode()
        self._status_payload = payload
        self.view.publish_retained([(self.topics.reconciler_status, payload)], 10.0)
        self._notify(status)

    def _offline(self, status: ReconcilerStatus, message: str) -> ReconcilerStatus:
        """The status that says the reconciler is gone; it keeps what it had applied."""
        return ReconcilerStatus(
            state="Offline",
            ready=False,
            reason=Reason.OFFLINE.value,
            branch=status.branch,
            source=status.source,
            last_applied_revision=status.last_applied_revision,
            last_attempted_revision=status.last_attempted_revision,
            message=message,
            robots=status.robots,
            interval=self.interval,
        )

    def _hold_will(self, status: ReconcilerStatus) -> None:
        """Keeps the Last Will naming the revision applied: a new will is a new connection, so
        only when what it says changes."""
        key = (status.last_applied_revision, status.robots, status.branch, status.source)
        if key == self._will_key:
            return
        will = self._offline(
            status, "the reconciler is offline: it died or lost the broker (its Last Will)"
        )
        if self.presence.hold(will.model_dump_json().encode(), WILL_TIMEOUT):
            self._will_key = key
        else:
            log.warning("the broker did not take the reconciler's Last Will; trying again later")

    def _go_offline(self) -> None:
        """On a clean stop the will is not sent: say offline ourselves, then leave."""
        try:
            if self.status is not None and self.view.synced:
                offline = self._offline(self.status, "the reconciler was stopped")
                payload = offline.model_dump_json().encode()
                self._status_payload = payload
                self.view.publish_retained([(self.topics.reconciler_status, payload)], 5.0)
        except Exception:
            log.exception("cannot publish the offline status")
        finally:
            self.presence.release()

    def _notify(self, status: ReconcilerStatus) -> None:
        if self._on_reconciled is None:
            return
        try:
            self._on_reconciled(status)
        except Exception:
            log.exception("the on_reconciled callback failed; ignored")

    def _say(self, message: str, level: int) -> None:
        """Logs a line once, not at every resync."""
        if message != self._last_log:
            log.log(level, "%s", message)
            self._last_log = message


_NOT_CONTENT = {"since", "published", "cleared", "heartbeat", "ignored_payloads"}


def _same(a: ReconcilerStatus, b: ReconcilerStatus, but: set[str] | None = None) -> bool:
    """Equal but for the fields in `but` (default: counts and times: `since` marks the last
    change that matters, and a heartbeat or a skipped payload is not one)."""
    exclude = _NOT_CONTENT if but is None else but
    return a.model_dump(exclude=exclude) == b.model_dump(exclude=exclude)


def _one_line(exc: Exception) -> str:
    return " ".join(str(exc).split())[:300]
