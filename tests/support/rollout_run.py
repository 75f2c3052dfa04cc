"""A rollout stepped by hand, pure: `roll_out` called step after step with the robots running
whatever the last step left them holding, and goal outcomes counted as the reconciler counts
them (the roles and criteria of the step the rollout stands in)."""

from __future__ import annotations

from robotconf.configurator.render import FleetRender
from robotconf.configurator.stages import plan_waves
from robotconf.contract.notes import VerdictNote
from robotconf.contract.wire import AgentState, AgentStatus, RolloutStatus
from robotconf.readmodel.outcomes import Row
from robotconf.reconciler.evidence import EvidenceKey, WaveEvidence, new_evidence
from robotconf.reconciler.rollout import (
    RolloutInput,
    RolloutStep,
    criteria,
    kept_requests,
    roll_out,
    stage_bases,
    wave_roles,
)

T0 = 1_000_000.0


class RolloutRun:
    """One rollout of `head` over `stable`; `notes` are the head's (decisions by hand)."""

    def __init__(
        self,
        stable: FleetRender,
        head: FleetRender,
        previous: RolloutStatus | None = None,
        held: dict[str, str] | None = None,
    ) -> None:
        """`previous`: the rollout before this one (of another revision), and `held`, what the
        robots hold when it begins (the stable requests by default)."""
        self.stable, self.head = stable, head
        self.last: RolloutStep | None = None
        self.previous = previous
        self.held = held
        self.evidence: WaveEvidence | None = None
        self.notes: list[VerdictNote] = []
        self.builds: dict[str, FleetRender] = {}  # the stages' kept revisions, by revision
        self.states: dict[str, AgentState] = {}  # robots not running what they hold
        self.blind = False  # the robots' statuses not known (a reconciler just restarted)
        self.next_id = 0

    def launches(self) -> dict[str, str | None]:
        """What each robot holds after the last step: what it held at first, or what the step
        published (a robot it keeps stays as it is; rolled back, the stable everywhere)."""
        held: dict[str, str | None] = {r: q.digest for r, q in self.stable.requests.items()}
        last = self.last
        if self.held is not None and (last is None or not last.serve_stable):
            held.update(self.held)
        if last is not None and not last.serve_stable:
            held.update({r: q.digest for r, q in last.requests.items() if r not in last.keep})
        return held

    def step(self, now: float) -> RolloutStep:
        launches = self.launches()
        statuses = {
            r: AgentStatus(
                robot_id=r, state=self.states.get(r, AgentState.RUNNING), digest=d, since=T0
            )
            for r, d in launches.items()
        }
        self.last = roll_out(
            RolloutInput(
                self.head,
                self.stable,
                self.last.status if self.last is not None else self.previous,
                launches,
                None if self.blind else statuses,
                {r: T0 for r in launches},
                now,
                self.last.record if self.last is not None else None,
                evidence=self.evidence,
                notes=self.notes,
                stage_builds=self.builds,
            )
        )
        return self.last

    def report(
        self, robots: list[str], outcome: str, each: int = 1, code: str | None = None
    ) -> None:
        """Goals of `robots` ended on what they hold, received just after the current step
        began, counted for it."""
        status = self.last.status if self.last is not None else None
        assert status is not None and status.wave_started_at is not None
        key = EvidenceKey(self.head.revision, status.wave, status.wave_started_at)
        if self.evidence is None or self.evidence.key != key:
            verify = criteria(self.head, plan_waves(self.head).specs[status.wave])
            assert verify is not None, "this step is judged by health alone"
            plan = plan_waves(self.head)
            bases = stage_bases(self.head, status, self.stable.revision)
            kept = kept_requests(self.head, self.stable, bases, self.builds, plan)
            roles = wave_roles(self.head, self.stable, status.wave, plan, kept)
            self.evidence = new_evidence(key, roles, verify)
        held = self.launches()
        rows = []
        for robot in robots:
            for _ in range(each):
                self.next_id += 1
                rows.append(
                    Row(self.next_id, robot, held[robot], "s", outcome, code, key.started_at + 1)
                )
        self.evidence.add(rows)

    def moved(self) -> list[str]:
        """The robots holding the head's request."""
        held = self.launches()
        return sorted(r for r, d in held.items() if d == self.head.requests[r].digest)
