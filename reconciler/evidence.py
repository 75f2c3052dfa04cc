"""Wave evidence, pure: the goal outcomes that count toward a wave's verification
(`rollout.verify`), counted as they arrive, and the verdict they give.

What counts: goals ended by the wave's robots on the digest the new revision gives them, and
(for `compare: stable`) goals ended over the same window by the robots of the same scenarios
still on the stable revision. The window is the reconciler's clock, never a robot's: from the
wave's publication to its verification deadline, by when the ledger received each outcome. A
bounded window makes the verdict a fact about the ledger: a restarted reconciler recounting it
reaches the same one.

Counting is incremental: `WaveEvidence.add` takes the rows that arrived since its last call
(the ledger's ids only grow), so a step costs what arrived since the last, not the whole ledger.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from robotconf.configurator.types import Verify
from robotconf.contract.goals import OutcomeState, success_rate
from robotconf.contract.wire import Verdict, WaveVerification
from robotconf.readmodel.outcomes import Row

_SUCCEEDED, _FAILED, _CANCELED = (
    OutcomeState.SUCCEEDED.value,
    OutcomeState.FAILED.value,
    OutcomeState.CANCELED.value,
)


@dataclass(frozen=True)
class EvidenceKey:
    """The wave the evidence is about: a rollout of `revision`, its wave published then."""

    revision: str
    wave: int
    started_at: float


@dataclass(frozen=True)
class Roles:
    """Whose outcomes count, robot -> the digest they count on: the wave's robots on the new
    revision's request (`new`); robots no wave has moved yet, on the stable one (`stable`)."""

    new: Mapping[str, str]
    stable: Mapping[str, str]


@dataclass
class Counts:
    succeeded: int = 0
    failed: int = 0
    canceled: int = 0

    @property
    def decided(self) -> int:
        """Goals that say something of the robot's work: canceled ones were called off."""
        return self.succeeded + self.failed

    @property
    def rate(self) -> float | None:
        return success_rate(self.succeeded, self.failed)

    def add(self, outcome: str) -> None:
        if outcome == _SUCCEEDED:
            self.succeeded += 1
        elif outcome == _FAILED:
            self.failed += 1
        elif outcome == _CANCELED:
            self.canceled += 1

    def plus(self, other: Counts) -> Counts:
        return Counts(
            self.succeeded + other.succeeded,
            self.failed + other.failed,
            self.canceled + other.canceled,
        )


def total(counts: Iterable[Counts]) -> Counts:
    found = Counts()
    for each in counts:
        found = found.plus(each)
    return found


@dataclass
class WaveEvidence:
    """The outcomes counted so far for one wave, per scenario; `last_id` is the newest ledger
    row looked at (the next call starts after it)."""

    key: EvidenceKey
    roles: Roles
    until: float  # the verification deadline: outcomes received later do not count
    critical: frozenset[str] = frozenset()
    new: dict[str, Counts] = field(default_factory=dict)
    stable: dict[str, Counts] = field(default_factory=dict)
    reporting: set[str] = field(default_factory=set)  # the wave's robots that ended a goal
    critical_seen: dict[str, int] = field(default_factory=dict)
    last_id: int = 0

    def add(self, rows: Iterable[Row]) -> None:
        """Counts rows newer than `last_id`, once each."""
        start, until, roles = self.key.started_at, self.until, self.roles
        for row in rows:
            if row.id <= self.last_id:
                continue
            self.last_id = row.id
            if row.digest is None or not start <= row.received_at <= until:
                continue
            if roles.new.get(row.robot_id) == row.digest:
                self.new.setdefault(row.scenario, Counts()).add(row.outcome)
                self.reporting.add(row.robot_id)
                if row.outcome == _FAILED and row.code in self.critical:
                    self.critical_seen[row.code] = self.critical_seen.get(row.code, 0) + 1
            elif roles.stable.get(row.robot_id) == row.digest:
                self.stable.setdefault(row.scenario, Counts()).add(row.outcome)


def new_evidence(key: EvidenceKey, roles: Roles, verify: Verify) -> WaveEvidence:
    return WaveEvidence(
        key, roles, key.started_at + verify.timeout_seconds, frozenset(verify.critical)
    )


@dataclass(frozen=True)
class Comparison:
    scenario: str
    rate: float
    stable_rate: float
    stable_goals: int

    @property
    def drop(self) -> float:
        return self.stable_rate - self.rate


