"""Rollout step, pure: a commit reaches the fleet wave by wave, each gated by the robots' health.

Where a rollout stands is read back from what the broker holds — the retained launch topics,
the robots' statuses, the rollout in the reconciler's retained status and what the current wave
established (`reconciler.wave_memory`) — so a restarted reconciler resumes the same wave without
publishing anything anew, and neither forgets a robot it saw healthy or failed nor counts one
healthy it has not seen so.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum

from configurator.render import FleetRender
from configurator.rendered import RenderedRequest
from configurator.stages import WavePlan, WaveSpec, plan_waves
from configurator.types import RolloutPolicy, Verify
from configurator.waves import failure_budget
from contract.notes import VerdictNote
from contract.wire import (
    MAX_LISTED,
    VERIFY_COMMANDS,
    AgentState,
    AgentStatus,
    RolloutState,
    RolloutStatus,
    StageState,
    StageWord,
    WaveVerification,
    is_online,
    short_rev,
)
from reconciler.evidence import Counts, EvidenceKey, Roles, WaveEvidence, judge, new_evidence
from reconciler.wave_memory import WaveMemory, WaveRecord, memory_of

# An agent reporting these about the new request has failed it.
_FAILED_STATES = {AgentState.FAILED, AgentState.BACKOFF, AgentState.EXITED}
# Seconds a robot stays dark, watched without a break, before it counts as gone: a broker that
# shuts down publishes every client's Last Will just before it drops the reconciler too.
DARK_GRACE = 2.0
# Seconds between looks at a wave's evidence while it is gathered: outcomes arrive on their own
# schedule (the ledger's feed), and a verdict a second or two later is soon enough.
VERIFY_POLL = 2.0


class Health(str, Enum):
    """A robot of the current wave, judged only on what it reports about the new request."""

    HEALTHY = "healthy"  # ran the new request for healthy_after seconds
    FAILED = "failed"  # failed, backed off, exited or refused it; went dark; timed out
    PENDING = "pending"  # on its way
    ABSENT = "absent"  # never seen online with it: pending, never failed; waited for until timeout
    # Offline (dark for DARK_GRACE) and never seen online since its wave published its request,
    # under `offline: skip`: the wave goes on without it; it gets the request when it is back.
    OFFLINE = "offline"


@dataclass(frozen=True)
class RolloutInput:
    """What the rollout of `head` sees at one step."""

    head: FleetRender  # the commit rolled out; has a policy
    stable: FleetRender | None  # the last revision that fully rolled out
    previous: RolloutStatus | None  # from the reconciler's retained status
    launches: Mapping[str, str | None]  # robot -> digest held on its launch topic
    statuses: Mapping[str, AgentStatus] | None  # None: not known yet (health not judged)
    running_since: Mapping[str, float]  # robot -> unix time it was first seen running its digest
    now: float
    # What the current wave established (the last step's record, or the retained one after a
    # restart), and when the statuses were last (re)learned: the wave's clock counts from then.
    record: WaveRecord | None = None
    watching_since: float = 0.0
    # robot -> when the reconciler first saw it dark (offline, or its status gone) since then
    dark_since: Mapping[str, float] = field(default_factory=dict)
    # How the statuses' read is known to lack messages the broker dropped (its queue limit),
    # or None: then a robot without any status is unknown, not offline, and not dark.
    statuses_lost: str | None = None
    # Robots whose new request is held back for drift (drift: hold): not sent it, they count
    # as absent — pending, never failed; the wave goes on without them at its timeout.
    held: frozenset[str] = frozenset()
    # rollout.verify: the goal outcomes counted for the wave `evidence.key` names (another
    # wave's are not used), the stable revision's own counts per scenario (compare's fallback),
    # and the notes of the head's commit (an operator's resume or abort of a wave run).
    evidence: WaveEvidence | None = None
    baseline: Mapping[str, Counts] = field(default_factory=dict)
    notes: Sequence[VerdictNote] = ()
    # fleet.yaml stages: the builds of the revisions verified for a stage's robots when the
    # rollout began (`stage_bases`) that are not the stable one, by revision.
    stage_builds: Mapping[str, FleetRender] = field(default_factory=dict)


@dataclass
class RolloutStep:
    """What the broker should hold now, and where the rollout stands."""

    requests: dict[str, RenderedRequest] = field(default_factory=dict)  # to hold (publish if not)
    keep: set[str] = field(default_factory=set)  # left exactly as they are
    status: RolloutStatus | None = None
    recheck_at: float | None = None  # unix time a health judgment changes with no new message
    complete: bool = False  # every wave healthy: `head` is the new stable revision
    serve_stable: bool = False  # rolled back: the fleet gets the stable revision
    record: WaveRecord | None = None  # what the current wave established, to keep retained
    # Verdicts reached in this step (a wave verified and passed, failed, inconclusive): to note.
    verdicts: list[VerdictNote] = field(default_factory=list)

    @property
    def stopped(self) -> bool:
        return self.status is not None and self.status.state in ("Halted", "RolledBack")


def stable_revision_of(previous: RolloutStatus | None, applied: str | None) -> str | None:
    """The last revision that fully rolled out: the previous rollout's when it completed."""
    if previous is None:
        return applied
    if previous.state == "Complete":
        return previous.revision
    return previous.stable_revision


