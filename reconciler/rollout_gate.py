"""The rollout's gates, pure: whether a wave healthy throughout may go on by its evidence
(`rollout.verify`, a stage's soak, an operator's decision), and whether a stage verified
before has its verification revoked by robots failing on the head since."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from robotconf.configurator.render import FleetRender
from robotconf.configurator.stages import WaveSpec
from robotconf.configurator.types import Verify
from robotconf.configurator.waves import failure_budget
from robotconf.contract.notes import VerdictNote
from robotconf.contract.wire import WaveVerification, is_online, short_rev
from robotconf.reconciler.evidence import EvidenceKey, Roles, judge, new_evidence
from robotconf.reconciler.rollout_health import FAILED_STATES
from robotconf.reconciler.rollout_report import verdict_note
from robotconf.reconciler.rollout_scope import RolloutScope

# Seconds between looks at a wave's evidence while it is gathered: outcomes arrive on their own
# schedule (the ledger's feed), and a verdict a second or two later is soon enough.
VERIFY_POLL = 2.0


def criteria(head: FleetRender, spec: WaveSpec) -> Verify | None:
    """What a step's evidence is judged by: `rollout.verify` for a wave; for a stage's gate,
    its soak (that many goals more, ended by the whole stage after its last wave, judged by
    the same criteria), or nothing (a stage whose waves all passed is verified)."""
    verify = head.rollout.verify if head.rollout is not None else None
    if not spec.gate:
        return verify
    soak = head.stages[spec.stage].soak if spec.stage is not None else None
    if soak is None:
        return None
    base = verify if verify is not None else Verify()
    return base.model_copy(update={"min_goals": max(base.min_goals, soak.goals)})


@dataclass
class WaveGate:
    """A wave's evidence at one step: may it go on, is it held (why), or has it failed."""

    done: bool
    verification: WaveVerification | None
    held_for: str = ""  # "inconclusive" (paused for an operator) or "gathering"
    failed: str | None = None  # why the wave fails by its evidence
    poll: float | None = None  # when to look at the evidence again
    notes: list[VerdictNote] = field(default_factory=list)  # verdicts reached: to note


@dataclass(frozen=True)
class Revocation:
    """A verified stage whose robots failed on the head later: why, and the note saying so."""

    stage: int
    why: str
    verification: WaveVerification
    note: VerdictNote


def evidence_gate(
    scope: RolloutScope,
    wave: int,
    started_at: float,
    healthy: bool,
    verification: WaveVerification | None,
    by_hand: VerdictNote | None,
) -> WaveGate:
    """Whether a wave healthy throughout may go on by its evidence (`rollout.verify`, a
    stage's soak): passed, failed (why), or held (paused, gathering); the verdicts reached
    are noted. A dry run is judged and noted, never gating."""
    name, now = scope.specs[wave].name, scope.seen.now
    gate = WaveGate(healthy, verification)
    if verification is not None and verification.verdict is None:
        gate.poll = min(now + VERIFY_POLL, verification.deadline or math.inf)
    gating = verification is not None and not verification.dry_run
    if gating and verification is not None and verification.verdict == "Failed":
        gate.failed = f"verification of wave '{name}' failed: {verification.message}"
        return gate
    if healthy and gating and verification is not None:
        rules = criteria(scope.seen.head, scope.specs[wave])
        assert rules is not None  # a verification is made only by criteria
        verdict = verification.verdict
        if by_hand is not None and by_hand.kind in ("resume", "promote"):
            gate.verification = verification.model_copy(update={"decided_by": by_hand.by})
        elif verdict == "Inconclusive" and rules.inconclusive == "fail":
            gate.failed = f"verification of wave '{name}' inconclusive: {verification.message}"
            return gate
        elif verdict == "Inconclusive" and rules.inconclusive == "pause":
            gate.done, gate.held_for = False, "inconclusive"
        elif verdict is None:
            gate.done, gate.held_for = False, "gathering"
    found = gate.verification
    if gate.done and found is not None and (found.verdict or found.decided_by):
        gate.notes.append(verdict_note(scope, wave, started_at, found))
    elif gate.done and found is None and scope.specs[wave].gate:
        # No soak: a stage whose every wave passed is verified; said in the notes.
        passed = WaveVerification(verdict="Successful", message="every wave passed")
        gate.notes.append(verdict_note(scope, wave, started_at, passed))
    return gate


