"""Rollout step, pure: a commit reaches the fleet wave by wave, each gated by the robots' health.

Where a rollout stands is read back from what the broker holds — the retained launch topics,
the robots' statuses, the rollout in the reconciler's retained status and what the current wave
established (`reconciler.wave_memory`) — so a restarted reconciler resumes the same wave without
publishing anything anew, and neither forgets a robot it saw healthy or failed nor counts one
healthy it has not seen so.

This module walks the waves and decides (go on, hold, halt, roll back); its parts, each one
job over the step's `RolloutScope`: the wave judge (`reconciler.rollout_health`), the evidence
gate and the stages' revocation (`reconciler.rollout_gate`), what the robots hold
(`reconciler.rollout_requests`) and the status and notes told (`reconciler.rollout_report`).
"""

from __future__ import annotations

from collections.abc import Mapping

from robotconf.configurator.render import FleetRender
from robotconf.configurator.rendered import RenderedRequest
from robotconf.configurator.stages import WavePlan, plan_waves
from robotconf.configurator.waves import failure_budget
from robotconf.contract.notes import VerdictNote
from robotconf.contract.wire import VERIFY_COMMANDS, RolloutState, RolloutStatus, WaveVerification
from robotconf.reconciler.evidence import Roles
from robotconf.reconciler.rollout_gate import (
    VERIFY_POLL,
    WaveGate,
    criteria,
    decision,
    evidence_gate,
    revocation,
    wave_verification,
)
from robotconf.reconciler.rollout_health import DARK_GRACE, Health, WaveJudge, deferral_deadline
from robotconf.reconciler.rollout_report import rollout_status, verdict_note
from robotconf.reconciler.rollout_requests import back, hold, kept_requests, stage_bases
from robotconf.reconciler.rollout_scope import RolloutInput, RolloutScope, RolloutStep

# What callers import from here: the step, its input and result, and the rules the
# reconciler's evidence feed and builds share with it (defined in the parts).
__all__ = [
    "DARK_GRACE",
    "VERIFY_POLL",
    "Health",
    "RolloutInput",
    "RolloutStep",
    "criteria",
    "deferral_deadline",
    "kept_requests",
    "roll_out",
    "stable_revision_of",
    "stage_bases",
    "wave_roles",
]


def stable_revision_of(previous: RolloutStatus | None, applied: str | None) -> str | None:
    """The last revision that fully rolled out: the previous rollout's when it completed."""
    if previous is None:
        return applied
    if previous.state == "Complete":
        return previous.revision
    return previous.stable_revision


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
    base = _Rollout(RolloutScope(seen, policy, plan, changed, stable_requests, list(bases)))
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


