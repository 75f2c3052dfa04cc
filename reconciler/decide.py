"""Decide step, pure: what the source and the broker show -> what to publish and what to report.

Every outcome of a reconcile step is decided here, with a reason from one enum, so that a rule
such as "an invalid head keeps the last good revision serving" lives in one place and is tested
without a broker.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence, Set
from dataclasses import dataclass, field, replace

from robotconf.configurator.drift import Drift, drift_of, needs_of_rendered
from robotconf.configurator.render import FleetRender
from robotconf.configurator.rendered import RenderedRequest
from robotconf.contract.interfaces import Reported
from robotconf.contract.notes import VerdictNote
from robotconf.contract.wire import (
    MAX_LISTED,
    AgentStatus,
    HeldRobot,
    ReconcilerReason,
    ReconcilerState,
    RolloutStatus,
    StatusDiagnostic,
    short_rev,
)
from robotconf.reconciler.desired import Desired
from robotconf.reconciler.diff import Actions, diff
from robotconf.reconciler.evidence import Counts, WaveEvidence
from robotconf.reconciler.rollout import RolloutInput, RolloutStep, roll_out
from robotconf.reconciler.wave_memory import WaveRecord

Reason = ReconcilerReason

# The state a reason puts the reconciler in; every other reason means it is stalled.
_STATE_OF: dict[ReconcilerReason, ReconcilerState] = {
    Reason.APPLIED: "Ready",
    Reason.PROGRESSING: "Progressing",
    Reason.ROLLOUT_PAUSED: "Progressing",
    Reason.OFFLINE: "Offline",
}


def state_of(reason: Reason) -> ReconcilerState:
    return _STATE_OF.get(reason, "Stalled")


class Retry(enum.Enum):
    """What the loop does about a step's reason (as a Flux reason is retried or stalls)."""

    NONE = "none"  # nothing failed: the next commit, push, report or interval moves it on
    BACKOFF = "backoff"  # a fault outside the commit that may pass: tried again soon, backing off
    RESYNC = "resync"  # tried again when the branch moves or at the next resync, which fetches
    TERMINAL = "terminal"  # never retried: only a new commit or an operator's action ends it


@dataclass(frozen=True)
class Handling:
    retry: Retry
    says: str  # what the reconciler's log adds to a stalled step's message


# Retry or terminal, per reason: the one place it is decided (the controller reads it).
HANDLING: Mapping[Reason, Handling] = {
    Reason.APPLIED: Handling(Retry.NONE, "in sync"),
    Reason.PROGRESSING: Handling(Retry.NONE, "the broker's and the robots' answers move it on"),
    Reason.ROLLOUT_PAUSED: Handling(
        Retry.TERMINAL, "waits for fleet.yaml or an operator to resume the rollout"
    ),
    Reason.BUILD_FAILED: Handling(Retry.TERMINAL, "not retried: a new commit mends it"),
    Reason.EMPTY_FLEET_REFUSED: Handling(
        Retry.TERMINAL, "not retried: a new commit (or `allow_empty: true`) mends it"
    ),
    # Only a fetch or a moved branch can mend it: a sooner retry would read the same cache.
    Reason.SOURCE_UNAVAILABLE: Handling(
        Retry.RESYNC, "read again when the branch moves, and fetched again at the next resync"
    ),
    Reason.BROKER_UNAVAILABLE: Handling(Retry.BACKOFF, "retried with backoff"),
    # A build that raised is built again at each resync (a step that raised: with backoff).
    Reason.INTERNAL_ERROR: Handling(
        Retry.RESYNC, "a bug: tried again (a build, at the next resync)"
    ),
    Reason.OFFLINE: Handling(Retry.NONE, "the reconciler is not running"),
    Reason.ROLLOUT_HALTED: Handling(
        Retry.TERMINAL, "not retried: a new commit or an operator's action ends it"
    ),
    Reason.ROLLED_BACK: Handling(
        Retry.TERMINAL, "not retried: a new commit or an operator's action ends it"
    ),
}


def retry_of(reason: Reason) -> Retry:
    return HANDLING[reason].retry