def judge(
    verify: Verify,
    evidence: WaveEvidence,
    now: float,
    baseline: Mapping[str, Counts] | None = None,
) -> WaveVerification:
    """The wave's verification now: a verdict once the evidence decides it, none while it is
    gathered. `baseline`: the stable revision's own counts per scenario (its ledger tally),
    compared with when too few robots of a scenario are left on it to compare over the window.

    Failed at once on a critical code, or as soon as the failures make the threshold out of
    reach at `min_goals`; judged on the rate once `min_goals` goals ended; Inconclusive when
    they have not by the deadline."""
    counts = total(evidence.new.values())
    decided, rate = counts.decided, counts.rate
    deadline = evidence.until
    worst = _worst_comparison(verify, evidence, baseline or {})
    found = WaveVerification(
        dry_run=verify.dry_run,
        goals=decided,
        min_goals=verify.min_goals,
        succeeded=counts.succeeded,
        failed=counts.failed,
        canceled=counts.canceled,
        robots=len(evidence.reporting),
        rate=rate,
        success_rate=verify.success_rate,
        stable_rate=worst.stable_rate if worst is not None else None,
        stable_goals=worst.stable_goals if worst is not None else 0,
        max_drop=verify.max_drop if verify.compare else None,
        critical=sorted(evidence.critical_seen),
        deadline=deadline,
    )
    verdict, why = _verdict(verify, evidence, decided, rate, worst, now >= deadline)
    return found.model_copy(update={"verdict": verdict, "message": _words(found, verdict, why)})


def _verdict(
    verify: Verify,
    evidence: WaveEvidence,
    decided: int,
    rate: float | None,
    worst: Comparison | None,
    past_deadline: bool,
) -> tuple[Verdict | None, str]:
    if evidence.critical_seen:
        codes = ", ".join(sorted(evidence.critical_seen))
        return "Failed", f"critical failure code {codes} reported"
    threshold = verify.success_rate
    failed = total(evidence.new.values()).failed
    if threshold is not None and decided < verify.min_goals and failed:
        best = (verify.min_goals - failed) / verify.min_goals
        if best < threshold:
            return "Failed", f"{failed} failed: {threshold:.0%} is out of reach"
    if decided < verify.min_goals:
        if past_deadline:
            return "Inconclusive", "too few goals ended by the deadline"
        return None, ""
    if threshold is not None and rate is not None and rate < threshold:
        return "Failed", f"success rate {rate:.0%} < {threshold:.0%}"
    if worst is not None and worst.drop > verify.max_drop + 1e-9:
        return "Failed", (
            f"{worst.scenario}: {worst.rate:.0%} is {worst.drop:.0%} below the stable "
            f"revision's {worst.stable_rate:.0%} (max_drop {verify.max_drop:.0%})"
        )
    return "Successful", ""


def _worst_comparison(
    verify: Verify, evidence: WaveEvidence, baseline: Mapping[str, Counts]
) -> Comparison | None:
    """Per scenario the wave's robots ended goals in: their rate against the stable robots'
    over the same window (enough of them: `min_goals`, at least one), else against the stable
    revision's own counts; the scenario that dropped most."""
    if verify.compare != "stable":
        return None
    worst: Comparison | None = None
    enough = max(verify.min_goals, 1)
    for scenario, counts in sorted(evidence.new.items()):
        rate = counts.rate
        if rate is None:
            continue
        stable = evidence.stable.get(scenario)
        if stable is None or stable.decided < enough:
            stable = baseline.get(scenario)
        if stable is None or stable.rate is None:
            continue
        found = Comparison(scenario, rate, stable.rate, stable.decided)
        if worst is None or found.drop > worst.drop:
            worst = found
    return worst


def _words(found: WaveVerification, verdict: Verdict | None, why: str) -> str:
    """'14 of 20 goals, 92% ≥ 90%': what was gathered against what is needed, then why."""
    parts = [f"{found.goals} of {found.min_goals} goals"]
    if found.rate is not None and found.success_rate is not None:
        sign = "≥" if found.rate >= found.success_rate else "<"
        parts.append(f"{found.rate:.0%} {sign} {found.success_rate:.0%}")
    elif found.rate is not None:
        parts.append(f"{found.rate:.0%} succeeded")
    if found.stable_rate is not None:
        parts.append(f"stable {found.stable_rate:.0%} over {found.stable_goals}")
    text = ", ".join(parts)
    if verdict is not None:
        text += f": {verdict}" + (f" ({why})" if why else "")
    if found.dry_run:
        text += " [dry run: not gating]"
    return text
