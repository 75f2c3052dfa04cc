"""Verdicts as git notes: lines read back whatever else a note holds, written once each, in a
real repository (git itself, `refs/notes/robotconf`)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from robotconf.contract.notes import MAX_NOTE_BYTES, NOTES_REF, VerdictNote, read_notes
from robotconf.reconciler.notes_store import NotesError, NotesStore

T0 = 1_000_000.0


def note(revision: str, **changes: object) -> VerdictNote:
    fields: dict[str, object] = {
        "kind": "verification",
        "revision": revision,
        "at": T0,
        "wave": 0,
        "wave_name": "canary",
        "started_at": T0 - 60,
        "verdict": "Successful",
        "goals": 20,
        **changes,
    }
    return VerdictNote.model_validate(fields)


def test_only_readable_lines_about_the_commit_are_read() -> None:
    rev, other = "a" * 40, "b" * 40
    text = "\n".join(
        [
            "Reviewed by Ada: looks good",  # a person's own words
            note(rev).line(),
            "",
            '{"kind": "verification", "revision": "' + rev + '"}',  # no time: not ours
            note(other).line(),  # about another commit
            '{"kind": "verification", "revision": "' + rev + '", "at": 1, "extra": 1}',
            "{" + "x" * 5000 + "}",
        ]
    )
    found = read_notes(text, rev)
    assert [n.at for n in found] == [T0, 1.0]
    assert read_notes("x" * (MAX_NOTE_BYTES + 1), rev) == []


@pytest.fixture
def repo(tmp_path: Path) -> tuple[Path, str]:
    root = tmp_path / "lab"
    subprocess.run(["git", "init", "-q", "-b", "main", str(root)], check=True)
    (root / "a.txt").write_text("a\n")
    env = ["-c", "user.name=t", "-c", "user.email=t@example.invalid"]
    subprocess.run(["git", "-C", str(root), "add", "."], check=True)
    subprocess.run(["git", "-C", str(root), *env, "commit", "-qm", "one"], check=True)
    head = subprocess.run(
        ["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, check=True
    ).stdout.strip()
    return root, head


def test_notes_are_written_once_each_and_read_back_by_another_store(
    repo: tuple[Path, str],
) -> None:
    root, head = repo
    store = NotesStore(root)
    assert store.read(head) == []
    first = note(head)
    store.append([first, note(head, kind="resume", verdict=None, by="ada")])
    store.append([first])  # the same decision again: kept once
    again = NotesStore(root).read(head)
    assert [(n.kind, n.by) for n in again] == [("verification", None), ("resume", "ada")]
    log = subprocess.run(
        ["git", "-C", str(root), "log", "-1", "--notes=robotconf"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert '"verdict": "Successful"' in log
    shown = subprocess.run(
        ["git", "-C", str(root), "notes", f"--ref={NOTES_REF}", "list"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert head in shown


def test_a_repository_that_cannot_be_written_is_a_clear_error(tmp_path: Path) -> None:
    store = NotesStore(tmp_path / "nowhere")
    with pytest.raises(NotesError, match="git notes in"):
        store.append([note("c" * 40)])
