"""Alert events, pure: (what was told so far, what is seen now) -> the transitions to tell.

Each event is told once per transition, never per resync: a refused commit once per revision,
the branch's recovery once after it (the next head that applies),
a halted or rolled back rollout once per revision, a paused rollout once per wave run and its
resumption once after it, a wave's failed verification once per wave, a robot once as it drifts
and once as it fits again, a robot once as it degrades or goes offline and once as it is back in
sync (running the desired request for SETTLE seconds: a brain in a crash loop runs a moment
before each crash, and that is no recovery), a robot once as its brain's hold file defers a stop.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from robotconf.configurator.drift import Drift
from robotconf.contract.notes import VerdictNote
from robotconf.contract.textsafe import chat_text
from robotconf.contract.wire import (
    AgentState,
    AgentStatus,
    ReconcilerReason,
    ReconcilerStatus,
    RolloutStatus,
    short_rev,
)

SETTLE = 5.0  # seconds a robot told degraded or offline runs the desired request before in sync
REMEMBERED = 64  # revisions remembered as told: a commit refused long ago is not told again
_REFUSED = {ReconcilerReason.BUILD_FAILED.value, ReconcilerReason.EMPTY_FLEET_REFUSED.value}
# States in which the branch's head is accepted: applied, or being applied (a rollout).
_APPLYING = {"Ready", "Progressing"}
_DEGRADED = {AgentState.FAILED, AgentState.BACKOFF, AgentState.REJECTED}


class Kind(str, enum.Enum):
    COMMIT_REFUSED = "commit_refused"
    COMMIT_RECOVERED = "commit_recovered"
    ROLLOUT_HALTED = "rollout_halted"
    ROLLOUT_ROLLED_BACK = "rollout_rolled_back"
    ROLLOUT_PAUSED = "rollout_paused"
    ROLLOUT_RESUMED = "rollout_resumed"
    VERIFICATION_FAILED = "verification_failed"
    STAGE_PROMOTED = "stage_promoted"
    ROBOT_DEGRADED = "robot_degraded"
    ROBOT_OFFLINE = "robot_offline"
    ROBOT_IN_SYNC = "robot_in_sync"
    ROBOT_DRIFTED = "robot_drifted"
    ROBOT_DRIFT_CLEARED = "robot_drift_cleared"
    ROBOT_DEFERRED = "robot_deferred"
    ROBOT_GOALS_FAILING = (
        "robot_goals_failing"  # told by the outcome ledger (readmodel/outcomes.py)
    )
    ROBOT_GOALS_RECOVERED = "robot_goals_recovered"
    # Kept in the timeline only (readmodel/timeline.py), not told to --notify's receivers:
    # every commit and wave would be noise in a chat; the history wants them.
    COMMIT_APPLIED = "commit_applied"
    WAVE_STARTED = "wave_started"
    ROBOT_RESTARTED = "robot_restarted"


_ROLLOUT_KINDS = {"Halted": Kind.ROLLOUT_HALTED, "RolledBack": Kind.ROLLOUT_ROLLED_BACK}
# States of a rollout that goes on: one told paused and seen in them again was resumed.
_GOING_ON = {"Progressing", "Complete"}
# A wave run: (revision, wave, when the wave was published). A rollout paused, resumed and
# paused again at its next wave is paused twice; a resync of the same pause is not.
WaveRun = tuple[str, int, float | None]


@dataclass(frozen=True)
class Event:
    """One thing worth telling a person, as receivers get it (`as_json`). `message` quotes
    what robots say as they said it: JSON carries it as data, `text` and logs escape it."""

    kind: Kind
    message: str
    at: float
    branch: str | None = None
    revision: str | None = None
    robot: str | None = None
    reason: str | None = None  # the reconciler's reason, or the robot's state
    refused_revision: str | None = None  # commit_recovered: the revision told refused before
    subject: str | None = None  # the subject of `revision`'s commit, when the status carries it
    by: str | None = None  # robot_restarted: who asked for it from the desk

    def as_json(self) -> dict[str, Any]:
        found = {
            "event": self.kind.value,
            "at": self.at,
            "branch": self.branch,
            "revision": self.revision,
            "robot": self.robot,
            "reason": self.reason,
            "message": self.message,
            "refused_revision": self.refused_revision,
            "subject": self.subject,
        }
        if self.by is not None:  # the alerts' payload as it was, unless there is a who
            found["by"] = self.by
        return found

    def text(self) -> str:
        """One line for a chat (the Slack form). The message quotes robots (a status message)
        and commits: it is made inert text there, so that no robot pings a channel."""
        subject = (
            f' (commit {short_rev(self.revision)}: "{self.subject}")'
            if self.subject and self.revision
            else ""
        )
        what = f"robotconf {self.kind.value.replace('_', ' ')}: {self.message}{subject}"
        return chat_text(what)


@dataclass(frozen=True)
class Seen:
    """What is seen now: the reconciler's status, and the robots' statuses with the digest each
    should run (None: the robots are not known yet)."""

    status: ReconcilerStatus | None = None
    robots: Mapping[str, AgentStatus] | None = None
    desired: Mapping[str, str] = field(default_factory=dict)  # robot -> digest, unsuspended
    # robot -> when it was first seen running the digest it reports (the observer's clock)
    running_since: Mapping[str, float] = field(default_factory=dict)
    # robot -> its drift against its desired request (None: interfaces not known yet)
    drift: Mapping[str, Drift] | None = None
    # wave run -> the operator who resumed it, from the verdicts the steps reached (`resumers`):
    # the status shows the name only while the rollout is still at that wave, seldom after
    resumed_by: Mapping[WaveRun, str] = field(default_factory=dict)


@dataclass(frozen=True)
class PausedRun:
    """A wave run told paused, and its wave as the events name it."""

    run: WaveRun
    wave: str


@dataclass(frozen=True)
class Told:
    """What was told so far: the memory that makes events transitions."""

    refused: tuple[str, ...] = ()  # revisions told refused, oldest first
    unrecovered: str | None = None  # the revision told refused last, until the branch applies
    rollouts: tuple[tuple[str, str], ...] = ()  # (revision, state) told, oldest first
    paused: tuple[WaveRun, ...] = ()  # wave runs told paused, oldest first
    pausing: PausedRun | None = None  # the wave run told paused last, until told resumed
    verifications: tuple[tuple[str, int], ...] = ()  # (revision, wave) told failed verifying
    promotions: tuple[tuple[str, str], ...] = ()  # (revision, stage) told promoted to
    alerting: Mapping[str, Kind] = field(default_factory=dict)  # robot -> degraded or offline
    drifted: frozenset[str] = frozenset()  # robots told drifted, not yet told fitting again
    deferred: frozenset[str] = frozenset()  # robots told deferred, still deferred


def resumed(told: Told, found: ReconcilerStatus | None) -> Told:
    """What a restarted reconciler knows was told, from the status it found on the broker:
    whatever that status would have told, the reconciler before told — a refusal (its
    recovery is told when the branch applies), the rollout's pause (its going on is told as a
    resumption), stop, failed verification and stage. The same transitions, their events
    dropped. (A clean stop or a Last Will leaves `Offline`, which names no refusal: the new
    reconciler tells the refusal again if the head is still refused.)"""
    if found is None:
        return told
    return transitions(told, Seen(found), found.since)[0]


def _refusal(told: Told, status: ReconcilerStatus, at: float) -> tuple[Told, list[Event]]:
    """A refused head, once per revision; remembered until the branch applies again."""
    revision = status.failed_revision
    if status.reason not in _REFUSED or not revision:
        return told, []
    if revision in told.refused:
        return told, []
    told = replace(told, refused=_remember(told.refused, revision), unrecovered=revision)
    message = f"{short_rev(revision)} on {status.branch} refused ({status.reason}): "
    event = Event(
        Kind.COMMIT_REFUSED,
        message + status.message,
        at,
        status.branch,
        revision,
        reason=status.reason,
    )
    return told, [event]


def _recovery(told: Told, status: ReconcilerStatus, at: float) -> tuple[Told, list[Event]]:
    """The branch applies again after a refusal: a later head was accepted (applied, or being
    rolled out). Once: the memory is cleared with it."""
    refused = told.unrecovered
    if refused is None or status.state not in _APPLYING or status.reason in _REFUSED:
        return told, []
    if status.last_attempted_revision == refused:  # still the refused head
        return told, []
    revision = status.last_applied_revision
    message = (
        f"{short_rev(revision)} on {status.branch} applies ({status.reason}) after "
        f"{short_rev(refused)} was refused"
    )
    event = Event(
        Kind.COMMIT_RECOVERED,
        message,
        at,
        status.branch,
        revision,
        reason=status.reason,
        refused_revision=refused,
    )
    return replace(told, unrecovered=None), [event]


def _remember(items: tuple[Any, ...], item: Any) -> tuple[Any, ...]:
    return (*items, item)[-REMEMBERED:]


def robot_kind(status: AgentStatus, digest: str) -> Kind | None:
    """Degraded, offline, in sync (running `digest`), or in between (None)."""
    if status.state in _DEGRADED:
        return Kind.ROBOT_DEGRADED
    if status.state is AgentState.OFFLINE:
        return Kind.ROBOT_OFFLINE
    if status.state is AgentState.RUNNING and status.digest == digest:
        return Kind.ROBOT_IN_SYNC
    return None


def transitions(
    told: Told, seen: Seen, at: float, settle: float = SETTLE
) -> tuple[Told, list[Event]]:
    """The events `seen` makes, given what was `told`; and the memory after telling them."""
    events: list[Event] = []
    status = seen.status
    branch = status.branch if status is not None else None
    if status is not None:
        told, refusal = _refusal(told, status, at)
        told, recovery = _recovery(told, status, at)
        events += refusal + recovery
    rollout = status.rollout if status is not None else None
    if rollout is not None:
        told, rollout_events = _rollout_transitions(told, rollout, branch, at, seen.resumed_by)
        events += rollout_events
    if seen.robots is not None:
        settled = {r for r, since in seen.running_since.items() if at - since >= settle}
        told, robot_events = _robot_transitions(told, seen, settled, branch, at)
        events += robot_events
    if seen.drift is not None:
        told, drift_events = _drift_transitions(told, seen, branch, at)
        events += drift_events
    if seen.robots is not None:
        told, deferral_events = _deferral_transitions(told, seen.robots, branch, at)
        events += deferral_events
    return told, [with_subject(event, status) for event in events]


def with_subject(event: Event, status: ReconcilerStatus | None) -> Event:
    """The event with its revision's commit subject, when the status describes that commit."""
    line = status.commit(event.revision) if status is not None else None
    return replace(event, subject=line.subject) if line is not None and line.subject else event