class _Rollout:
    """One step's walk over the waves; the one owner of the verdicts reached in the step."""

    def __init__(self, scope: RolloutScope) -> None:
        self.scope = scope
        self.policy = scope.policy
        self.specs = scope.specs
        self.count = scope.count
        self.judge = WaveJudge(scope)  # owns what the wave's judgment leaves for the step
        self.noted: list[VerdictNote] = []  # verdicts reached in this step

    def _with_verdicts(self, step: RolloutStep) -> RolloutStep:
        step.verdicts = self.noted
        return step

    def _hold(self, started: int) -> RolloutStep:
        return hold(self.scope, started, self.judge.busy_held)

    def _status(
        self,
        state: RolloutState,
        wave: int,
        started_at: float | None,
        judged: Mapping[str, Health],
        message: str,
        verification: WaveVerification | None = None,
        revoked: int | None = None,
    ) -> RolloutStatus:
        return rollout_status(
            self.scope, state, wave, started_at, judged, message, verification, revoked
        )

    def everyone(self) -> RolloutStep:
        step = self._hold(self.count)
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
        now = self.scope.seen.now
        known = self.scope.seen.statuses is not None
        if wave < 0 and not self.policy.paused and known:
            wave, started_at = 0, now
        while True:
            if wave < 0:
                return self._before_first()
            begins = started_at is None or started_at == now
            started_at = now if started_at is None else started_at
            judged, recheck, deadline, memory = self.judge.judge(wave, started_at, begins)
            revoked = revocation(self.scope, wave)
            if revoked is not None:
                self.noted.append(revoked.note)
                return self._failed(
                    wave, started_at, judged, revoked.why, revoked.verification, revoked.stage, True
                )
            failed = [r for r, h in judged.items() if h is Health.FAILED]
            # A share of the robots that took part: four robots on chargers do not widen it.
            taking_part = sum(1 for h in judged.values() if h is not Health.OFFLINE)
            budget = failure_budget(self.policy.max_failures, taking_part) or 0
            verification = wave_verification(self.scope, wave, started_at) if known else None
            by_hand = decision(self.scope, wave, started_at)
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
            gate = evidence_gate(self.scope, wave, started_at, healthy, verification, by_hand)
            self.noted.extend(gate.notes)
            if gate.failed is not None:
                return self._failed(wave, started_at, judged, gate.failed, gate.verification)
            if gate.poll is not None:
                recheck = gate.poll if recheck is None else min(recheck, gate.poll)
            if gate.done and wave == self.count - 1:
                return self._with_verdicts(self.everyone())
            if gate.done and not self.policy.paused:
                wave, started_at = wave + 1, now
                continue
            step = self._hold(wave)
            state, why = self._standing(wave, started_at, gate)
            step.status = self._status(state, wave, started_at, judged, why, gate.verification)
            step.recheck_at = recheck
            step.record = memory.record() if memory is not None else None
            return self._with_verdicts(step)

    def _before_first(self) -> RolloutStep:
        step = self._hold(-1)
        why = (
            "paused before the first wave (rollout.paused)"
            if self.policy.paused
            else "waiting for the robots' statuses before the first wave"
        )
        state: RolloutState = "Paused" if self.policy.paused else "Progressing"
        step.status = self._status(state, 0, None, {}, why)
        return step

    def _standing(self, wave: int, started_at: float, gate: WaveGate) -> tuple[RolloutState, str]:
        """The state and why of a rollout held at `wave`: paused (by fleet.yaml, or for an
        operator), verifying, or waiting for a busy member of a group."""
        name, found = self.specs[wave].name, gate.verification
        seen = self.scope.seen
        previous = seen.previous
        if (
            seen.statuses is None
            and previous is not None
            and previous.state == "Paused"
            and (previous.revision, previous.wave, previous.wave_started_at)
            == (seen.head.revision, wave, started_at)
        ):
            return "Paused", previous.message  # restarted: paused until it can judge again
        state: RolloutState = "Progressing"
        why = ""
        if gate.done and self.policy.paused:
            state, why = "Paused", "paused (rollout.paused): a commit setting it false resumes"
        elif gate.held_for == "inconclusive" and found is not None:
            state = "Paused"
            why = f"wave '{name}' inconclusive ({found.message}): {VERIFY_COMMANDS}"
            self.noted.append(verdict_note(self.scope, wave, started_at, found))
        elif gate.held_for == "gathering" and found is not None:
            why = f"wave '{name}' verifying: {found.message}"
        busy_why, unknown = self.judge.busy_why, self.judge.unknown
        if busy_why and state == "Progressing":
            why = f"{why}; {busy_why}" if why else busy_why
        lost = seen.statuses_lost
        if lost is not None and unknown and state == "Progressing":
            said = (
                f"{len(unknown)} robot(s) without a status ({', '.join(unknown[:3])}"
                f"{', ...' if len(unknown) > 3 else ''}) waited for, not offline: the "
                f"broker dropped status messages ({lost})"
            )
            why = f"{why}; {said}" if why else said
        return state, why

    def halted(self, previous: RolloutStatus) -> RolloutStep:
        wave = min(max(previous.wave, 0), self.count - 1)
        if previous.wave_started_at is None:
            wave = -1
        step = self._hold(wave)
        step.status = previous.model_copy()
        return step

    def rolled_back(self, previous: RolloutStatus) -> RolloutStep:
        if self.scope.seen.stable is None:  # the stable revision cannot be built now: hold on
            return self.halted(previous)
        stopped = [s.state in ("failed", "revoked") for s in previous.stages]
        at = stopped.index(True) if True in stopped else None
        step, _ = back(self.scope, at)
        step.status = previous.model_copy()
        return step

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
            self.noted.append(verdict_note(self.scope, wave, started_at, verification))
        rollback = self.policy.on_failure == "rollback" and self.scope.seen.stable is not None
        if rollback:
            step, what = back(self.scope, stage if stage is not None else self.specs[wave].stage)
            step.status = self._status(
                "RolledBack", wave, started_at, judged, why + what, verification, stage
            )
            return self._with_verdicts(step)
        step = self._hold(wave)
        if self.policy.on_failure == "rollback":
            why += "; no revision ever fully rolled out to go back to: halted"
        step.status = self._status("Halted", wave, started_at, judged, why, verification, stage)
        return self._with_verdicts(step)
