"""The controller's rollout memory (one owner: `RolloutMemory`): what the current wave
established (kept retained, so a restarted reconciler finds it), the verdicts and operators'
decisions kept as git notes on the commits rolled out, operators' actions as they arrive, and
the outcome ledger's evidence a wave is judged on.

A part of `reconciler.controller`'s state, kept apart so that the controller is a loop over
named parts rather than one class holding all of them.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from pydantic import ValidationError

from robotconf.configurator.render import FleetRender
from robotconf.contract.notes import VerdictNote
from robotconf.contract.safejson import PayloadError
from robotconf.contract.wire import OperatorAnswer, ReconcilerStatus, Topics, short_rev
from robotconf.readmodel.observed import WAVE_RECORD
from robotconf.readmodel.retained import Ignored, RetainedView, read_object
from robotconf.reconciler.decide import Condition
from robotconf.reconciler.desired import Desired
from robotconf.reconciler.evidence import Counts, WaveEvidence
from robotconf.reconciler.evidence_feed import EvidenceCounter
from robotconf.reconciler.notes_store import NotesError, NotesStore
from robotconf.reconciler.operator_actions import Refused, judge_action
from robotconf.reconciler.report import one_line
from robotconf.reconciler.wave_memory import WaveRecord

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

log = logging.getLogger("robotconf.reconciler")
ROLLOUT_ACTION = "rollout-action"  # an operator's rollout action (reconciler.operator_actions)
MAX_WAITING_ACTIONS = 16  # operator actions waiting for the loop; a flood beyond is dropped


class RolloutMemory:
    """What a rollout's evidence and decisions need, on the loop; operators' actions arrive on
    the network thread (`action_arrived`), bounded: a flood is dropped, counted, and those kept
    are judged on the loop, the answer to the last one in the rollout's status."""

    def __init__(
        self,
        root: Path,
        topics: Topics,
        ignored: Ignored,
        ledger: Path | None,
        verifier: Ed25519PublicKey | None,
    ) -> None:
        self._topics = topics
        self._ignored = ignored
        self._evidence = EvidenceCounter(ledger) if ledger is not None else None
        self.notes = NotesStore(root)
        self._notes_failed = False
        self._verifier = verifier
        self._actions: collections.deque[bytes] = collections.deque(maxlen=MAX_WAITING_ACTIONS)
        self._actions_lock = threading.Lock()
        self._answer: OperatorAnswer | None = None
        self.verdicts: tuple[VerdictNote, ...] = ()  # reached by the current step
        # What a rollout's current wave established: this process's, or the retained one
        # found at start; and what the broker holds of it.
        self.wave_record: WaveRecord | None = None
        self._wave_record_held: bytes | None = None

    # ------------------------------------------------------------ the wave record

    def recover_wave_record(self, view: RetainedView) -> None:
        """The wave record the broker holds (a reconciler before this one left it); an
        unreadable one is skipped, counted, and replaced at the next change."""
        topic = self._topics.reconciler_rollout
        payload = view.get(topic)
        if not payload:
            self.wave_record, self._wave_record_held = None, None
            return
        try:
            self.wave_record = WaveRecord.model_validate(read_object(payload))
        except (PayloadError, ValidationError) as exc:
            self._ignored.note(WAVE_RECORD, topic, payload, one_line(exc))
            self.wave_record = None
        self._wave_record_held = payload

    def keep_wave_record(
        self, record: WaveRecord | None, view: RetainedView, timeout: float
    ) -> None:
        """Remembers what the wave established, and has the broker keep it (retained) before
        anything of the step is published: a reconciler killed after this step finds it."""
        self.wave_record = record
        payload = record.model_dump_json().encode() if record is not None else b""
        if payload == (self._wave_record_held or b""):
            return
        if view.publish_retained([(self._topics.reconciler_rollout, payload)], timeout):
            self._wave_record_held = payload
        else:  # kept here all the same; the broker is told at the next step
            log.warning("the broker did not take the rollout's wave record; trying again")

    # ------------------------------------------------------------ operators' actions

    def action_arrived(self, payload: bytes | None) -> bool:
        """Network thread: an operator's rollout action, kept for the loop to judge; whether
        it was kept (the loop is to be woken)."""
        if not payload:
            return False
        with self._actions_lock:
            if len(self._actions) == self._actions.maxlen:
                self._ignored.note(
                    ROLLOUT_ACTION, self._topics.rollout_request, payload, "too many at once"
                )
                return False
            self._actions.append(payload)
        return True

    @property
    def actions_waiting(self) -> bool:
        return bool(self._actions)

    def take_actions(self, status: ReconcilerStatus | None) -> None:
        """Judges the operators' actions that arrived, against the rollout as it stands; one
        carried out is a git note on the revision, read by the step that follows."""
        with self._actions_lock:
            waiting = list(self._actions)
            self._actions.clear()
        for payload in waiting:
            found = judge_action(
                payload, status.rollout if status else None, time.time(), self._verifier
            )
            if isinstance(found, Refused):
                if found.answer is None:
                    self._ignored.note(
                        ROLLOUT_ACTION, self._topics.rollout_request, payload, found.why
                    )
                else:
                    log.warning(
                        "refused %s by %s: %s",
                        found.answer.action,
                        found.answer.requested_by,
                        found.why,
                    )
                    self._answer = found.answer
                continue
            try:
                self.notes.append([found.note])
            except NotesError as exc:
                why = f"cannot keep the decision as a git note: {exc}"
                log.warning("%s", why)
                self._answer = found.answer.model_copy(update={"accepted": False, "message": why})
                continue
            log.info("%s", found.note.message)
            self._answer = found.answer

    def answered(self, condition: Condition) -> Condition:
        """The condition with the answer to the last operator action about its rollout."""
        rollout, answer = condition.rollout, self._answer
        if rollout is None or answer is None:
            return condition
        return replace(condition, rollout=rollout.model_copy(update={"answer": answer}))

    # ------------------------------------------------------------ evidence and verdicts

    def verification(
        self,
        build: Desired,
        previous: ReconcilerStatus | None,
        head: str | None,
        stage_builds: dict[str, FleetRender],
        serving: Desired | None,
    ) -> tuple[WaveEvidence | None, dict[str, Counts], list[VerdictNote]]:
        """What a rollout of the head is judged on beyond health: its wave's goal outcomes
        (rollout.verify) and the notes on its commit (an operator's resume or abort)."""
        fleet = build.fleet
        rollout = previous.rollout if previous is not None else None
        if fleet is None or fleet.rollout is None or head is None:
            return None, {}, []
        notes: list[VerdictNote] = []
        if rollout is not None and rollout.revision == head:
            try:
                notes = self.notes.read(head)
                self._notes_failed = False
            except NotesError as exc:
                if not self._notes_failed:
                    log.warning("%s", exc)
                    self._notes_failed = True
        judged = fleet.rollout.verify is not None or any(s.soak for s in fleet.stages)
        if self._evidence is None or not judged:
            return None, {}, notes
        stable = serving.fleet if serving is not None else None
        counted = self._evidence.count(fleet, stable, rollout, stage_builds)
        return counted.evidence, counted.baseline, notes

    def new_step(self) -> None:
        self.verdicts = ()  # a step that raised reached none

    def keep_verdicts(self, verdicts: tuple[VerdictNote, ...]) -> None:
        """The step's verdicts, as git notes on their commits; a failure is said and the
        verdict noted again at a later step (a verdict is recomputed the same from the ledger)."""
        self._note_verdicts(verdicts)
        self.verdicts = verdicts

    def _note_verdicts(self, verdicts: tuple[VerdictNote, ...]) -> None:
        if not verdicts:
            return
        try:
            self.notes.append(verdicts)
        except NotesError as exc:
            log.warning("cannot keep the rollout's verdict as a git note: %s", exc)
            return
        for note in verdicts:
            if note.verdict is not None:
                log.info(
                    "wave %s of %s: %s%s (%s)",
                    note.wave_name,
                    short_rev(note.revision),
                    note.verdict,
                    " [dry run]" if note.dry_run else "",
                    note.message,
                )
