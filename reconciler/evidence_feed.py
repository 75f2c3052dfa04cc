"""The reconcile loop's reader of wave evidence: the outcome ledger's new rows, counted into the
current wave's evidence (`reconciler.evidence`) at each step.

A read-only connection of its own beside the feed's writer (the ledger is in WAL mode: readers
never wait for it). A new wave, or a restart, counts the wave's window once from the ledger
(by the time each outcome was received, indexed); every later step reads only the rows after
the last one counted. A ledger set aside and started anew (ids start over) is counted anew.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from robotconf.configurator.render import FleetRender
from robotconf.configurator.stages import plan_waves
from robotconf.contract.wire import RolloutStatus
from robotconf.readmodel.ledger import Ledger, LedgerError
from robotconf.reconciler.evidence import Counts, EvidenceKey, WaveEvidence, new_evidence
from robotconf.reconciler.rollout import criteria, kept_requests, stage_bases, wave_roles

log = logging.getLogger("robotconf.reconciler")

ROWS_PER_STEP = 200_000  # rows counted in one step at most; the rest in the next steps


@dataclass(frozen=True)
class Counted:
    evidence: WaveEvidence | None
    baseline: dict[str, Counts]


class EvidenceCounter:
    def __init__(self, path: Path) -> None:
        self.path = path
        self._ledger: Ledger | None = None
        self._identity: tuple[int, int] | None = None
        self._evidence: WaveEvidence | None = None
        self._without: EvidenceKey | None = None  # the last key with nothing to judge by
        self._baseline: tuple[str, dict[str, Counts]] | None = None
        self._complained = False

    def close(self) -> None:
        if self._ledger is not None:
            self._ledger.close()
            self._ledger = None

    def count(
        self,
        head: FleetRender,
        stable: FleetRender | None,
        rollout: RolloutStatus | None,
        builds: Mapping[str, FleetRender] | None = None,
    ) -> Counted:
        """The evidence of the wave `rollout` stands in (when it is the head's, under way, and
        judged by criteria: `rollout.verify`, or a stage's soak), counted up to what the ledger
        holds now. `builds`: the stages' kept revisions' builds (`RolloutInput.stage_builds`)."""
        if (
            head.rollout is None
            or rollout is None
            or rollout.revision != head.revision
            or rollout.state not in ("Progressing", "Paused")
            or rollout.wave_started_at is None
        ):
            self._evidence = None
            return Counted(None, {})
        key = EvidenceKey(head.revision, rollout.wave, rollout.wave_started_at)
        if key == self._without:
            return Counted(None, {})  # a step judged by health alone
        if self._evidence is None or self._evidence.key != key:
            plan = plan_waves(head)
            verify = (
                criteria(head, plan.specs[rollout.wave])
                if 0 <= rollout.wave < len(plan.specs)
                else None
            )
            if verify is None:
                self._evidence, self._without = None, key
                return Counted(None, {})
            bases = stage_bases(head, rollout, stable.revision if stable is not None else None)
            kept = kept_requests(head, stable, bases, builds or {}, plan)
            roles = wave_roles(head, stable, rollout.wave, plan, kept)
            self._evidence = new_evidence(key, roles, verify)
        evidence = self._evidence
        ledger = self._open()
        if ledger is not None:
            try:
                self._read(ledger, evidence)
            except LedgerError as exc:
                self._say(f"wave evidence: {exc}")
                self.close()
        return Counted(evidence, self._stable_counts(ledger, stable))

    def _read(self, ledger: Ledger, evidence: WaveEvidence) -> None:
        counted = 0
        while counted < ROWS_PER_STEP:
            if evidence.last_id == 0:
                rows = ledger.evidence_rows(since=evidence.key.started_at)
                if not rows:
                    return
            else:
                rows = ledger.evidence_rows(after=evidence.last_id)
            if not rows:
                return
            evidence.add(rows)
            counted += len(rows)

    def _stable_counts(
        self, ledger: Ledger | None, stable: FleetRender | None
    ) -> dict[str, Counts]:
        if ledger is None or stable is None:
            return {}
        if self._baseline is not None and self._baseline[0] == stable.revision:
            return self._baseline[1]
        try:
            scenarios = ledger.report(stable.revision).scenarios  # the revision's own tallies
        except LedgerError as exc:
            self._say(f"wave evidence: {exc}")
            return {}
        counts = {
            name: Counts(found.tally.succeeded, found.tally.failed, found.tally.canceled)
            for name, found in scenarios.items()
        }
        self._baseline = (stable.revision, counts)
        return counts

    def _open(self) -> Ledger | None:
        """The ledger, opened anew when its file was replaced (set aside, a new one started):
        then the wave's evidence is counted again from the new file."""
        try:
            stat = os.stat(self.path)
        except OSError:
            self.close()
            return None  # no outcome reported yet: no ledger, no evidence
        identity = (stat.st_dev, stat.st_ino)
        if self._ledger is not None and identity == self._identity:
            return self._ledger
        self.close()
        try:
            self._ledger = Ledger.open(self.path, read_only=True, check=False)
        except LedgerError as exc:
            self._say(f"wave evidence: {exc}")
            return None
        if self._identity is not None:
            self._evidence = None if self._evidence is None else self._recounted(self._evidence)
            self._baseline = None
        self._identity = identity
        self._complained = False
        return self._ledger

    @staticmethod
    def _recounted(evidence: WaveEvidence) -> WaveEvidence:
        return WaveEvidence(evidence.key, evidence.roles, evidence.until, evidence.critical)

    def _say(self, message: str) -> None:
        if not self._complained:
            log.warning("%s", message)
            self._complained = True
