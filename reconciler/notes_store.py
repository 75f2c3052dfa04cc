"""Rollout verdicts kept in git: the reconciler's notes on the commits it rolls out
(`refs/notes/robotconf`, `contract.notes`), written and read back with git itself.

Git, not the broker: a verdict belongs to the commit, travels with the repository (push the
notes ref to share it, docs/how-to/rollouts.md), outlives the reconciler and the broker, and
`git log --notes=robotconf` shows it beside the commit. Each write is git's own `notes append`
(a commit on the notes ref, atomic): a kill leaves the note whole or absent.
"""

from __future__ import annotations

import logging
import os
import subprocess
from collections.abc import Sequence
from pathlib import Path

from robotconf.contract.notes import MAX_NOTE_BYTES, NOTES_REF, VerdictNote, read_notes

log = logging.getLogger("robotconf.reconciler")

GIT_TIMEOUT = 30.0
# Who the notes' commits are by, whatever the machine's git configuration says (it may have none).
_IDENTITY = {
    "GIT_AUTHOR_NAME": "robotconf reconciler",
    "GIT_AUTHOR_EMAIL": "reconciler@robotconf.invalid",
    "GIT_COMMITTER_NAME": "robotconf reconciler",
    "GIT_COMMITTER_EMAIL": "reconciler@robotconf.invalid",
}


class NotesError(Exception):
    """git could not read or write the notes: said in the log and the status, retried."""


class NotesStore:
    """The notes of one repository (a work tree or a bare cache clone)."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self._cache: dict[str, list[VerdictNote]] = {}

    def read(self, revision: str) -> list[VerdictNote]:
        """The verdict lines of `revision`'s note (none: no note); cached until this store
        writes one or `forget` is called."""
        if revision in self._cache:
            return self._cache[revision]
        done = self._git("notes", f"--ref={NOTES_REF}", "show", revision, check=False)
        if done.returncode != 0:
            text = ""  # no note on it (git says so on stderr)
        else:
            text = done.stdout[: MAX_NOTE_BYTES + 1].decode("utf-8", "replace")
        found = read_notes(text, revision)
        self._cache[revision] = found
        return found

    def append(self, notes: Sequence[VerdictNote]) -> None:
        """Adds lines to their commits' notes, each line once."""
        by_revision: dict[str, list[VerdictNote]] = {}
        for note in notes:
            by_revision.setdefault(note.revision, []).append(note)
        for revision, adding in by_revision.items():
            known = {_identity(note) for note in self.read(revision)}
            fresh = [note for note in adding if _identity(note) not in known]
            if not fresh:
                continue
            text = "\n".join(note.line() for note in fresh)
            self._cache.pop(revision, None)
            self._git("notes", f"--ref={NOTES_REF}", "append", "-m", text, revision)

    def forget(self) -> None:
        self._cache.clear()

    def _git(self, *args: str, check: bool = True) -> subprocess.CompletedProcess[bytes]:
        env = {**os.environ, **_IDENTITY, "GIT_TERMINAL_PROMPT": "0"}
        try:
            done = subprocess.run(
                ["git", "-C", str(self.root), *args],
                capture_output=True,
                env=env,
                timeout=GIT_TIMEOUT,
                check=False,
            )
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise NotesError(f"git notes in {self.root}: {exc}") from None
        if check and done.returncode != 0:
            error = done.stderr.decode("utf-8", "replace").strip().splitlines()
            raise NotesError(f"git notes in {self.root}: {error[-1] if error else 'failed'}")
        return done


def _identity(note: VerdictNote) -> tuple[object, ...]:
    """What makes two lines the same record: the same decision about the same wave run."""
    return (note.kind, note.wave, note.started_at, note.stage, note.verdict, note.by, note.dry_run)
