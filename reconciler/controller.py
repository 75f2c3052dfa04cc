"""The control loop: on a commit, a reconnect or every interval: source -> build -> diff -> apply.

Level-triggered and stateless: what is published is learned from the broker at every
(re)connection, so a restart or a broker that lost its retained messages is harmless.
"""

from __future__ import annotations

import enum
import json
import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Literal

from pydantic import ValidationError

from configurator.launch import LaunchRequest
from configurator.mqtt import Connection
from configurator.source import SourceError
from configurator.wire import ReconcilerStatus, Topics
from reconciler.desired import Desired, load_desired
from reconciler.diff import Actions, diff
from reconciler.retained import RetainedView, take_snapshot
from reconciler.source import BranchSource

log = logging.getLogger("robotconf.reconciler")

BACKOFF_INITIAL, BACKOFF_MAX = 1.0, 30.0
LOCAL_POLL = 1.0  # when refs cannot be watched, look at the branch this often
SAMPLE_TIMEOUT = 10.0  # seconds to wait for a sample of the robots' statuses


class Outcome(enum.Enum):
    DONE = "done"  # the broker holds what the serving revision asks for
    WAIT = "wait"  # not connected: the next (re)connection wakes the loop
    RETRY = "retry"  # a failure worth retrying with backoff


def short(revision: str | None) -> str:
    return revision[:12] if revision else "none"


_BRAIN_STATES = {"starting", "running", "backoff", "stopping"}


def running_robots(retained: dict[str, bytes], topics: Topics) -> set[str]:
    """Robots whose retained status says a brain is up or about to be (online agents only)."""
    found = set()
    for topic, payload in retained.items():
        where = topics.robot_of(topic)
        if where is None or where[1] != "status" or not payload:
            continue
        try:
            state = json.loads(payload).get("state")
        except (ValueError, AttributeError):
            continue
        if state in _BRAIN_STATES:
            found.add(where[0])
    return found


def observed_digests(retained: dict[str, bytes], topics: Topics) -> dict[str, str | None]:
    """robot -> digest of its retained launch request (None: retained but unreadable)."""
    found: dict[str, str | None] = {}
    for topic, payload in retained.items():
        where = topics.robot_of(topic)
        if where is None or where[1] != "launch":
            continue
        try:
            digest = json.loads(payload).get("digest")
        except (ValueError, AttributeError):
            digest = None
        found[where[0]] = digest if isinstance(digest, str) else None
    return found