def _rollout_transitions(
    told: Told,
    rollout: RolloutStatus,
    branch: str | None,
    at: float,
    resumed_by: Mapping[WaveRun, str],
) -> tuple[Told, list[Event]]:
    """A rollout's transitions, the cause before its effect: a wave's failed verification,
    a resumption, then the rollout halted, rolled back or paused."""
    told, failed = _verification_failed(told, rollout, branch, at)
    told, resumption = _resumption(told, rollout, branch, at, resumed_by)
    told, stopped = _stopped(told, rollout, branch, at)
    told, paused = _pause(told, rollout, branch, at)
    told, promoted = _promotion(told, rollout, branch, at)
    return told, failed + resumption + stopped + paused + promoted


def _promotion(
    told: Told, rollout: RolloutStatus, branch: str | None, at: float
) -> tuple[Told, list[Event]]:
    """A revision that reached a stage after the first (fleet.yaml stages): verified on the
    stage before it, or promoted by hand; once per (revision, stage)."""
    names = [stage.name for stage in rollout.stages]
    if rollout.stage is None or rollout.stage not in names[1:]:
        return told, []
    if rollout.state not in ("Progressing", "Paused", "Complete"):
        return told, []
    key = (rollout.revision, rollout.stage)
    if key in told.promotions:
        return told, []
    told = replace(told, promotions=_remember(told.promotions, key))
    before = names[names.index(rollout.stage) - 1]
    message = (
        f"{short_rev(rollout.revision)} on {branch} promoted to stage '{rollout.stage}' "
        f"(verified on '{before}', or promoted by hand)"
    )
    event = Event(Kind.STAGE_PROMOTED, message, at, branch, rollout.revision, reason="Promoted")
    return told, [event]


