"""Decide step, pure: what the source and the broker show -> what to publish and what to report.

Every outcome of a reconcile step is decided here, with a reason from one enum, so that a rule
such as "an invalid head keeps the last good revision serving" lives in one place and is tested
without a broker.
"""

from __future__ import annotations

from collections.abc import Mapping, Set
from dataclasses import dataclass, field

from configurator.launch import LaunchRequest
from configurator.wire import ReconcilerReason, ReconcilerState, StatusDiagnostic, short_rev
from reconciler.desired import Desired
from reconciler.diff import Actions, diff

Reason = ReconcilerReason

# The state a reason puts the reconciler in; every other reason means it is stalled.
_STATE_OF: dict[ReconcilerReason, ReconcilerState] = {
    Reason.APPLIED: "Ready",
    Reason.PROGRESSING: "Progressing",
    Reason.OFFLINE: "Offline",
}


def state_of(reason: Reason) -> ReconcilerState:
    return _STATE_OF.get(reason, "Stalled")


@dataclass(frozen=True)
class Observation:
    """What one step saw: the branch's head and its build, and what the broker holds."""

    head: str | None  # None: the source could not be read
    build: Desired  # the head's build, or why there is none
    build_crashed: bool = False  # the build raised: a bug, not the commit's fault
    fetch_error: str | None = None  # the last fetch failed: the head may be stale
    serving: Desired | None = None  # the last good revision, applied or being applied
    launches: Mapping[str, str | None] = field(default_factory=dict)  # robot -> digest held
    active: Set[str] = frozenset()  # robots whose agent says a brain is up


@dataclass(frozen=True)
class Condition:
    """The reconciler's condition after a step, as its status reports it."""

    reason: Reason
    message: str
    failed_revision: str | None = None
    diagnostics: tuple[StatusDiagnostic, ...] = ()
    more_diagnostics: int = 0

    @property
    def state(self) -> ReconcilerState:
        return state_of(self.reason)


@dataclass(frozen=True)
class Decision:
    """What to make the broker hold (`target`, through `actions`) and what to report."""

    target: Desired | None
    actions: Actions[LaunchRequest] | None
    condition: Condition

    @property
    def changes(self) -> bool:
        return self.actions is not None and not self.actions.empty

    def progressing(self) -> Condition:
        """Reported while the changes are published: the outcome is not known yet."""
        assert self.target is not None
        return Condition(
            Reason.PROGRESSING,
            f"applying {short_rev(self.target.revision)}",
            self.condition.failed_revision,
            self.condition.diagnostics,
            self.condition.more_diagnostics,
        )

    def unacknowledged(self, error: str | None) -> Condition:
        """The outcome when the broker did not acknowledge every message in time."""
        assert self.target is not None
        return Condition(
            Reason.BROKER_UNAVAILABLE,
            "the broker did not acknowledge every message; retrying: " + (error or "timeout"),
            self.target.revision,
            self.condition.diagnostics,
            self.condition.more_diagnostics,
        )


def decide(seen: Observation) -> Decision:
    """The head when it can be applied, else the last good revision kept (and refilled)."""
    build = seen.build
    problems = list(build.problems)
    reason = _failure(seen)
    actions: Actions[LaunchRequest] | None = None
    if build.fleet is not None:
        fleet = build.fleet
        actions = diff(
            fleet.requests, seen.launches, fleet.suspended, fleet.allow_empty, seen.active
        )
        if actions.refused:
            problems = [
                StatusDiagnostic(
                    path="configs/fleet.yaml",
                    code=Reason.EMPTY_FLEET_REFUSED.value,
                    message=actions.refused,
                )
            ]
            reason = Reason.EMPTY_FLEET_REFUSED
            actions = None
    target = build if actions is not None else seen.serving
    if actions is None and target is not None and target.fleet is not None:
        fleet = target.fleet
        actions = diff(fleet.requests, seen.launches, fleet.suspended, True, seen.active)
    return Decision(target, actions, _condition(seen, target, problems, reason, build.omitted))


def _failure(seen: Observation) -> Reason:
    """Why the head is not applicable, should it not be."""
    if seen.head is None:
        return Reason.SOURCE_UNAVAILABLE
    if seen.build_crashed:
        return Reason.INTERNAL_ERROR
    return Reason.BUILD_FAILED


def _condition(
    seen: Observation,
    target: Desired | None,
    problems: list[StatusDiagnostic],
    reason: Reason,
    omitted: int,
) -> Condition:
    head = seen.head
    if problems:
        serving = f"; serving {short_rev(target.revision)}" if target is not None else ""
        what = f"revision {short_rev(head)}" if head else "the branch"
        return Condition(
            reason,
            f"{what} is not applied ({reason.value}){serving}",
            head,
            tuple(problems),
            omitted,
        )
    if seen.fetch_error is not None:
        return Condition(
            Reason.SOURCE_UNAVAILABLE,
            f"applied {short_rev(head)}, but the last fetch failed: it may be stale",
            None,
            (StatusDiagnostic(code=Reason.SOURCE_UNAVAILABLE.value, message=seen.fetch_error),),
        )
    return Condition(Reason.APPLIED, f"applied {short_rev(head)}")


def internal_error(exc: Exception, head: str | None) -> Condition:
    """A step raised: a bug, not the commit's fault. Reported; the step is retried."""
    message = f"internal error: {type(exc).__name__}: {exc}"[:500]
    return Condition(
        Reason.INTERNAL_ERROR,
        f"{message} (see the reconciler's log); retrying",
        head,
        (StatusDiagnostic(code=Reason.INTERNAL_ERROR.value, message=message),),
    )