def stage_bases(
    head: FleetRender, previous: RolloutStatus | None, stable: str | None
) -> list[str | None]:
    """Per stage of the head (fleet.yaml stages), the revision verified for its robots when
    the rollout of the head began: what they keep until the head is verified on the stage
    before, and go back to if it fails on theirs. Read from the retained rollout: its own
    (a restart), or the one before it (a new head: what each stage verified last); a stage it
    does not name has the stable revision."""
    if not head.stages:
        return []
    same = previous is not None and previous.revision == head.revision
    known = {stage.name: stage for stage in previous.stages} if previous is not None else {}
    bases: list[str | None] = []
    for stage in head.stages:
        found = known.get(stage.name)
        base = None
        if found is not None:
            base = found.rollback_revision if same else found.verified_revision
        bases.append(base or stable)
    return bases


def kept_requests(
    head: FleetRender,
    stable: FleetRender | None,
    bases: Sequence[str | None],
    builds: Mapping[str, FleetRender],
    plan: WavePlan,
) -> Mapping[str, RenderedRequest]:
    """What each robot keeps while the rollout has not moved it: the stable revision's
    request, or (fleet.yaml stages) the one of the revision verified for its stage. A stage
    whose revision could not be built keeps the stable one."""
    requests: Mapping[str, RenderedRequest] = stable.requests if stable is not None else {}
    revision = stable.revision if stable is not None else None
    other = {
        index: builds[base]
        for index, base in enumerate(bases)
        if base is not None and base != revision and base in builds
    }
    if not other:
        return requests
    merged = dict(requests)
    for robot, stage in plan.stage_of.items():
        build = other.get(stage)
        request = build.requests.get(robot) if build is not None else None
        if request is not None:
            merged[robot] = request
    return merged


def roll_out(seen: RolloutInput) -> RolloutStep:
    """The next step of rolling `head` out; see the module docstring and docs/how-to/rollouts.md."""
    head, stable, previous = seen.head, seen.stable, seen.previous
    policy = head.rollout
    assert policy is not None
    plan = plan_waves(head)
    bases = stage_bases(head, previous, stable.revision if stable is not None else None)
    stable_requests = kept_requests(head, stable, bases, seen.stage_builds, plan)
    changed = _changed(head, stable_requests)
    same = previous is not None and previous.revision == head.revision
    base = _Rollout(seen, policy, plan, changed, stable_requests, bases)
    if not changed or (same and previous is not None and previous.state == "Complete"):
        return base.everyone()  # nothing to move (paused or not), or moved already
    if same and previous is not None and previous.state == "RolledBack":
        return base.rolled_back(previous)
    if same and previous is not None and previous.state in ("Halted", "Progressing", "Paused"):
        started = previous.wave_started_at
        # Read back from the broker: a wave out of range (another reconciler's, a hand-made
        # status) is brought into range rather than trusted.
        wave = min(max(previous.wave, 0), base.count - 1) if started is not None else -1
        if previous.state == "Halted":
            return base.halted(previous)
        return base.advance(wave, started)
    return base.advance(-1, None)


def _changed(head: FleetRender, stable_requests: Mapping[str, RenderedRequest]) -> set[str]:
    """The robots the rollout moves: not suspended, and with a request the stable lacks."""
    return {
        robot
        for robot, request in head.requests.items()
        if robot not in head.suspended
        and (robot not in stable_requests or stable_requests[robot].digest != request.digest)
    }


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


def wave_roles(
    head: FleetRender,
    stable: FleetRender | None,
    wave: int,
    plan: WavePlan | None = None,
    kept: Mapping[str, RenderedRequest] | None = None,
) -> Roles:
    """Whose goal outcomes count toward `wave`'s verification: its moved robots on the head's
    requests (for a stage's gate, every moved robot of the stage), and the robots no wave has
    moved yet on what they keep (the comparison): `kept` (`kept_requests`), else the stable
    revision's requests."""
    stable_requests = kept if kept is not None else stable.requests if stable is not None else {}
    plan = plan if plan is not None else plan_waves(head)
    return _roles(plan, head, _changed(head, stable_requests), stable_requests, wave)


def _roles(
    plan: WavePlan,
    head: FleetRender,
    changed: set[str],
    stable_requests: Mapping[str, RenderedRequest],
    wave: int,
) -> Roles:
    last = len(plan.specs)
    spec = plan.specs[wave] if 0 <= wave < last else None
    new: dict[str, str] = {}
    kept: dict[str, str] = {}
    for robot in changed:
        at = plan.of.get(robot, last)
        ours = at == wave
        if spec is not None and spec.gate:
            ours = plan.stage_of.get(robot) == spec.stage and at < wave
        if ours:
            new[robot] = head.requests[robot].digest
        elif at > wave and robot in stable_requests:
            kept[robot] = stable_requests[robot].digest
    return Roles(new, kept)


