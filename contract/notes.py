"""Rollout verdicts as git notes (`refs/notes/robotconf`), one JSON object a line: which commit
was verified where, by what evidence, and what operators decided by hand.

`git log --notes=robotconf` shows them beside each commit; the reconciler reads them back after
a restart (an operator's resume or abort is kept nowhere else). Pure: the model and the lines.
"""

from __future__ import annotations

import json
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from robotconf.contract.wire import Verdict

NOTES_REF = "refs/notes/robotconf"
MAX_NOTE_BYTES = 256 * 1024  # a note larger than this is not read: not ours, or not whole
MAX_LINE_BYTES = 4096

NoteKind = Literal["verification", "resume", "abort", "promote"]


class VerdictNote(BaseModel):
    """One line of a commit's note. A wave run is (revision, wave, started_at): a decision
    about one run never applies to a later run of the same commit."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    kind: NoteKind
    revision: str = Field(pattern=r"^[0-9a-f]{40}$")
    at: float = Field(description="unix time it was decided")
    wave: int | None = None
    wave_name: str | None = None
    started_at: float | None = Field(None, description="when the wave was published")
    stage: str | None = None
    verdict: Verdict | None = None
    dry_run: bool = False
    goals: int | None = None
    min_goals: int | None = None
    rate: float | None = None
    success_rate: float | None = None
    stable_rate: float | None = None
    max_drop: float | None = None
    by: str | None = Field(None, description="the operator, for a decision by hand")
    message: str = ""

    def line(self) -> str:
        return json.dumps(self.model_dump(exclude_none=True), sort_keys=True, ensure_ascii=True)

    def about(self, revision: str, wave: int, started_at: float | None) -> bool:
        return self.revision == revision and self.wave == wave and self.started_at == started_at


def read_notes(text: str, revision: str) -> list[VerdictNote]:
    """The readable lines of a note about `revision`; a line that is not one (a person's own
    words, a note of another tool, a line about another commit) is skipped, never trusted."""
    if len(text.encode("utf-8", "replace")) > MAX_NOTE_BYTES:
        return []
    found: list[VerdictNote] = []
    for line in text.splitlines():
        line = line.strip()
        if not line.startswith("{") or len(line) > MAX_LINE_BYTES:
            continue
        try:
            note = VerdictNote.model_validate_json(line)
        except (ValidationError, ValueError):
            continue
        if note.revision == revision:
            found.append(note)
    return found
