"""Fleet status verdicts (docs/architecture.md#fleet-status-verdicts), pure: desired robots +
retained topics -> a verdict each.

The JSON form and the words of the reconciler's lines are here; the table for people is drawn
by workstation/cli/fleet_view.py.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from robotconf.configurator.drift import (
    UNKNOWN,
    Drift,
    DriftMemo,
    Need,
    drift_of,
    needs_of,
    needs_of_rendered,
)
from robotconf.configurator.render import FleetRender
from robotconf.configurator.waves import assign_waves, matches
from robotconf.contract.interfaces import interfaces_verdict
from robotconf.contract.launch import template_mismatch
from robotconf.contract.textsafe import printable, shorten
from robotconf.contract.wire import (
    ACTIVE_STATES,
    RESUME_COMMAND,
    VERIFY_COMMANDS,
    AgentState,
    ReconcilerStatus,
    RolloutStatus,
    WaveVerification,
)
from robotconf.contract.wire import short_digest as _short_digest
from robotconf.contract.wire import short_rev as _short_rev
from robotconf.readmodel.observed import Retained, RobotSeen
from robotconf.readmodel.robot_goals import NO_GOALS, RobotGoals


class Verdict(str, enum.Enum):
    DEGRADED = "Degraded"  # assigned, but its brain failed, crashed or was refused
    # Assigned, and the broker holds no status of it that could be read: it dropped retained
    # messages on their way to this reader (a queue limit), so Offline would be a guess.
    UNKNOWN = "Unknown"
    OFFLINE = "Offline"  # assigned, but its agent is not connected
    PROGRESSING = "Progressing"  # on its way: not published yet, starting, stopping
    SUSPENDED = "Suspended"  # fleet.yaml says leave it as it is
    UNASSIGNED = "Unassigned"  # known to the broker, not in fleet.yaml
    IN_SYNC = "InSync"  # running the desired request


WORST_FIRST = list(Verdict)
# Suspended and unassigned robots are not the reconciler's to converge: they do not fail status.
SETTLED = {Verdict.IN_SYNC, Verdict.SUSPENDED, Verdict.UNASSIGNED}


@dataclass(frozen=True)
class DesiredRobot:
    """What the fleet asks of one robot."""

    robot_id: str
    scenario: str | None
    digest: str
    suspended: bool = False
    template: str | None = None
    labels: Mapping[str, str] = field(default_factory=dict)
    wave: str | None = None  # the rollout wave it falls in; None: no policy
    needs: Sequence[Need] = ()  # the interfaces its request needs of the robot


def desired_from_fleet(fleet: FleetRender) -> dict[str, DesiredRobot]:
    waves: dict[str, str] = {}
    if fleet.rollout is not None:
        names = [wave.name for wave in fleet.rollout.waves]
        placed = assign_waves(fleet.labels, fleet.rollout.waves)
        waves = {robot: names[index] for robot, index in placed.items()}
    return {
        robot_id: DesiredRobot(
            robot_id,
            fleet.scenario_of.get(robot_id),
            request.digest,
            robot_id in fleet.suspended,
            request.robot_template,
            fleet.labels.get(robot_id, {}),
            waves.get(robot_id),
            needs_of_rendered(request, fleet.needed_by.get(request.capability_name)),
        )
        for robot_id, request in fleet.requests.items()
    }


def desired_from_retained(retained: Retained) -> dict[str, DesiredRobot]:
    """Without a repository, what is published is the best account of what is desired."""
    return {
        robot_id: DesiredRobot(
            robot_id,
            robot.launch.scenario.name,
            robot.launch.digest,
            template=robot.launch.scenario.capability.robot_template,
            needs=needs_of(robot.launch),
        )
        for robot_id, robot in retained.robots.items()
        if robot.launch is not None
    }


@dataclass
class RobotRow:
    robot_id: str
    verdict: Verdict
    reason: str
    online: bool
    scenario: str | None
    desired: str | None
    published: str | None
    reported: str | None
    state: str
    restarts: int
    reloads: int = 0  # of the running brain, in place: each one a request applied unrestarted
    warnings: list[str] = field(default_factory=list)
    labels: dict[str, str] = field(default_factory=dict)  # fleet.yaml's; none when not desired
    wave: str | None = None  # its rollout wave, when fleet.yaml has a rollout policy
    # The last restart asked for from the desk that its agent carried out: who, issued when.
    restart_requested_by: str | None = None
    restart_requested_at: float | None = None
    drift: Drift = UNKNOWN  # its reported interfaces against its desired request
    # While `deferred`: since when its brain's hold file defers a stop (the agent's clock).
    deferred_since: float | None = None
    goals: RobotGoals = NO_GOALS  # its retained goals summary: unknown when it has none

    def as_json(self) -> dict[str, Any]:
        return {
            "robot_id": self.robot_id,
            "verdict": self.verdict.value,
            "reason": self.reason,
            "online": self.online,
            "scenario": self.scenario,
            "labels": self.labels,
            "wave": self.wave,
            "desired_digest": self.desired,
            "published_digest": self.published,
            "reported_digest": self.reported,
            "state": self.state,
            "deferred_since": self.deferred_since,
            "restarts": self.restarts,
            "reloads": self.reloads,
            "warnings": self.warnings,
            "interfaces": self.drift.interfaces,
            "drift": [item.as_json() for item in self.drift.items],
            "drift_note": self.drift.note,
            "restart": (
                {"requested_by": self.restart_requested_by, "at": self.restart_requested_at}
                if self.restart_requested_by is not None
                else None
            ),
            "goals": self.goals.as_json(),
            "goals_state": self.goals.state,
            "goals_note": self.goals.note,
            "vitals": self.goals.vitals_json(),
        }

    def restart_line(self) -> str | None:
        """`restart: tb3-01 by alice at 2026-11-24 12:00:03 UTC`, when one was carried out."""
        if self.restart_requested_by is None:
            return None
        at = self.restart_requested_at
        when = (
            time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(at))
            if at is not None and 0 <= at < 1e11
            else "an unknown time"
        )
        return f"restart: {clean(self.robot_id)} by {clean(self.restart_requested_by)} at {when}"


def verdict(desired: DesiredRobot | None, robot: RobotSeen) -> tuple[Verdict, str]:
    """The sync verdict of one robot, and a few words of why."""
    status = robot.status
    state = status.state if status is not None else AgentState.OFFLINE
    if desired is None:
        if state in ACTIVE_STATES and robot.launch_digest is not None:
            return Verdict.PROGRESSING, "not in fleet.yaml: its request is still published"
        if state is AgentState.DEFERRED:
            return Verdict.PROGRESSING, "not in fleet.yaml: its brain's hold file defers its stop"
        if state in ACTIVE_STATES:
            return Verdict.PROGRESSING, "not in fleet.yaml: its brain is being stopped"
        return Verdict.UNASSIGNED, "not in fleet.yaml"
    if desired.suspended:
        return Verdict.SUSPENDED, "suspended in fleet.yaml: left as it is"
    if status is None or state is AgentState.OFFLINE:
        return Verdict.OFFLINE, (status.message if status else "") or "its agent has never reported"
    if state in (AgentState.FAILED, AgentState.REJECTED, AgentState.BACKOFF, AgentState.EXITED):
        return Verdict.DEGRADED, status.message or f"brain service {state.value}"
    if state is AgentState.DEFERRED:  # says what waits for the brain's hold file, since when
        return Verdict.PROGRESSING, status.message or "deferred by its brain's hold file"
    if robot.launch_digest != desired.digest:
        return Verdict.PROGRESSING, "the desired request is not published yet"
    if status.digest != desired.digest:
        return Verdict.PROGRESSING, f"{state.value}, not yet on the desired request"
    if state is AgentState.RUNNING:
        return Verdict.IN_SYNC, "running the desired request"
    return Verdict.PROGRESSING, state.value


def template_warning(desired: DesiredRobot | None, robot: RobotSeen) -> str | None:
    recommended = robot.description.recommended_template if robot.description else None
    if desired is None:
        return None
    warning = template_mismatch(desired.template, recommended)
    if warning is not None and robot.status is not None and warning in robot.status.warnings:
        return None  # the agent reports the same words: one line is enough
    return warning


def robot_drift(
    robot_id: str, want: DesiredRobot | None, robot: RobotSeen, memo: DriftMemo | None = None
) -> Drift:
    """Its interfaces against its desired request: judged only for a robot assigned and not
    suspended (whose request is delivered); else only whether it reports them."""
    if want is None or want.suspended:
        if robot.interfaces_error is not None:
            return Drift("error", note=f"its interfaces cannot be read: {robot.interfaces_error}")
        return Drift(interfaces_verdict(robot.interfaces), judged=False)
    if memo is not None:
        return memo.get(robot_id, want.digest, want.needs, robot.interfaces, robot.interfaces_error)
    return drift_of(robot_id, want.needs, robot.interfaces, robot.interfaces_error)


def row_order(row: RobotRow) -> tuple[int, bool, str]:
    """Where a row goes: worst verdict first, drifted first among its verdict's, then by id."""
    return (WORST_FIRST.index(row.verdict), not row.drift.drifted, row.robot_id)