@dataclass
class _Gate:
    """A wave's evidence at one step: may it go on, is it held (why), or has it failed."""

    done: bool
    verification: WaveVerification | None
    held_for: str = ""  # "inconclusive" (paused for an operator) or "gathering"
    failed: str | None = None  # why the wave fails by its evidence
    poll: float | None = None  # when to look at the evidence again


class _Rollout:
    def __init__(
        self,
        seen: RolloutInput,
        policy: RolloutPolicy,
        plan: WavePlan,
        changed: set[str],
        stable_requests: Mapping[str, RenderedRequest],
        bases: Sequence[str | None] = (),
    ) -> None:
        self.seen = seen
        self.bases = list(bases)  # per stage: what its robots keep (`stage_bases`)
        self.revoked: int | None = None  # a verified stage whose robots failed later
        self.policy = policy
        self.plan = plan
        self.specs = plan.specs
        self.waves = plan.of
        self.changed = changed
        self.stable_requests = stable_requests
        self.count = len(plan.specs)
        self.noted: list[VerdictNote] = []  # verdicts reached in this step
        self.busy_held: set[str] = set()  # robots whose group waits for a busy member
        self.busy_why = ""  # which group waits for whom, for the status
        self.unknown: list[str] = []  # the wave's robots whose status may have been dropped

    def _with_verdicts(self, step: RolloutStep) -> RolloutStep:
        step.verdicts = self.noted
        return step

    # ------------------------------------------------------------------ what to hold

    def hold(self, started: int) -> RolloutStep:
        """Robots of started waves hold the head's request; the others are not touched (a
        robot that holds nothing readable gets the stable request back)."""
        head = self.seen.head
        step = RolloutStep()
        for robot, request in head.requests.items():
            if robot in head.suspended:
                step.requests[robot] = request  # the diff leaves suspended robots as they are
                continue
            waiting = robot in self.busy_held  # its group waits for a busy member
            if not waiting and (
                robot not in self.changed or self.waves.get(robot, self.count) <= started
            ):
                step.requests[robot] = request
            elif self.seen.launches.get(robot) is not None:
                step.keep.add(robot)
                step.requests[robot] = request  # held as it is: the diff leaves it alone
            elif robot in self.stable_requests:
                step.requests[robot] = self.stable_requests[robot]
        return step

    def everyone(self) -> RolloutStep:
        step = self.hold(self.count)
        step.complete = True
        status = self._status("Complete", self.count - 1, None, {}, "rolled out")
        # Rolled out everywhere, the head is what a later rollback would restore.
        step.status = status.model_copy(update={"stable_revision": status.revision})
        return step

    # ------------------------------------------------------------------ the states

    def advance(self, wave: int, started_at: float | None) -> RolloutStep:
        """From `wave` (-1: none started yet), publish and judge waves as far as they are
        healthy and verified; stop on too many failures or a failed verification. No wave
        begins before the robots' statuses are known: who was online when it was published is
        part of what it is judged on."""
        now = self.seen.now
        known = self.seen.statuses is not None
        if wave < 0 and not self.policy.paused and known:
            wave, started_at = 0, now
        while True:
            if wave < 0:
                return self._before_first()
            begins = started_at is None or started_at == now
            started_at = now if started_at is None else started_at
            judged, recheck, deadline, memory = self._judge(wave, started_at, begins)
            revoked = self._revocation(wave, started_at, judged)
            if revoked is not None:
                return revoked
            failed = [r for r, h in judged.items() if h is Health.FAILED]
            # A share of the robots that took part: four robots on chargers do not widen it.
            taking_part = sum(1 for h in judged.values() if h is not Health.OFFLINE)
            budget = failure_budget(self.policy.max_failures, taking_part) or 0
            verification = self._verify(wave, started_at) if known else None
            by_hand = self._decision(wave, started_at)
            name = self.specs[wave].name
            if by_hand is not None and by_hand.kind == "abort":
                why = f"aborted by {by_hand.by or 'an operator'} in wave '{name}'"
                return self._failed(wave, started_at, judged, why, verification)
            if len(failed) > budget:
                return self._failed(wave, started_at, judged, None, verification)
            healthy = known and (
                all(h in (Health.HEALTHY, Health.FAILED, Health.OFFLINE) for h in judged.values())
                or (all(h is not Health.PENDING for h in judged.values()) and now >= deadline)
            )
            gate = self._gate(wave, started_at, healthy, verification, by_hand)
            if gate.failed is not None:
                return self._failed(wave, started_at, judged, gate.failed, gate.verification)
            if gate.poll is not None:
                recheck = gate.poll if recheck is None else min(recheck, gate.poll)
            if gate.done and wave == self.count - 1:
                return self._with_verdicts(self.everyone())
            if gate.done and not self.policy.paused:
                wave, started_at = wave + 1, now
                continue
            step = self.hold(wave)
            state, why = self._standing(wave, started_at, gate)
            step.status = self._status(state, wave, started_at, judged, why, gate.verification)
            step.recheck_at = recheck
            step.record = memory.record() if memory is not None else None
            return self._with_verdicts(step)

    def _before_first(self) -> RolloutStep:
        step = self.hold(-1)
        why = (
            "paused before the first wave (rollout.paused)"
            if self.policy.paused
            else "waiting for the robots' statuses before the first wave"
        )
        state: RolloutState = "Paused" if self.policy.paused else "Progressing"
        step.status = self._status(state, 0, None, {}, why)
        return step

    def _gate(
        self,
        wave: int,
        started_at: float,
        healthy: bool,
        verification: WaveVerification | None,
        by_hand: VerdictNote | None,
    ) -> _Gate:
        """Whether a wave healthy throughout may go on by its evidence (`rollout.verify`, a
        stage's soak): passed, failed (why), or held (paused, gathering); the verdicts reached
        are noted. A dry run is judged and noted, never gating."""
        name, now = self.specs[wave].name, self.seen.now
        gate = _Gate(healthy, verification)
        if verification is not None and verification.verdict is None:
            gate.poll = min(now + VERIFY_POLL, verification.deadline or math.inf)
        gating = verification is not None and not verification.dry_run
        if gating and verification is not None and verification.verdict == "Failed":
            gate.failed = f"verification of wave '{name}' failed: {verification.message}"
            return gate
        if healthy and gating and verification is not None:
            rules = criteria(self.seen.head, self.specs[wave])
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
            self.noted.append(self._note(wave, started_at, found))
        elif gate.done and found is None and self.specs[wave].gate:
            # No soak: a stage whose every wave passed is verified; said in the notes.
            passed = WaveVerification(verdict="Successful", message="every wave passed")
            self.noted.append(self._note(wave, started_at, passed))
        return gate

    def _standing(self, wave: int, started_at: float, gate: _Gate) -> tuple[RolloutState, str]:
        """The state and why of a rollout held at `wave`: paused (by fleet.yaml, or for an
        operator), verifying, or waiting for a busy member of a group."""
        name, found = self.specs[wave].name, gate.verification
        previous = self.seen.previous
        if (
            self.seen.statuses is None
            and previous is not None
            and previous.state == "Paused"
            and (previous.revision, previous.wave, previous.wave_started_at)
            == (self.seen.head.revision, wave, started_at)
        ):
            return "Paused", previous.message  # restarted: paused until it can judge again
        state: RolloutState = "Progressing"
        why = ""
        if gate.done and self.policy.paused:
            state, why = "Paused", "paused (rollout.paused): a commit setting it false resumes"
        elif gate.held_for == "inconclusive" and found is not None:
            state = "Paused"
            why = f"wave '{name}' inconclusive ({found.message}): {VERIFY_COMMANDS}"
            self.noted.append(self._note(wave, started_at, found))
        elif gate.held_for == "gathering" and found is not None:
            why = f"wave '{name}' verifying: {found.message}"
        if self.busy_why and state == "Progressing":
            why = f"{why}; {self.busy_why}" if why else self.busy_why
        lost = self.seen.statuses_lost
        if lost is not None and self.unknown and state == "Progressing":
            said = (
                f"{len(self.unknown)} robot(s) without a status ({', '.join(self.unknown[:3])}"
                f"{', ...' if len(self.unknown) > 3 else ''}) waited for, not offline: the "
                f"broker dropped status messages ({lost})"
            )
            why = f"{why}; {said}" if why else said
        return state, why

    def halted(self, previous: RolloutStatus) -> RolloutStep:
        wave = min(max(previous.wave, 0), self.count - 1)
        if previous.wave_started_at is None:
            wave = -1
        step = self.hold(wave)
        step.status = previous.model_copy()
        return step

    def rolled_back(self, previous: RolloutStatus) -> RolloutStep:
        if self.seen.stable is None:  # the stable revision cannot be built now: hold on
            return self.halted(previous)
        stopped = [s.state in ("failed", "revoked") for s in previous.stages]
        at = stopped.index(True) if True in stopped else None
        step, _ = self._back(at)
        step.status = previous.model_copy()
        return step

    def _back(self, stage: int | None) -> tuple[RolloutStep, str]:
        """Rolled back from a failure on `stage`, and what the status says of it: the stage and
        those after it get what was verified for them when the rollout began, the stages
        before it keep the head (verified there). Without stages, or when that is the stable
        revision everywhere, the whole fleet is served the stable revision."""
        stable = self._stable_revision()
        if stage is None or (stage == 0 and all(b in (None, stable) for b in self.bases)):
            return RolloutStep(serve_stable=True), f"; rolled back to {short_rev(stable)}"
        head, step = self.seen.head, RolloutStep()
        for robot, request in head.requests.items():
            at = self.plan.stage_of.get(robot)
            if robot in head.suspended or (at is not None and at < stage):
                step.requests[robot] = request
            elif robot in self.stable_requests:
                step.requests[robot] = self.stable_requests[robot]
        for robot in self.stable_requests.keys() - head.requests.keys():
            step.requests[robot] = self.stable_requests[robot]  # gone from the head: back
        names = [s.name for s in head.stages]
        told = ", ".join(
            f"'{names[i]}' to {short_rev(self.bases[i] if i < len(self.bases) else stable)}"
            for i in range(stage, len(names))
        )
        kept = ", ".join(f"'{name}'" for name in names[:stage])
        what = f"; rolled back stage {told}" + (
            f"; stage {kept} keeps {short_rev(head.revision)}, verified there" if kept else ""
        )
        return step, what

    def _revocation(
        self, wave: int, started_at: float, judged: dict[str, Health]
    ) -> RolloutStep | None:
        """A stage verified before the current wave's, whose robots now fail on the head (crash,
        back off or exit on its request, online) beyond max_failures of its moved robots: its
        verification is revoked (a note says so), and it and the stages after it are rolled
        back. Watched until the rollout completes."""
        statuses, current = self.seen.statuses, self.specs[wave].stage
        if statuses is None or not current:
            return None
        failing: dict[int, list[str]] = {}
        moved: dict[int, int] = {}
        for robot in self.changed:
            stage = self.plan.stage_of.get(robot)
            if stage is None or stage >= current:
                continue
            moved[stage] = moved.get(stage, 0) + 1
            status = statuses.get(robot)
            if (
                is_online(status)
                and status is not None
                and status.digest == self._digest(robot)
                and status.state in _FAILED_STATES
            ):
                failing.setdefault(stage, []).append(robot)
        for stage in sorted(failing):
            robots = sorted(failing[stage])
            if len(robots) <= (failure_budget(self.policy.max_failures, moved[stage]) or 0):
                continue
            name = self.seen.head.stages[stage].name
            why = (
                f"verification of stage '{name}' revoked: {len(robots)} of its robots failed "
                f"on {short_rev(self.seen.head.revision)} after it was verified "
                f"({', '.join(robots[:5])}{', ...' if len(robots) > 5 else ''})"
            )
            self.revoked = stage
            found = WaveVerification(verdict="Failed", message=why)
            gate = next(i for i, s in enumerate(self.specs) if s.gate and s.stage == stage)
            self.noted.append(self._note(gate, None, found))  # about the stage, not a wave run
            return self._failed(wave, started_at, judged, why, found, stage, noted=True)
        return None

    def _failed(
        self,
        wave: int,
        started_at: float | None,
        judged: dict[str, Health],
        reason: str | None = None,
        verification: WaveVerification | None = None,
        stage: int | None = None,
        noted: bool = False,
    ) -> RolloutStep:
        """Stopped by a failure of `wave` (or of `stage`, verified before it): rolled back, or
        halted, as the policy says; the failed verification noted unless it is (`noted`)."""
        failed = sorted(r for r, h in judged.items() if h is Health.FAILED)
        why = reason or (
            f"{len(failed)} robot(s) of wave '{self.specs[wave].name}' failed "
            f"({', '.join(failed[:5])}{', ...' if len(failed) > 5 else ''}), over max_failures "
            f"{self.policy.max_failures}"
        )
        found = verification is not None and verification.verdict
        if found and verification is not None and started_at is not None and not noted:
            self.noted.append(self._note(wave, started_at, verification))
        rollback = self.policy.on_failure == "rollback" and self.seen.stable is not None
        if rollback:
            step, what = self._back(stage if stage is not None else self.specs[wave].stage)
            step.status = self._status(
                "RolledBack", wave, started_at, judged, why + what, verification
            )
            return self._with_verdicts(step)
        step = self.hold(wave)
        if self.policy.on_failure == "rollback":
            why += "; no revision ever fully rolled out to go back to: halted"
        step.status = self._status("Halted", wave, started_at, judged, why, verification)
        return self._with_verdicts(step)

    # ------------------------------------------------------------------ evidence

    def _verify(self, wave: int, started_at: float) -> WaveVerification | None:
        """The wave's verification by its goal outcomes (`rollout.verify`), None without one.
        Evidence counted for another wave, or none yet, is no evidence: this wave's counts
        start empty (the reconciler counts them from the ledger in the steps that follow)."""
        spec = self.specs[wave]
        verify = criteria(self.seen.head, spec)
        if verify is None or not self._judged_robots(wave):
            return None  # nothing to judge by, or no robot whose goals would say anything
        key = EvidenceKey(self.seen.head.revision, wave, started_at)
        evidence = self.seen.evidence
        if evidence is None or evidence.key != key:
            evidence = new_evidence(key, Roles({}, {}), verify)
        return judge(verify, evidence, self.seen.now, self.seen.baseline)

    def _judged_robots(self, wave: int) -> bool:
        """Whether the step moved any robot to judge: its own, or (a gate) its stage's."""
        spec = self.specs[wave]
        if not spec.gate:
            return any(self.waves.get(r) == wave for r in self.changed)
        return any(
            self.plan.stage_of.get(r) == spec.stage and self.waves.get(r, self.count) < wave
            for r in self.changed
        )

    def _decision(self, wave: int, started_at: float) -> VerdictNote | None:
        """An operator's resume or abort of this very wave run, or a promotion of the head to
        a later stage (which passes the evidence of every wave before that stage): the
        latest, from the notes."""
        head = self.seen.head
        stages = {stage.name: index for index, stage in enumerate(head.stages)}
        found = [
            note
            for note in self.seen.notes
            if (note.kind in ("resume", "abort") and note.about(head.revision, wave, started_at))
            or (
                note.kind == "promote"
                and note.revision == head.revision
                and note.stage in stages
                and wave < self.plan.first_of_stage(stages[note.stage])
            )
        ]
        return max(found, key=lambda note: note.at) if found else None

    def _note(self, wave: int, started_at: float | None, found: WaveVerification) -> VerdictNote:
        return VerdictNote(
            kind="verification",
            revision=self.seen.head.revision,
            at=self.seen.now,
            wave=wave,
            wave_name=self.specs[wave].name,
            started_at=started_at,
            stage=self._stage_name(wave),
            verdict=found.verdict,
            dry_run=found.dry_run,
            goals=found.goals,
            min_goals=found.min_goals,
            rate=found.rate,
            success_rate=found.success_rate,
            stable_rate=found.stable_rate,
            max_drop=found.max_drop,
            by=found.decided_by,
            message=found.message,
        )

    def _stage_name(self, wave: int) -> str | None:
        stage = self.specs[wave].stage if 0 <= wave < self.count else None
        return self.seen.head.stages[stage].name if stage is not None else None

    # ------------------------------------------------------------------ health

    def _judge(
        self, wave: int, started_at: float, begins: bool
    ) -> tuple[dict[str, Health], float | None, float, WaveMemory | None]:
        """The health of the wave's changed robots; when a judgment changes with time; the
        wave's deadline; and what the wave has established, this step included."""
        head, policy, now = self.seen.head, self.policy, self.seen.now
        members = sorted(r for r in self.changed if self.waves.get(r) == wave)
        statuses = self.seen.statuses
        if statuses is None:  # not known yet: nothing is judged, nothing is forgotten
            memory = memory_of(self.seen.record, head.revision, wave, started_at, members)
            return {r: Health.PENDING for r in members}, None, math.inf, memory
        memory = self._memory(wave, started_at, members, statuses, begins)
        # The wave's clock runs while the reconciler watches: restarted, or back from a lost
        # broker, it gives the robots the whole wave_timeout again rather than blame them for
        # what it could not see.
        deadline = max(started_at, memory.watching_since) + policy.wave_timeout
        deadline = deferral_deadline(memory, members, statuses, now, deadline, policy)
        deadline, held_until = self._hold_busy_groups(members, statuses, memory, deadline)
        judged: dict[str, Health] = {}
        times: list[float] = []  # when a judgment changes with time
        for robot in members:
            judged[robot] = self._judge_robot(robot, statuses, memory, deadline, times.append)
        self.unknown = [r for r in members if self._unknown(r, statuses)]
        self._fail_groups(judged, memory)
        if held_until is not None:
            times.append(held_until)  # the group goes at its max_defer at the latest
        return judged, min(times, default=None), deadline, memory

    def _judge_robot(
        self,
        robot: str,
        statuses: Mapping[str, AgentStatus],
        memory: WaveMemory,
        deadline: float,
        soon: Callable[[float], None],
    ) -> Health:
        """One robot of the wave, and (`soon`) when its judgment may change with time."""
        policy, now = self.policy, self.seen.now
        digest = self.seen.head.requests[robot].digest
        since = self.seen.running_since.get(robot)
        dark_at = self.seen.dark_since.get(robot, memory.watching_since) + DARK_GRACE
        unknown = self._unknown(robot, statuses)
        health = (
            Health.ABSENT
            if robot in self.seen.held
            else _health(
                robot,
                statuses.get(robot),
                digest,
                self.seen.launches.get(robot) == digest,
                since,
                now >= dark_at and not unknown,
                now,
                policy.healthy_after,
                memory,
            )
        )
        if health is Health.ABSENT and robot not in self.seen.held and not unknown:
            health = self._offline(robot, now >= dark_at, memory)
            if health is Health.ABSENT and policy.offline != "wait":
                soon(dark_at)  # dark a moment ago (a reconnecting agent): offline once it lasts
        dark = robot in memory.seen and not is_online(statuses.get(robot))
        if health is Health.PENDING and dark and now < dark_at and robot not in memory.doubted:
            soon(dark_at)  # dark a moment ago: gone once it has lasted
        if health is Health.PENDING and since is not None:
            soon(since + policy.healthy_after)
        if health is Health.PENDING and now >= deadline:
            health = Health.FAILED  # not healthy by wave_timeout
            memory.failed.add(robot)
        if health in (Health.PENDING, Health.ABSENT) and now < deadline:
            soon(deadline)
        return health

    def _hold_busy_groups(
        self,
        members: list[str],
        statuses: Mapping[str, AgentStatus],
        memory: WaveMemory,
        deadline: float,
    ) -> tuple[float, float | None]:
        """A group changes restart-class content only when all its robots can: while one of
        the wave's groups has a busy robot (its brain's hold file) and the change restarts a
        brain of it, none of the group is sent its request — for the robots' `max_defer` at
        most, from the first look that held it (kept in the wave's record); then they are sent
        it and each agent defers as usual. The wave's deadline gives them wave_timeout after.
        Returns the deadline and when the hold ends (None: nothing held)."""
        group_of, now = self.plan.group_of, self.seen.now
        self.busy_held, self.busy_why = set(), ""
        if not group_of:
            return deadline, None
        groups: dict[str, list[str]] = {}
        for robot in members:
            if robot in group_of:
                groups.setdefault(group_of[robot], []).append(robot)
        waiting: dict[str, tuple[str, float]] = {}  # group -> (a busy robot, its max_defer)
        for group, robots in groups.items():
            restarts = any(self._restarts(r) for r in robots)
            if not restarts or all(self.seen.launches.get(r) == self._digest(r) for r in robots):
                continue  # nothing to restart, or already sent
            for robot in robots:
                status = statuses.get(robot)
                if status is not None and status.busy and is_online(status):
                    waiting[group] = (robot, status.max_defer or 0.0)
                    break
        if not waiting:
            return deadline, None
        if memory.held_since is None:
            memory.held_since = now
        until = memory.held_since + max(defer for _, defer in waiting.values())
        if now >= until:
            return deadline, None  # held for max_defer: sent now, each agent defers as usual
        for group in waiting:
            self.busy_held.update(groups[group])
        self.busy_why = (
            "; ".join(
                f"group '{group}' waits while {robot} is busy"
                for group, (robot, _) in waiting.items()
            )
            + f" (until {until - now:.0f} s from now at most)"
        )
        return max(deadline, until + self.policy.wave_timeout), until

    def _restarts(self, robot: str) -> bool:
        """Whether the head's request restarts the robot's brain (not a reload)."""
        old = self.stable_requests.get(robot)
        new = self.seen.head.requests[robot]
        return old is None or old.restart_digest != new.restart_digest

    def _digest(self, robot: str) -> str:
        return self.seen.head.requests[robot].digest

    def _fail_groups(self, judged: dict[str, Health], memory: WaveMemory) -> None:
        """A group moves as one: a member that failed fails the others of the wave too (the
        thesis' cooperation: a delivery robot without its guide has not done its work)."""
        group_of = self.plan.group_of
        failing = {group_of[r] for r, h in judged.items() if h is Health.FAILED and r in group_of}
        for robot, health in judged.items():
            if health is not Health.FAILED and group_of.get(robot) in failing:
                judged[robot] = Health.FAILED
                memory.failed.add(robot)

    def _unknown(self, robot: str, statuses: Mapping[str, AgentStatus]) -> bool:
        """A robot without any status while the read is known to lack messages the broker
        dropped: its status may be one of them. It is waited for (absent: until wave_timeout,
        never failed for it), not taken for offline or dark."""
        return self.seen.statuses_lost is not None and robot not in statuses

    def _offline(self, robot: str, lasted: bool, memory: WaveMemory) -> Health:
        """A robot never seen online since its wave published its request, dark now: what
        `rollout.offline` makes of it once it has been dark for DARK_GRACE. One seen since (online
        as the wave was published, or later) is never this: gone dark, it failed (_health)."""
        if not lasted or self.policy.offline == "wait":
            return Health.ABSENT
        if self.policy.offline == "fail":
            memory.failed.add(robot)
            return Health.FAILED
        return Health.OFFLINE

    def _memory(
        self,
        wave: int,
        started_at: float,
        members: list[str],
        statuses: Mapping[str, AgentStatus],
        begins: bool,
    ) -> WaveMemory:
        """The wave's memory: its record when it is about this wave, else a new one whose
        baseline is what is true now."""
        head, watching_since = self.seen.head, self.seen.watching_since
        memory = memory_of(self.seen.record, head.revision, wave, started_at, members)
        if memory is None:
            memory = WaveMemory(head.revision, wave, started_at, members, watching_since)
            memory.rejecting = {
                r for r in members if (s := statuses.get(r)) and s.state is AgentState.REJECTED
            }
            if begins:  # published in this step: those online now are sent it at once
                memory.seen = {r for r in members if is_online(statuses.get(r))}
        elif memory.watching_since != watching_since:
            # The statuses were learned anew (a restart, a reconnection): a robot dark now may
            # have died meanwhile, or only be one whose broker restarted (which publishes every
            # Last Will as it stops, or forgets them all): it has until the deadline to be back.
            memory.doubted = {r for r in memory.seen if not is_online(statuses.get(r))}
            memory.watching_since = watching_since
        return memory

    # ------------------------------------------------------------------ status

    def _behind(self, wave: int, judged: Mapping[str, Health]) -> set[str]:
        """Robots of the waves up to `wave` (not judged in it) that are offline and do not
        report running the head's request: passed by while they were off, they get it when
        they reconnect (listed until then, after the rollout completed too)."""
        statuses, head = self.seen.statuses, self.seen.head
        if statuses is None:
            return set()
        behind = set()
        # Every robot, not only the changed ones: once complete, the head is the stable
        # revision and nothing is changed, but a robot that was off is still behind.
        for robot in head.requests.keys() - head.suspended:
            status = statuses.get(robot)
            if robot in judged or self.waves.get(robot, self.count) > wave or is_online(status):
                continue
            if self._unknown(robot, statuses):
                continue  # its status may be one the broker dropped: not known to be off
            if status is None or status.digest != head.requests[robot].digest:
                behind.add(robot)
        return behind

    def _stable_revision(self) -> str | None:
        stable = self.seen.stable
        return stable.revision if stable is not None else None

    def _status(
        self,
        state: RolloutState,
        wave: int,
        started_at: float | None,
        judged: Mapping[str, Health],
        message: str,
        verification: WaveVerification | None = None,
    ) -> RolloutStatus:
        def robots(*kinds: Health) -> list[str]:
            return sorted(r for r, h in judged.items() if h in kinds)

        healthy, failed = robots(Health.HEALTHY), robots(Health.FAILED)
        pending = robots(Health.PENDING, Health.ABSENT)
        index = max(0, min(wave, self.count - 1))
        offline = sorted(set(robots(Health.OFFLINE)) | self._behind(wave, judged))
        counts = {"healthy": len(healthy), "failed": len(failed), "pending": len(pending)}
        return RolloutStatus(
            revision=self.seen.head.revision,
            stable_revision=self._stable_revision(),
            state=state,
            wave=index,
            waves=self.count,
            wave_name=self.specs[index].name,
            wave_started_at=started_at,
            healthy=healthy[:MAX_LISTED],
            failed=failed[:MAX_LISTED],
            pending=pending[:MAX_LISTED],
            offline=offline[:MAX_LISTED],
            counts={**counts, "offline": len(offline)} if offline else counts,
            verification=verification,
            stage=self._stage_name(index),
            stages=self._stages(state, index),
            message=message,
        )

    def _stages(self, state: RolloutState, wave: int) -> list[StageState]:
        """Each stage's standing: stages before the current wave's are verified on the head;
        the current one rolls, verifies (at its gate) or failed; later ones wait, keeping what
        was verified for them (`stage_bases`). A verified stage revoked is where it stopped."""
        head, stable = self.seen.head, self._stable_revision()
        stopped = state in ("RolledBack", "Halted")
        current = self.specs[wave].stage if 0 <= wave < self.count else None
        at = self.revoked if stopped and self.revoked is not None else current
        found: list[StageState] = []
        for index, stage in enumerate(head.stages):
            base = self.bases[index] if index < len(self.bases) else stable
            word: StageWord
            verified: str | None
            if state == "Complete" or (at is not None and index < at):
                word, verified = "verified", head.revision
            elif index == at:
                if stopped:
                    word = "revoked" if index == self.revoked else "failed"
                else:
                    word = "verifying" if self.specs[wave].gate else "rolling"
                verified = base
            else:
                word, verified = "waiting", base
            found.append(
                StageState(
                    name=stage.name, state=word, verified_revision=verified, rollback_revision=base
                )
            )
        return found