RESUMERS = 8  # wave runs whose resumer is kept: one rollout at a time, a few pauses each


def resumers(known: Mapping[WaveRun, str], reached: Sequence[VerdictNote]) -> dict[WaveRun, str]:
    """`known` with the operators of the wave runs resumed by hand among the verdicts a step
    `reached` (a verification note naming who decided it), the last RESUMERS kept."""
    found = dict(known)
    for note in reached:
        if note.kind == "verification" and note.by and note.wave is not None:
            run = (note.revision, note.wave, note.started_at)
            found.pop(run, None)  # the newest last: the oldest are dropped first
            found[run] = note.by
    return dict(list(found.items())[-RESUMERS:])


def _stopped(
    told: Told, rollout: RolloutStatus, branch: str | None, at: float
) -> tuple[Told, list[Event]]:
    """Halted or rolled back, once per (revision, state)."""
    if rollout.state not in _ROLLOUT_KINDS:
        return told, []
    key = (rollout.revision, rollout.state)
    if key in told.rollouts:
        return told, []
    told = replace(told, rollouts=_remember(told.rollouts, key))
    what = "halted" if rollout.state == "Halted" else "rolled back"
    message = f"rollout of {short_rev(rollout.revision)} on {branch} {what}: {rollout.message}"
    event = Event(
        _ROLLOUT_KINDS[rollout.state], message, at, branch, rollout.revision, reason=rollout.state
    )
    return told, [event]