def build_rows(
    desired: Mapping[str, DesiredRobot], retained: Retained, memo: DriftMemo | None = None
) -> list[RobotRow]:
    """Every robot that is desired or known to the broker, worst verdict first (a drifted
    robot first among its verdict's). `memo`: each robot's drift, kept while its request and
    its interfaces stay the same."""
    rows = []
    robots = sorted(set(desired) | set(retained.robots))
    reconciler = retained.reconciler
    held = {h.robot: h.reason for h in reconciler.held} if reconciler is not None else {}
    for robot_id in robots:
        want = desired.get(robot_id)
        robot = retained.robots.get(robot_id, RobotSeen())
        found, reason = verdict(want, robot)
        if robot_id in held and found not in SETTLED:
            why = f"held by the reconciler for drift (drift: hold): {held[robot_id]}"
            reason = why if found is Verdict.PROGRESSING else f"{reason}; {why}"
        status = robot.status
        warnings = [w for w in [template_warning(want, robot)] if w]
        if status is not None:
            warnings += status.warnings
        rows.append(
            RobotRow(
                robot_id=robot_id,
                verdict=found,
                reason=reason,
                online=robot.online,
                scenario=want.scenario if want else None,
                desired=want.digest if want and not want.suspended else None,
                published=robot.launch_digest,
                reported=status.digest if status else None,
                state=status.state.value if status else AgentState.OFFLINE.value,
                restarts=status.restarts if status else 0,
                reloads=status.reloads if status else 0,
                warnings=warnings,
                labels=dict(want.labels) if want else {},
                wave=want.wave if want else None,
                restart_requested_by=status.restart_requested_by if status else None,
                restart_requested_at=status.restart_requested_at if status else None,
                drift=robot_drift(robot_id, want, robot, memo),
                deferred_since=status.deferred_since if status else None,
                goals=RobotGoals.of(robot.goals, robot.goals_error),
            )
        )
    if memo is not None:
        memo.keep_only(robots)
    rows.sort(key=row_order)
    return rows