def deferral_deadline(
    memory: WaveMemory,
    members: list[str],
    statuses: Mapping[str, AgentStatus],
    now: float,
    deadline: float,
    policy: RolloutPolicy,
) -> float:
    """The wave's deadline with its busy robots: a robot whose brain holds off the new request
    (state `deferred`) is neither healthy nor failed while it defers — its agent proceeds by
    its max_defer at the latest — and the wave gives it wave_timeout again from the last look
    that saw it deferring, or just done deferring, to start and settle. Going dark still fails
    it (`_health`): it may have died of the new request."""
    for robot in members:
        status = statuses.get(robot)
        if status is not None and status.state is AgentState.DEFERRED:
            memory.deferring.add(robot)
            memory.deferred_at = now
        elif robot in memory.deferring:
            memory.deferring.discard(robot)
            memory.deferred_at = now
    if memory.deferred_at is None:
        return deadline
    return max(deadline, memory.deferred_at + policy.wave_timeout)


def _health(
    robot: str,
    status: AgentStatus | None,
    digest: str,
    delivered: bool,
    running_since: float | None,
    gone: bool,
    now: float,
    healthy_after: float,
    memory: WaveMemory,
) -> Health:
    """One robot of the current wave, judged on what the reconciler saw and remembers — never
    on a robot's clock. A status about another digest never counts as health (the trap of
    judging a wave by robots still reporting the previous request)."""
    if robot in memory.failed:
        return Health.FAILED  # a failure is not undone by what comes after, in this wave
    if not is_online(status):
        if robot not in memory.seen:
            return Health.ABSENT
        if gone and robot not in memory.doubted:
            # Dark (its Last Will, or no status at all) after it was sent the new request,
            # for DARK_GRACE: it may have died of it, whatever times its Will carries.
            memory.failed.add(robot)
            return Health.FAILED
        return Health.PENDING  # failed at the wave's deadline if it is not back by then
    assert status is not None
    memory.doubted.discard(robot)
    if status.state is not AgentState.REJECTED:
        memory.rejecting.discard(robot)
    if not delivered:
        return Health.PENDING
    memory.seen.add(robot)
    if status.state is AgentState.REJECTED:
        if robot in memory.rejecting:
            return Health.PENDING  # a rejection from before the wave, not of its request
        memory.failed.add(robot)
        return Health.FAILED  # it refused the new request
    if status.digest != digest:
        return Health.PENDING
    if status.state in _FAILED_STATES:
        memory.failed.add(robot)
        return Health.FAILED
    if robot in memory.healthy:
        return Health.HEALTHY
    settled = running_since is not None and now - running_since >= healthy_after
    if status.state is AgentState.RUNNING and settled:
        memory.healthy.add(robot)
        return Health.HEALTHY
    return Health.PENDING