def _wave_run(rollout: RolloutStatus) -> WaveRun:
    return (rollout.revision, rollout.wave, rollout.wave_started_at)


def _wave_named(rollout: RolloutStatus) -> str:
    name = f"'{rollout.wave_name}' " if rollout.wave_name else ""
    return f"wave {name}({rollout.wave + 1} of {rollout.waves})"


def _pause(
    told: Told, rollout: RolloutStatus, branch: str | None, at: float
) -> tuple[Told, list[Event]]:
    """Paused, once per wave run, whatever the cause: fleet.yaml's `rollout.paused`, or a wave
    whose evidence was inconclusive. The rollout's message says which, and what resumes it."""
    if rollout.state != "Paused":
        return told, []
    run = _wave_run(rollout)
    if run in told.paused:
        return told, []
    told = replace(
        told, paused=_remember(told.paused, run), pausing=PausedRun(run, _wave_named(rollout))
    )
    message = (
        f"rollout of {short_rev(rollout.revision)} on {branch} paused at {_wave_named(rollout)}: "
        f"{rollout.message}"
    )
    return told, [
        Event(Kind.ROLLOUT_PAUSED, message, at, branch, rollout.revision, reason="Paused")
    ]


def _resumption(
    told: Told,
    rollout: RolloutStatus,
    branch: str | None,
    at: float,
    resumed_by: Mapping[WaveRun, str],
) -> tuple[Told, list[Event]]:
    """The rollout told paused goes on (Progressing, Complete, or paused at a later wave run)
    with the same revision: resumed, once. Another revision's rollout, or the same one halted
    or rolled back (an abort, told as such), ends the pause without a word."""
    pausing = told.pausing
    if pausing is None:
        return told, []
    revision = pausing.run[0]
    if rollout.revision != revision or rollout.state in _ROLLOUT_KINDS:
        return replace(told, pausing=None), []
    # Gone on: past the paused wave run, or decided by hand on it. Progressing at the same run
    # with no decision is a reconciler that cannot judge yet (restarted), not a resumption.
    moved = _wave_run(rollout) != pausing.run
    decided = rollout.verification is not None and rollout.verification.decided_by is not None
    going_on = (
        rollout.state == "Complete"
        or (rollout.state == "Progressing" and (moved or decided))
        or (rollout.state == "Paused" and moved)
    )
    if not going_on:
        return told, []
    # The operator's name is on the resumed wave's verdict note; the status shows it only when
    # the rollout is still at that wave (it usually moves to the next one in the same step).
    verification = rollout.verification
    by = resumed_by.get(pausing.run) or (
        verification.decided_by if verification is not None else None
    )
    who = f" by {by}" if by else ""
    message = (
        f"rollout of {short_rev(revision)} on {branch} resumed{who} after {pausing.wave}: "
        f"now {rollout.state}" + (f" ({rollout.message})" if rollout.message else "")
    )
    event = Event(Kind.ROLLOUT_RESUMED, message, at, branch, revision, reason=rollout.state)
    return replace(told, pausing=None), [event]


def _verification_failed(
    told: Told, rollout: RolloutStatus, branch: str | None, at: float
) -> tuple[Told, list[Event]]:
    """A wave's verification failed, once per (revision, wave); the evidence's message says
    why. A gating failure also halts or rolls back the rollout, told on its own.

    A dry run's failure is told too, its message saying it does not gate (and `reason`
    `DryRun`): dry runs are how a lab tries criteria in shadow mode, and a failure it does not
    hear about is a criterion it cannot tune. A receiver that wants only gating failures
    filters on `reason` `Failed`."""
    verification = rollout.verification
    if verification is None or verification.verdict != "Failed":
        return told, []
    key = (rollout.revision, rollout.wave)
    if key in told.verifications:
        return told, []
    told = replace(told, verifications=_remember(told.verifications, key))
    shadow = " (dry run: not gating)" if verification.dry_run else ""
    message = (
        f"verification of {short_rev(rollout.revision)} on {branch} failed at "
        f"{_wave_named(rollout)}{shadow}: {verification.message}"
    )
    reason = "DryRun" if verification.dry_run else "Failed"
    event = Event(Kind.VERIFICATION_FAILED, message, at, branch, rollout.revision, reason=reason)
    return told, [event]