@dataclass(frozen=True)
class Observation:
    """What one step saw: the branch's head and its build, and what the broker holds."""

    head: str | None  # None: the source could not be read
    build: Desired  # the head's build, or why there is none
    build_crashed: bool = False  # the build raised: a bug, not the commit's fault
    fetch_error: str | None = None  # the last fetch failed: the head may be stale
    serving: Desired | None = None  # the last good revision, applied or being applied
    launches: Mapping[str, str | None] = field(default_factory=dict)  # robot -> digest held
    unsigned: Set[str] = frozenset()  # robots held unsigned while the reconciler signs
    active: Set[str] = frozenset()  # robots whose agent says a brain is up
    # For rollouts: where the last one stood, the robots' statuses (None: not known yet),
    # when each robot was first seen running its digest, and the time now.
    previous_rollout: RolloutStatus | None = None
    statuses: Mapping[str, AgentStatus] | None = None
    running_since: Mapping[str, float] = field(default_factory=dict)
    now: float = 0.0
    # What the current wave established, and when the statuses were last (re)learned.
    wave_record: WaveRecord | None = None
    watching_since: float = 0.0
    dark_since: Mapping[str, float] = field(default_factory=dict)  # robot -> first seen dark
    statuses_lost: str | None = None  # how the statuses' read is known to lack messages
    # The robots' readable interfaces reports, followed while fleet.yaml says `drift: hold`
    # (None: not followed; a robot absent reports nothing readable: never held).
    interfaces: Mapping[str, Reported] | None = None
    # rollout.verify: the current wave's goal outcomes, counted from the ledger; the stable
    # revision's own counts per scenario; the verdict notes of the head's commit.
    evidence: WaveEvidence | None = None
    baseline: Mapping[str, Counts] = field(default_factory=dict)
    notes: Sequence[VerdictNote] = ()
    # fleet.yaml stages: builds of the revisions a stage's robots keep, when not the serving one.
    stage_builds: Mapping[str, FleetRender] = field(default_factory=dict)


@dataclass(frozen=True)
class Condition:
    """The reconciler's condition after a step, as its status reports it."""

    reason: Reason
    message: str
    failed_revision: str | None = None
    diagnostics: tuple[StatusDiagnostic, ...] = ()
    more_diagnostics: int = 0
    rollout: RolloutStatus | None = None
    held: tuple[HeldRobot, ...] = ()  # robots held back for drift, at most MAX_LISTED
    more_held: int = 0

    @property
    def state(self) -> ReconcilerState:
        return state_of(self.reason)


@dataclass(frozen=True)
class Decision:
    """What to make the broker hold (`target`, through `actions`) and what to report."""

    target: Desired | None
    actions: Actions[RenderedRequest] | None
    condition: Condition
    stable: Desired | None = None  # the last revision fully applied, once this step is
    recheck_at: float | None = None  # unix time to look again though nothing arrives
    wave_record: WaveRecord | None = None  # what a rollout's current wave established
    verdicts: tuple[VerdictNote, ...] = ()  # reached in this step: to keep as git notes

    @property
    def changes(self) -> bool:
        return self.actions is not None and not self.actions.empty

    def progressing(self) -> Condition:
        """Reported while the changes are published: the outcome is not known yet."""
        assert self.target is not None
        return replace(
            self.condition,
            reason=Reason.PROGRESSING,
            message=f"applying {short_rev(self.target.revision)}",
        )

    def unacknowledged(self, error: str | None) -> Condition:
        """The outcome when the broker did not acknowledge every message in time."""
        assert self.target is not None
        return replace(
            self.condition,
            reason=Reason.BROKER_UNAVAILABLE,
            message="the broker did not acknowledge every message; retrying: "
            + (error or "timeout"),
            failed_revision=self.target.revision,
        )