class Health(str, enum.Enum):
    """Is a reconciler at work? Only `ok` lets a fleet be in sync."""

    OK = "ok"
    MISSING = "missing"  # no retained status: none ever ran on this prefix (or it was wiped)
    OFFLINE = "offline"  # stopped, or its Last Will: it died or lost the broker
    STALE = "stale"  # its heartbeat is overdue: hung, or cut off without its will firing yet


def reconciler_health(status: ReconcilerStatus | None, at: float) -> Health:
    if status is None:
        return Health.MISSING
    if status.state == "Offline":
        return Health.OFFLINE
    if status.stale(at):
        return Health.STALE
    return Health.OK


@dataclass
class FleetStatus:
    rows: list[RobotRow]
    reconciler: ReconcilerStatus | None
    desired_from: str  # where the desired state came from, in words
    notes: list[str] = field(default_factory=list)
    ignored: dict[str, int] = field(default_factory=dict)  # unreadable payloads, by kind
    lost: str | None = None  # why the read is known to lack retained messages the broker holds
    checked_at: float = field(default_factory=time.time)

    @property
    def health(self) -> Health:
        return reconciler_health(self.reconciler, self.checked_at)

    def select(self, selector: Mapping[str, str]) -> FleetStatus:
        """Only the robots whose fleet.yaml labels match `selector` (all of it), as rollout
        waves select them; the reconciler's lines stay."""
        if not selector:
            return self
        rows = [r for r in self.rows if matches(r.labels, selector)]
        wanted = ",".join(f"{k}={v}" for k, v in sorted(selector.items()))
        note = f"only robots labelled {wanted}: {len(rows)} of {len(self.rows)}"
        return replace(self, rows=rows, notes=[*self.notes, note])

    @property
    def in_sync(self) -> bool:
        """Every robot settled, and a live reconciler has applied its branch."""
        robots_ok = all(r.verdict in SETTLED for r in self.rows)
        ready = self.reconciler is not None and self.reconciler.ready
        return robots_ok and ready and self.health is Health.OK

    def not_in_sync_because(self) -> str | None:
        """Why the fleet is not in sync in a few words, None when it is: its robots' counts
        say it when some are not settled; else the reconciler does (a rollback leaves every
        robot InSync on the stable revision, and the fleet short of its branch's head)."""
        if self.in_sync:
            return None
        unsettled = sum(r.verdict not in SETTLED for r in self.rows)
        if unsettled:
            return f"{unsettled} robot{'s' if unsettled != 1 else ''} not settled"
        health, status = self.health, self.reconciler
        if status is None or health is not Health.OK:
            return {
                Health.MISSING: "no reconciler status on the broker",
                Health.OFFLINE: "the reconciler is offline",
                Health.STALE: "the reconciler's heartbeat is overdue",
            }.get(health, "the reconciler is not ready")
        rollout = status.rollout
        if rollout is not None and rollout.state == "RolledBack":
            return (
                f"the rollout of {short_rev(rollout.revision)} was rolled back: the robots run "
                f"{short_rev(rollout.stable_revision)}, the last revision that fully rolled out"
            )
        if rollout is not None and rollout.state in ("Halted", "Paused"):
            return f"the rollout of {short_rev(rollout.revision)} is {rollout.state.lower()}"
        failed = f" {short_rev(status.failed_revision)}" if status.failed_revision else ""
        return f"the reconciler is {clean(status.state)} ({clean(status.reason)}{failed})"

    def counts(self) -> dict[str, int]:
        found = {v.value: 0 for v in Verdict}
        for row in self.rows:
            found[row.verdict.value] += 1
        return {k: n for k, n in found.items() if n}

    def as_json(self, *, heartbeat: bool = True) -> dict[str, Any]:
        """For scripts; without `heartbeat`, what `--watch` compares (a heartbeat alone is not
        a change)."""
        reconciler = self.reconciler.model_dump(mode="json") if self.reconciler else None
        if reconciler is not None and not heartbeat:
            reconciler.pop("heartbeat", None)
        return {
            "in_sync": self.in_sync,
            "not_in_sync_because": self.not_in_sync_because(),
            "desired_from": self.desired_from,
            "counts": self.counts(),
            "reconciler": reconciler,
            "reconciler_health": self.health.value,
            "robots": [r.as_json() for r in self.rows],
            "notes": self.notes,
            "ignored_payloads": self.ignored,
            "broker_dropped": self.lost,
        }


