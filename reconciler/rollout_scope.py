"""A rollout step's typed data, pure: what it sees (`RolloutInput`), what it decides
(`RolloutStep`), and the scope every part of the step reads and none changes (`RolloutScope`):
the wave judge (`reconciler.rollout_health`), the evidence gate and the stages' revocation
(`reconciler.rollout_gate`), what the robots hold (`reconciler.rollout_requests`) and the
status told (`reconciler.rollout_report`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from robotconf.configurator.render import FleetRender
from robotconf.configurator.rendered import RenderedRequest
from robotconf.configurator.stages import WavePlan, WaveSpec
from robotconf.configurator.types import RolloutPolicy
from robotconf.contract.notes import VerdictNote
from robotconf.contract.wire import AgentStatus, RolloutStatus
from robotconf.reconciler.evidence import Counts, WaveEvidence
from robotconf.reconciler.wave_memory import WaveRecord


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


@dataclass(frozen=True)
class RolloutScope:
    """What one step of the rollout works on, fixed for the step: what it sees, the head's
    policy and wave plan, the robots it moves (`changed`), what the others keep
    (`stable_requests`, `kept_requests`) and, per stage, the revision its robots keep
    (`bases`, `stage_bases`)."""

    seen: RolloutInput
    policy: RolloutPolicy
    plan: WavePlan
    changed: set[str]
    stable_requests: Mapping[str, RenderedRequest]
    bases: list[str | None]

    @property
    def specs(self) -> tuple[WaveSpec, ...]:
        return self.plan.specs

    @property
    def waves(self) -> dict[str, int]:
        return self.plan.of

    @property
    def count(self) -> int:
        return len(self.plan.specs)

    def digest(self, robot: str) -> str:
        return self.seen.head.requests[robot].digest

    def stable_revision(self) -> str | None:
        stable = self.seen.stable
        return stable.revision if stable is not None else None

    def stage_name(self, wave: int) -> str | None:
        stage = self.specs[wave].stage if 0 <= wave < self.count else None
        return self.seen.head.stages[stage].name if stage is not None else None