def wave_verification(scope: RolloutScope, wave: int, started_at: float) -> WaveVerification | None:
    """The wave's verification by its goal outcomes (`rollout.verify`), None without one.
    Evidence counted for another wave, or none yet, is no evidence: this wave's counts
    start empty (the reconciler counts them from the ledger in the steps that follow)."""
    spec = scope.specs[wave]
    verify = criteria(scope.seen.head, spec)
    if verify is None or not _judged_robots(scope, wave):
        return None  # nothing to judge by, or no robot whose goals would say anything
    key = EvidenceKey(scope.seen.head.revision, wave, started_at)
    evidence = scope.seen.evidence
    if evidence is None or evidence.key != key:
        evidence = new_evidence(key, Roles({}, {}), verify)
    return judge(verify, evidence, scope.seen.now, scope.seen.baseline)


def _judged_robots(scope: RolloutScope, wave: int) -> bool:
    """Whether the step moved any robot to judge: its own, or (a gate) its stage's."""
    spec = scope.specs[wave]
    if not spec.gate:
        return any(scope.waves.get(r) == wave for r in scope.changed)
    return any(
        scope.plan.stage_of.get(r) == spec.stage and scope.waves.get(r, scope.count) < wave
        for r in scope.changed
    )


def decision(scope: RolloutScope, wave: int, started_at: float) -> VerdictNote | None:
    """An operator's resume or abort of this very wave run, or a promotion of the head to
    a later stage (which passes the evidence of every wave before that stage): the
    latest, from the notes."""
    head = scope.seen.head
    stages = {stage.name: index for index, stage in enumerate(head.stages)}
    found = [
        note
        for note in scope.seen.notes
        if (note.kind in ("resume", "abort") and note.about(head.revision, wave, started_at))
        or (
            note.kind == "promote"
            and note.revision == head.revision
            and note.stage in stages
            and wave < scope.plan.first_of_stage(stages[note.stage])
        )
    ]
    return max(found, key=lambda note: note.at) if found else None


def revocation(scope: RolloutScope, wave: int) -> Revocation | None:
    """A stage verified before the current wave's, whose robots now fail on the head (crash,
    back off or exit on its request, online) beyond max_failures of its moved robots: its
    verification is revoked (a note says so), and it and the stages after it are rolled
    back. Watched until the rollout completes."""
    statuses, current = scope.seen.statuses, scope.specs[wave].stage
    if statuses is None or not current:
        return None
    failing: dict[int, list[str]] = {}
    moved: dict[int, int] = {}
    for robot in scope.changed:
        stage = scope.plan.stage_of.get(robot)
        if stage is None or stage >= current:
            continue
        moved[stage] = moved.get(stage, 0) + 1
        status = statuses.get(robot)
        if (
            is_online(status)
            and status is not None
            and status.digest == scope.digest(robot)
            and status.state in FAILED_STATES
        ):
            failing.setdefault(stage, []).append(robot)
    for stage in sorted(failing):
        robots = sorted(failing[stage])
        if len(robots) <= (failure_budget(scope.policy.max_failures, moved[stage]) or 0):
            continue
        name = scope.seen.head.stages[stage].name
        why = (
            f"verification of stage '{name}' revoked: {len(robots)} of its robots failed "
            f"on {short_rev(scope.seen.head.revision)} after it was verified "
            f"({', '.join(robots[:5])}{', ...' if len(robots) > 5 else ''})"
        )
        found = WaveVerification(verdict="Failed", message=why)
        gate = next(i for i, s in enumerate(scope.specs) if s.gate and s.stage == stage)
        note = verdict_note(scope, gate, None, found)  # about the stage, not a wave run
        return Revocation(stage, why, found, note)
    return None