# ------------------------------------------------------------------ words


def clean(text: str) -> str:
    """Text from the broker, safe to print: control characters escaped."""
    return printable(text)


def short_digest(digest: str | None) -> str:
    return clean(_short_digest(digest))


def short_rev(revision: str | None) -> str:
    return clean(_short_rev(revision))


def _offline_count(rollout: RolloutStatus) -> str:
    offline = rollout.counts.get("offline", 0)
    return f", {offline} offline" if offline else ""


def evidence_words(found: WaveVerification) -> str:
    """A wave's evidence in words: what was gathered against what `rollout.verify` asks, the
    verdict, and who decided it by hand ('14 of 20 goals, 92% ≥ 90%: Successful')."""
    # The reconciler words it as it judges (reconciler/evidence.py); a status without them
    # (an older reconciler's) still says what was counted.
    text = found.message or f"{found.goals} of {found.min_goals} goals"
    if found.decided_by is not None:
        how = "aborted" if found.verdict == "Failed" else "resumed"
        text += f"; {how} by {found.decided_by}"
    return clean(text)


def paused_for_evidence(rollout: RolloutStatus) -> bool:
    """Whether the rollout waits on an operator because its wave's evidence is inconclusive
    (`rollout.verify.inconclusive: pause`): then resume or abort is theirs to run."""
    found = rollout.verification
    return (
        rollout.state == "Paused"
        and found is not None
        and found.verdict == "Inconclusive"
        and not found.dry_run  # a dry run does not gate: it pauses nothing
        and found.decided_by is None
    )


def stages_words(rollout: RolloutStatus) -> str:
    """The promotion ladder in a few words: 'sim verified a3f… > real waiting (keeps 8be…)'."""
    parts = []
    for stage in rollout.stages:
        kept = short_rev(stage.verified_revision)
        tail = f" {kept}" if stage.state == "verified" else f" (keeps {kept})"
        parts.append(f"{clean(stage.name)} {clean(stage.state)}{tail}")
    return " > ".join(parts)


SUBJECT_SHOWN = 48  # characters of a commit subject in a line of text


