"""What a rollout step tells, pure: the rollout's status (the wave's robots by health, the
robots behind, each stage's standing) and the verdict notes it writes."""

from __future__ import annotations

from collections.abc import Mapping

from robotconf.contract.notes import VerdictNote
from robotconf.contract.wire import (
    MAX_LISTED,
    RolloutState,
    RolloutStatus,
    StageState,
    StageWord,
    WaveVerification,
    is_online,
)
from robotconf.reconciler.rollout_health import Health, status_unknown
from robotconf.reconciler.rollout_scope import RolloutScope


def rollout_status(
    scope: RolloutScope,
    state: RolloutState,
    wave: int,
    started_at: float | None,
    judged: Mapping[str, Health],
    message: str,
    verification: WaveVerification | None = None,
    revoked: int | None = None,
) -> RolloutStatus:
    """The rollout's status at `wave`; `revoked`: a verified stage whose robots failed later."""

    def robots(*kinds: Health) -> list[str]:
        return sorted(r for r, h in judged.items() if h in kinds)

    healthy, failed = robots(Health.HEALTHY), robots(Health.FAILED)
    pending = robots(Health.PENDING, Health.ABSENT)
    index = max(0, min(wave, scope.count - 1))
    offline = sorted(set(robots(Health.OFFLINE)) | _behind(scope, wave, judged))
    counts = {"healthy": len(healthy), "failed": len(failed), "pending": len(pending)}
    return RolloutStatus(
        revision=scope.seen.head.revision,
        stable_revision=scope.stable_revision(),
        state=state,
        wave=index,
        waves=scope.count,
        wave_name=scope.specs[index].name,
        wave_started_at=started_at,
        healthy=healthy[:MAX_LISTED],
        failed=failed[:MAX_LISTED],
        pending=pending[:MAX_LISTED],
        offline=offline[:MAX_LISTED],
        counts={**counts, "offline": len(offline)} if offline else counts,
        verification=verification,
        stage=scope.stage_name(index),
        stages=_stages(scope, state, index, revoked),
        message=message,
    )


def _behind(scope: RolloutScope, wave: int, judged: Mapping[str, Health]) -> set[str]:
    """Robots of the waves up to `wave` (not judged in it) that are offline and do not
    report running the head's request: passed by while they were off, they get it when
    they reconnect (listed until then, after the rollout completed too)."""
    statuses, head = scope.seen.statuses, scope.seen.head
    if statuses is None:
        return set()
    behind = set()
    # Every robot, not only the changed ones: once complete, the head is the stable
    # revision and nothing is changed, but a robot that was off is still behind.
    for robot in head.requests.keys() - head.suspended:
        status = statuses.get(robot)
        if robot in judged or scope.waves.get(robot, scope.count) > wave or is_online(status):
            continue
        if status_unknown(scope.seen, robot, statuses):
            continue  # its status may be one the broker dropped: not known to be off
        if status is None or status.digest != head.requests[robot].digest:
            behind.add(robot)
    return behind


def _stages(
    scope: RolloutScope, state: RolloutState, wave: int, revoked: int | None
) -> list[StageState]:
    """Each stage's standing: stages before the current wave's are verified on the head;
    the current one rolls, verifies (at its gate) or failed; later ones wait, keeping what
    was verified for them (`stage_bases`). A verified stage revoked is where it stopped."""
    head, stable = scope.seen.head, scope.stable_revision()
    stopped = state in ("RolledBack", "Halted")
    current = scope.specs[wave].stage if 0 <= wave < scope.count else None
    at = revoked if stopped and revoked is not None else current
    found: list[StageState] = []
    for index, stage in enumerate(head.stages):
        base = scope.bases[index] if index < len(scope.bases) else stable
        word: StageWord
        verified: str | None
        if state == "Complete" or (at is not None and index < at):
            word, verified = "verified", head.revision
        elif index == at:
            if stopped:
                word = "revoked" if index == revoked else "failed"
            else:
                word = "verifying" if scope.specs[wave].gate else "rolling"
            verified = base
        else:
            word, verified = "waiting", base
        found.append(
            StageState(
                name=stage.name, state=word, verified_revision=verified, rollback_revision=base
            )
        )
    return found


def verdict_note(
    scope: RolloutScope, wave: int, started_at: float | None, found: WaveVerification
) -> VerdictNote:
    """The note of a verdict reached on `wave` (run since `started_at`; None: the stage's)."""
    return VerdictNote(
        kind="verification",
        revision=scope.seen.head.revision,
        at=scope.seen.now,
        wave=wave,
        wave_name=scope.specs[wave].name,
        started_at=started_at,
        stage=scope.stage_name(wave),
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