class Controller:
    """Makes the retained launch topics equal to the branch's head commit, until stopped."""

    def __init__(
        self,
        source: BranchSource,
        connection: Connection,
        prefix: str,
        interval: float,
        *,
        publish_timeout: float = 60.0,
        on_reconciled: Callable[[ReconcilerStatus], None] | None = None,
        signer: Callable[[LaunchRequest], LaunchRequest] | None = None,
    ) -> None:
        self.source = source
        self.connection = connection
        self.topics = Topics(prefix)
        self.interval = interval
        self.publish_timeout = publish_timeout
        self._on_reconciled = on_reconciled
        self._sign = signer
        self._wake = threading.Event()
        self._stop = threading.Event()
        # Statuses are not mirrored: during a rollout every robot reports several times, and
        # they matter only for the repair below (`_sample_running`), sampled now and then.
        self.view = RetainedView(
            connection,
            [self.topics.all_launch, self.topics.reconciler_status],
            f"{prefix}/sync",
            role="reconciler",
            on_synced=self._wake.set,
        )
        self._sampled_connection = 0  # the view connection the last status sample was taken on
        self._built: OrderedDict[str, Desired] = OrderedDict()
        self.serving: Desired | None = None  # the last good revision, applied or being applied
        self.status: ReconcilerStatus | None = None
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
        """Runs until `stop()`; never raises for broker or repository trouble."""
        self.view.start()
        try:
            watching = self.source.watch(self.wake, self._stop)
            poll = None if watching else LOCAL_POLL
            next_resync = 0.0
            backoff = BACKOFF_INITIAL
            while not self._stop.is_set():
                self._wake.clear()
                now = time.monotonic()
                resync = now >= next_resync
                if resync:
                    next_resync = now + self.interval
                outcome = self.reconcile_once(fetch=resync)
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
            self.view.stop()

    # ------------------------------------------------------------------ one step

    def reconcile_once(self, *, fetch: bool = False) -> Outcome:
        """Source -> build -> diff -> apply -> status, once."""
        if fetch:
            try:
                self.source.refresh()
                self._fetch_error = None
            except SourceError as exc:
                # Keep going with what the cache holds; the status says it is stale.
                self._fetch_error = str(exc)
                self._say(f"source: {exc}", logging.WARNING)
        head: str | None = None
        try:
            resolved = self.source.head()
        except SourceError as exc:
            self._say(f"source: {exc}", logging.WARNING)
            desired = Desired("", None, [f"source unavailable: {exc}"])
        else:
            head = resolved
            desired = self._build(resolved)
        if not self.view.synced:
            if not self._waiting_logged:
                log.info("waiting for the broker at %s", self.connection.address.url)
                self._waiting_logged = True
            return Outcome.WAIT
        self._waiting_logged = False
        self._recover_serving(head)

        snapshot = self.view.snapshot()
        observed = observed_digests(snapshot, self.topics)
        running = self._sample_running(fetch)
        errors = list(desired.errors)
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
                actions = None
        target = desired if actions is not None else self.serving
        if actions is None and target is not None and target.fleet is not None:
            # The head cannot be applied: keep serving (and refilling) the last good revision.
            actions = diff(target.fleet.requests, observed, target.fleet.suspended, True, running)
        if actions is not None and target is not None and not actions.empty:
            self._publish_status(
                self._status(
                    "Progressing",
                    attempted=head,
                    message=f"applying {short(target.revision)}",
                    errors=errors,
                )
            )
            started = time.monotonic()
            if not self._apply(actions):
                self._publish_status(
                    self._status(
                        "Stalled",
                        attempted=head,
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
        if errors:
            serving = f"; serving {short(self.serving.revision)}" if self.serving else ""
            what = f"revision {short(head)}" if head else "the branch"
            self._say(f"{what} is not applied ({len(errors)} error(s)){serving}", logging.WARNING)
            status = self._status(
                "Stalled",
                attempted=head,
                message=f"{what} is not applied{serving}",
                errors=errors,
                actions=actions,
            )
        elif self._fetch_error:
            status = self._status(
                "Stalled",
                attempted=head,
                message=f"applied {short(head)}, but the last fetch failed: it may be stale",
                errors=[self._fetch_error],
                actions=actions,
            )
        else:
            self._say(f"in sync with {short(head)} ({self.source.branch})", logging.INFO)
            status = self._status(
                "Ready", attempted=head, message=f"applied {short(head)}", actions=actions
            )
        self._publish_status(status)
        return Outcome.RETRY if head is None else Outcome.DONE

    # ------------------------------------------------------------------ helpers

    def _build(self, revision: str) -> Desired:
        """A commit never changes: build each one once (the last few are kept)."""
        built = self._built.get(revision)
        if built is None:
            started = time.monotonic()
            built = load_desired(self.source.root, revision)
            log.info("built %s in %.3f s", short(revision), time.monotonic() - started)
            self._built[revision] = built
            while len(self._built) > 4:
                self._built.popitem(last=False)
        return built

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
        return running_robots(statuses, self.topics)

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
        payload = self.view.snapshot().get(self.topics.reconciler_status)
        if not payload:
            return None
        try:
            return ReconcilerStatus.model_validate_json(payload)
        except ValidationError:
            return None

    def _apply(self, actions: Actions[LaunchRequest]) -> bool:
        # Signed at publish time: issued_at is when the robot was told, not when it was built.
        sign = self._sign or (lambda request: request)
        items = [(self.topics.launch(r), sign(req).payload()) for r, req in actions.publish.items()]
        items += [(self.topics.launch(r), b"") for r in actions.clear]
        return self.view.publish_retained(items, self.publish_timeout)

    def _status(
        self,
        state: Literal["Ready", "Stalled", "Progressing"],
        *,
        attempted: str | None,
        message: str,
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
            branch=self.source.branch,
            source=self.source.description,
            last_applied_revision=applied,
            last_attempted_revision=attempted
            or (previous.last_attempted_revision if previous else None),
            diagnostics=errors or [],
            message=message,
            robots=len(fleet.requests) if fleet is not None else 0,
            published=published,
            cleared=cleared,
        )

    def _publish_status(self, status: ReconcilerStatus) -> None:
        """Retained; published only when its content differs from what the broker holds."""
        retained = self._retained_status()
        if retained is not None and _same(retained, status):
            status = status.model_copy(update={"since": retained.since})
            if status == retained:
                self.status = status
                self._notify(status)
                return
        self.status = status
        self.view.publish_retained(
            [(self.topics.reconciler_status, status.model_dump_json().encode())], 10.0
        )
        self._notify(status)

    def _notify(self, status: ReconcilerStatus) -> None:
        if self._on_reconciled is not None:
            self._on_reconciled(status)

    def _say(self, message: str, level: int) -> None:
        """Logs a line once, not at every resync."""
        if message != self._last_log:
            log.log(level, "%s", message)
            self._last_log = message


def _same(a: ReconcilerStatus, b: ReconcilerStatus) -> bool:
    """Equal but for the counts and the time: `since` marks the last change that matters."""
    exclude = {"since", "published", "cleared"}
    return a.model_dump(exclude=exclude) == b.model_dump(exclude=exclude)