def _deferral_transitions(
    told: Told, robots: Mapping[str, AgentStatus], branch: str | None, at: float
) -> tuple[Told, list[Event]]:
    """Into `deferred` (its brain's hold file holds off a stop, restart or reload), once per
    deferral; whether it is assigned or leaving the fleet (its stop waits too). Its end needs
    no word of its own: what waited happens, and the robot's other events follow it."""
    events: list[Event] = []
    deferred = {r for r, status in robots.items() if status.state is AgentState.DEFERRED}
    for robot_id in sorted(deferred - told.deferred):
        status = robots[robot_id]
        events.append(
            Event(
                Kind.ROBOT_DEFERRED,
                f"{robot_id} is deferred: {status.message}",
                at,
                branch,
                status.revision,
                robot_id,
                AgentState.DEFERRED.value,
            )
        )
    return replace(told, deferred=frozenset(deferred)), events


DRIFT_ITEMS_TOLD = 5  # drift items an event's message names; the rest are counted


def _drift_transitions(
    told: Told, seen: Seen, branch: str | None, at: float
) -> tuple[Told, list[Event]]:
    """Into drift (its reported interfaces lack what its request needs), and out of it (they
    fit again), once each. A robot whose interfaces become unknown or unreadable is neither:
    nothing is claimed either way until it reports again; one no longer assigned is forgotten."""
    assert seen.drift is not None
    events: list[Event] = []
    drifted: set[str] = set()
    for robot_id in sorted(seen.desired):
        drift = seen.drift.get(robot_id)
        was = robot_id in told.drifted
        if drift is None or drift.interfaces != "reported":
            if was:
                drifted.add(robot_id)
            continue
        if drift.drifted:
            drifted.add(robot_id)
            if not was:
                texts = [item.reason() for item in drift.items[:DRIFT_ITEMS_TOLD]]
                more = len(drift.items) - len(texts)
                message = f"{robot_id} drifted: " + "; ".join(texts)
                if more > 0:
                    message += f"; and {more} more"
                events.append(
                    Event(Kind.ROBOT_DRIFTED, message, at, branch, robot=robot_id, reason="drift")
                )
        elif was:
            events.append(
                Event(
                    Kind.ROBOT_DRIFT_CLEARED,
                    f"{robot_id}'s interfaces fit its request again",
                    at,
                    branch,
                    robot=robot_id,
                    reason="fits",
                )
            )
    return replace(told, drifted=frozenset(drifted)), events


def _robot_transitions(
    told: Told, seen: Seen, settled: set[str], branch: str | None, at: float
) -> tuple[Told, list[Event]]:
    """Only robots the fleet assigns (and does not suspend) are judged; one that is no longer
    assigned, or whose status is gone, is forgotten without a word."""
    assert seen.robots is not None
    events: list[Event] = []
    alerting: dict[str, Kind] = {}
    for robot_id, digest in sorted(seen.desired.items()):
        status = seen.robots.get(robot_id)
        was = told.alerting.get(robot_id)
        if status is None:
            continue
        now = robot_kind(status, digest)
        if now in (Kind.ROBOT_DEGRADED, Kind.ROBOT_OFFLINE):
            alerting[robot_id] = now
            if now is not was:
                state = status.state.value
                why = f": {status.message}" if status.message else ""
                events.append(
                    Event(
                        now,
                        f"{robot_id} is {state}{why}",
                        at,
                        branch,
                        status.revision,
                        robot_id,
                        state,
                    )
                )
        elif now is Kind.ROBOT_IN_SYNC and was is not None and robot_id in settled:
            events.append(
                Event(
                    now,
                    f"{robot_id} is back in sync, running {short_rev(status.revision)}",
                    at,
                    branch,
                    status.revision,
                    robot_id,
                    status.state.value,
                )
            )
        elif was is not None:  # on its way back (starting, settling): still told as it was
            alerting[robot_id] = was
    return replace(told, alerting=alerting), events
