"""Status step: the reconciler's retained status — its one writer, its Last Will, its heartbeat.

`status_of` is pure (a step's condition -> the status message); `StatusWriter` publishes it
when it changed or a heartbeat is due, keeps the Last Will naming the revision applied, and
says Offline on a clean stop.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

from pydantic import ValidationError

from robotconf.configurator.rendered import RenderedRequest
from robotconf.contract.clock import now
from robotconf.contract.safejson import PayloadError
from robotconf.contract.wire import ReconcilerStatus, Topics
from robotconf.readmodel.observed import RECONCILER_STATUS
from robotconf.readmodel.retained import Ignored, Presence, RetainedView, read_object
from robotconf.reconciler.decide import Condition, Reason
from robotconf.reconciler.desired import Desired
from robotconf.reconciler.diff import Actions

log = logging.getLogger("robotconf.reconciler")

WILL_TIMEOUT = 10.0  # seconds to wait for the broker to take a new Last Will
PUBLISH_TIMEOUT = 10.0  # seconds to wait for the broker to acknowledge a status
# Not what a status says, but when and how often: a change of these alone is no change.
_NOT_CONTENT = {"since", "published", "cleared", "heartbeat", "ignored_payloads"}


@dataclass(frozen=True)
class Followed:
    """What the reconciler follows, as its status names it."""

    branch: str
    source: str  # a path, or a URL without credentials
    interval: float  # seconds between heartbeats


def status_of(
    condition: Condition,
    actions: Actions[RenderedRequest] | None,
    *,
    serving: Desired | None,
    head: str | None,
    previous: ReconcilerStatus | None,
    followed: Followed,
) -> ReconcilerStatus:
    """The status after a step: its condition, the revision serving, what the step changed."""
    fleet = serving.fleet if serving is not None else None
    applied = serving.revision if serving is not None else None
    if applied is None and previous is not None:
        applied = previous.last_applied_revision
    published = len(actions.publish) if actions else 0
    cleared = len(actions.clear) if actions else 0
    quiet = not published and not cleared and condition.reason is not Reason.PROGRESSING
    if quiet and previous is not None and previous.last_applied_revision == applied:
        # A resync that changed nothing keeps the counts of the apply that did.
        published, cleared = previous.published, previous.cleared
    return ReconcilerStatus(
        state=condition.state,
        ready=condition.reason is Reason.APPLIED,
        reason=condition.reason.value,
        branch=followed.branch,
        source=followed.source,
        last_applied_revision=applied,
        last_attempted_revision=head or (previous.last_attempted_revision if previous else None),
        failed_revision=condition.failed_revision,
        diagnostics=list(condition.diagnostics),
        more_diagnostics=condition.more_diagnostics,
        message=condition.message,
        robots=len(fleet.requests) if fleet is not None else 0,
        published=published,
        cleared=cleared,
        interval=followed.interval,
        rollout=condition.rollout,
        held=list(condition.held),
        more_held=condition.more_held,
    )


def offline_status(status: ReconcilerStatus, message: str) -> ReconcilerStatus:
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
        interval=status.interval,
        rollout=status.rollout,
        commits=status.commits,
    )


def same_content(a: ReconcilerStatus, b: ReconcilerStatus, but: set[str] | None = None) -> bool:
    """Equal but for the fields in `but` (default: counts and times: `since` marks the last
    change that matters, and a heartbeat or a skipped payload is not one)."""
    exclude = _NOT_CONTENT if but is None else but
    return a.model_dump(exclude=exclude) == b.model_dump(exclude=exclude)


class StatusWriter:
    """Publishes the reconciler status on the reconciler's own view of the broker."""

    def __init__(
        self,
        view: RetainedView,
        topics: Topics,
        presence: Presence,
        ignored: Ignored,
        on_written: Callable[[ReconcilerStatus], None] | None = None,
    ) -> None:
        self.view = view
        self.topic = topics.reconciler_status
        self.presence = presence
        self.ignored = ignored
        self._on_written = on_written
        self.status: ReconcilerStatus | None = None  # the last one written (or found)
        self._payload: bytes | None = None  # what was published last, to know its echo
        self._will_key: tuple[object, ...] | None = None
        # Why a read of the broker is known to be lossy (the controller asks all its views).
        self.lost: Callable[[], str | None] = lambda: view.lost

    def is_echo(self, payload: bytes) -> bool:
        return payload == self._payload

    def retained(self) -> ReconcilerStatus | None:
        """The status the broker holds; None when there is none or it is unreadable."""
        payload = self.view.get(self.topic)
        if not payload:
            return None
        try:
            return ReconcilerStatus.model_validate(read_object(payload))
        except (PayloadError, ValidationError) as exc:
            self.ignored.note(RECONCILER_STATUS, self.topic, payload, one_line(exc))
            return None

    def write(self, status: ReconcilerStatus, *, heartbeat: bool = False) -> None:
        """Published when its content differs from what the broker holds, and at every resync
        (`heartbeat`) so that readers can tell a live reconciler from a dead one. `since`
        moves only when the content does."""
        status = status.model_copy(
            update={
                "heartbeat": now(),
                "ignored_payloads": self.ignored.counts(),
                "broker_dropped": self.lost(),
            }
        )
        retained = self.retained()
        if retained is not None and same_content(retained, status):
            status = status.model_copy(update={"since": retained.since})
            if not heartbeat and same_content(retained, status, but={"heartbeat"}):
                self.status = retained
                self._notify(retained)
                return
        self._hold_will(status)
        self.status = status
        self._publish(status, PUBLISH_TIMEOUT)
        self._notify(status)

    def go_offline(self) -> None:
        """On a clean stop the will is not sent: say offline ourselves, then leave."""
        try:
            if self.status is not None and self.view.synced:
                self._publish(offline_status(self.status, "the reconciler was stopped"), 5.0)
        except Exception:
            log.exception("cannot publish the offline status")
        finally:
            self.presence.release()

    def _publish(self, status: ReconcilerStatus, timeout: float) -> None:
        payload = status.model_dump_json().encode()
        self._payload = payload
        self.view.publish_retained([(self.topic, payload)], timeout)

    def _hold_will(self, status: ReconcilerStatus) -> None:
        """Keeps the Last Will naming the revision applied: a new will is a new connection, so
        only when what it says changes."""
        rollout = status.rollout
        # A restarted reconciler resumes a rollout from the status it finds, which after a
        # crash is this will: it must name the current wave and when it started.
        where = (
            (rollout.revision, rollout.state, rollout.wave, rollout.wave_started_at)
            if rollout
            else None
        )
        key = (status.last_applied_revision, status.robots, status.branch, status.source, where)
        if key == self._will_key:
            return
        will = offline_status(
            status, "the reconciler is offline: it died or lost the broker (its Last Will)"
        )
        if self.presence.hold(will.model_dump_json().encode(), WILL_TIMEOUT):
            self._will_key = key
        else:
            log.warning("the broker did not take the reconciler's Last Will; trying again later")

    def _notify(self, status: ReconcilerStatus) -> None:
        if self._on_written is None:
            return
        try:
            self._on_written(status)
        except Exception:
            log.exception("the on_reconciled callback failed; ignored")


def one_line(exc: Exception) -> str:
    return " ".join(str(exc).split())[:300]