def decide(seen: Observation) -> Decision:
    """The head when it can be applied, else the last good revision kept (and refilled)."""
    build = seen.build
    if build.fleet is not None and build.fleet.rollout is not None:
        return _decide_rollout(seen, build)
    problems = list(build.problems)
    reason = _failure(seen)
    actions: Actions[RenderedRequest] | None = None
    held: dict[str, Drift] = {}
    if build.fleet is not None:
        fleet = build.fleet
        held = held_back(fleet, fleet.requests, seen)
        actions = diff(
            fleet.requests,
            seen.launches,
            fleet.suspended | held.keys(),
            fleet.allow_empty,
            seen.active,
            seen.unsigned,
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
        held = held_back(fleet, fleet.requests, seen)
        keep = fleet.suspended | held.keys()
        actions = diff(fleet.requests, seen.launches, keep, True, seen.active, seen.unsigned)
    condition = with_held(_condition(seen, target, problems, reason, build.omitted), held)
    return Decision(target, actions, condition, stable=target)


def held_back(
    fleet: FleetRender, requests: Mapping[str, RenderedRequest], seen: Observation
) -> dict[str, Drift]:
    """With `drift: hold`, the robots whose new request (one their launch topic does not hold)
    does not fit the interfaces they report: each keeps what it holds until they fit. A robot
    that reports nothing readable (unknown, error) is never held, nor a suspended one."""
    if fleet.drift != "hold" or seen.interfaces is None:
        return {}
    held: dict[str, Drift] = {}
    for robot_id, request in requests.items():
        found = seen.interfaces.get(robot_id)
        if found is None or robot_id in fleet.suspended:
            continue
        if seen.launches.get(robot_id) == request.digest:
            continue  # delivered already: drift is reported, there is nothing to hold
        needs = needs_of_rendered(request, fleet.needed_by.get(request.capability_name))
        drift = drift_of(robot_id, needs, found)
        if drift.drifted:
            held[robot_id] = drift
    return held


def with_held(condition: Condition, held: Mapping[str, Drift]) -> Condition:
    """The condition naming the robots held back for drift (bounded), and why each."""
    if not held:
        return condition
    robots = sorted(held)
    listed = tuple(
        HeldRobot(robot=robot_id, reason=_held_reason(held[robot_id]))
        for robot_id in robots[:MAX_LISTED]
    )
    names = ", ".join(robots[:5]) + (", ..." if len(robots) > 5 else "")
    message = f"{condition.message}; {len(robots)} robot(s) held for drift (drift: hold): {names}"
    return replace(condition, message=message, held=listed, more_held=len(robots) - len(listed))


def _held_reason(drift: Drift) -> str:
    shown = [item.reason() for item in drift.items[:3]]
    more = len(drift.items) - len(shown)
    return "; ".join(shown) + (f"; and {more} more" if more > 0 else "")


def _decide_rollout(seen: Observation, build: Desired) -> Decision:
    """The head has a rollout policy: its robots move wave by wave (reconciler/rollout.py)."""
    fleet = build.fleet
    assert fleet is not None
    stable = seen.serving if seen.serving is not None and seen.serving.fleet else None
    waiting = held_back(fleet, fleet.requests, seen)
    step = roll_out(_rollout_input(seen, fleet, stable, frozenset(waiting)))
    if step.serve_stable and stable is not None and stable.fleet is not None:
        back = stable.fleet
        held = held_back(back, back.requests, seen)
        actions = diff(
            back.requests,
            seen.launches,
            back.suspended | held.keys(),
            True,
            seen.active,
            seen.unsigned,
        )
        condition = with_held(_rollout_condition(seen, step), held)
        return Decision(stable, actions, condition, stable=stable, verdicts=tuple(step.verdicts))
    # Robots whose wave has not come are left as they are anyway: not held, only waiting.
    moving = {r: q for r, q in step.requests.items() if r not in step.keep}
    held = held_back(fleet, moving, seen)
    keep = fleet.suspended | step.keep | held.keys()
    actions = diff(
        step.requests, seen.launches, keep, fleet.allow_empty, seen.active, seen.unsigned
    )
    if actions.refused:  # the head would unassign every robot: the stable revision stays
        refused = decide(replace(seen, build=Desired(build.revision, None)))
        problem = StatusDiagnostic(
            path="configs/fleet.yaml",
            code=Reason.EMPTY_FLEET_REFUSED.value,
            message=actions.refused,
        )
        condition = replace(
            refused.condition,
            reason=Reason.EMPTY_FLEET_REFUSED,
            message=f"revision {short_rev(build.revision)} is not applied (EmptyFleetRefused)",
            failed_revision=build.revision,
            diagnostics=(problem,),
        )
        return replace(refused, condition=condition)
    new_stable = build if step.complete else stable
    return Decision(
        build,
        actions,
        with_held(_rollout_condition(seen, step), held),
        stable=new_stable,
        recheck_at=step.recheck_at,
        wave_record=step.record,
        verdicts=tuple(step.verdicts),
    )


def _rollout_input(
    seen: Observation, head: FleetRender, stable: Desired | None, held: frozenset[str]
) -> RolloutInput:
    """What the rollout of `head` sees at this step, from the observation."""
    return RolloutInput(
        head=head,
        stable=stable.fleet if stable is not None else None,
        previous=seen.previous_rollout,
        launches=seen.launches,
        statuses=seen.statuses,
        running_since=seen.running_since,
        now=seen.now,
        record=seen.wave_record,
        watching_since=seen.watching_since,
        dark_since=seen.dark_since,
        statuses_lost=seen.statuses_lost,
        held=held,
        evidence=seen.evidence,
        baseline=seen.baseline,
        notes=seen.notes,
        stage_builds=seen.stage_builds,
    )


def _rollout_condition(seen: Observation, step: RolloutStep) -> Condition:
    rollout = step.status
    assert rollout is not None
    head = short_rev(rollout.revision)
    if step.complete:
        done = _condition(seen, None, [], Reason.APPLIED, 0)
        return replace(done, rollout=rollout)
    counts = rollout.counts
    where = (
        f"wave {rollout.wave + 1}/{rollout.waves} ({rollout.wave_name}): "
        f"{counts.get('healthy', 0)} healthy, {counts.get('failed', 0)} failed, "
        f"{counts.get('pending', 0)} pending"
        + (f", {counts['offline']} offline" if counts.get("offline") else "")
    )
    if rollout.state == "RolledBack":
        message = f"rollout of {head} rolled back: {rollout.message}"
        return Condition(Reason.ROLLED_BACK, message, rollout.revision, rollout=rollout)
    if rollout.state == "Halted":
        message = f"rollout of {head} halted at {where}: {rollout.message}"
        return Condition(Reason.ROLLOUT_HALTED, message, rollout.revision, rollout=rollout)
    if rollout.state == "Paused":
        message = f"rollout of {head} paused at {where}"
        return Condition(Reason.ROLLOUT_PAUSED, message, rollout=rollout)
    return Condition(Reason.PROGRESSING, f"rolling out {head}: {where}", rollout=rollout)


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