def rev_text(revision: str | None, status: ReconcilerStatus | None) -> str:
    """A revision as people read it: its 12 hex digits, and its commit's subject in quotes
    when the reconciler's status carries it (`3f2a9c1b7d0e "Rename the lab robots"`)."""
    line = status.commit(revision) if status is not None else None
    if line is None or not line.subject:
        return short_rev(revision)
    return f'{short_rev(revision)} "{clean(shorten(line.subject, SUBJECT_SHOWN))}"'


def rollout_line(rollout: RolloutStatus, status: ReconcilerStatus | None = None) -> str:
    """The rollout in one line: revision (and its commit's subject, from `status`), state,
    where, who is healthy, failed, pending, the wave's evidence when `rollout.verify` gathers
    it, why."""
    counts = rollout.counts
    line = (
        f"rollout: {rev_text(rollout.revision, status)} {clean(rollout.state)}, "
        f"wave {rollout.wave + 1}/{rollout.waves} ({clean(rollout.wave_name)}): "
        f"{counts.get('healthy', 0)} healthy, {counts.get('failed', 0)} failed, "
        f"{counts.get('pending', 0)} pending{_offline_count(rollout)}; "
        f"stable {short_rev(rollout.stable_revision)}"
    )
    if rollout.stages:
        line += "; stages " + stages_words(rollout)
    if rollout.failed:
        line += f"; failed: {clean(', '.join(rollout.failed[:5]))}"
    if rollout.offline:
        more = ", ..." if counts.get("offline", 0) > 5 else ""
        line += f"; offline (get it when back): {clean(', '.join(rollout.offline[:5]))}{more}"
    found = rollout.verification
    # The reconciler's message quotes the evidence while the wave waits on it: said once.
    if found is not None and not (found.message and found.message in rollout.message):
        line += f"; evidence {evidence_words(found)}"
    if rollout.message:
        line += f" — {clean(rollout.message)}"
    if paused_for_evidence(rollout) and RESUME_COMMAND not in rollout.message:
        line += f" — {VERIFY_COMMANDS}"
    return line


def reconciler_lines(status: ReconcilerStatus | None, at: float | None = None) -> list[str]:
    if status is None:
        return [
            "reconciler: MISSING — no reconciler status on the broker: no reconciler runs on "
            "this prefix (start `robotconf reconcile`)"
        ]
    at = time.time() if at is None else at
    where = f" on {clean(status.branch)}" if status.branch else ""
    why = f" ({clean(status.reason)})" if status.reason and status.reason != status.state else ""
    line = (
        f"reconciler: {clean(status.state)}{why}{where}, "
        f"applied {rev_text(status.last_applied_revision, status)}, "
        f"attempted {_attempted(status)}"
    )
    if status.failed_revision:
        failed = status.failed_revision
        said = failed == status.last_attempted_revision  # its subject is said just before
        line += f", failed on {short_rev(failed) if said else rev_text(failed, status)}"
    line += f", {status.robots} robots"
    if status.message:
        line += f" — {clean(status.message)}"
    lines = [line]
    if reconciler_health(status, at) is Health.STALE and status.heartbeat is not None:
        lines.append(
            f"  STALE: its last heartbeat is {at - status.heartbeat:.0f} s old and it beats "
            f"every {status.interval or 0:g} s: is the reconciler still running?"
        )
    if status.rollout is not None:
        lines.append(rollout_line(status.rollout, status))
    if status.broker_dropped:
        lines.append(
            f"  the broker dropped retained messages sent to it ({clean(status.broker_dropped)}):"
            " raise its max_queued_messages (robotconf broker-config sets it for the fleet)"
        )
    return lines + diagnostic_lines(status, 10)


def _attempted(status: ReconcilerStatus) -> str:
    """The attempted revision; its subject only when it is not the applied one's (said)."""
    attempted = status.last_attempted_revision
    if attempted == status.last_applied_revision:
        return short_rev(attempted)
    return rev_text(attempted, status)


def diagnostic_lines(status: ReconcilerStatus, limit: int) -> list[str]:
    """The status's first `limit` diagnostics, indented, and how many more there are (those
    left out of the status itself included)."""
    shown = status.diagnostics[:limit]
    lines = [f"  {clean(str(d))}" for d in shown]
    more = len(status.diagnostics) - len(shown) + status.more_diagnostics
    if more > 0:
        lines.append(f"  ... {more} more")
    return lines
