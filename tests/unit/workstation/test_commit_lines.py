"""Every revision is a commit: the commit lines a reconciler status carries are bounded and
printable data, and each reader shows a revision with its subject (escaped in the browser)."""

from __future__ import annotations

from robotconf.contract.wire import (
    MAX_SUBJECT,
    CommitLine,
    ReconcilerStatus,
    RolloutStatus,
    StageState,
)
from robotconf.readmodel.commits import named_revisions
from robotconf.readmodel.verdicts import reconciler_lines, rev_text, rollout_line
from robotconf.workstation.ui.goals_html import revision_link

A, B, C = "a" * 40, "b" * 40, "c" * 40


def status(**extra: object) -> ReconcilerStatus:
    return ReconcilerStatus.model_validate(
        {
            "state": "Stalled",
            "ready": False,
            "reason": "BuildFailed",
            "branch": "main",
            "last_applied_revision": A,
            "last_attempted_revision": B,
            "failed_revision": B,
            "commits": [
                {"revision": A, "subject": "Rename the lab robots", "author": "ada", "at": 1.0},
                {"revision": B, "subject": "Break the patrol", "author": "bob"},
            ],
            **extra,
        }
    )


def test_commit_text_is_made_printable_and_bounded_on_the_way_in() -> None:
    line = CommitLine(revision=A, subject="\x1b[31mred\u202e" + "x" * 500, author="a\nb")
    assert "\x1b" not in line.subject and "\u202e" not in line.subject
    assert len(line.subject) == MAX_SUBJECT and line.subject.endswith("…")
    assert line.author == "a\\nb"


def test_status_lines_say_each_revision_with_its_subject_once() -> None:
    line = reconciler_lines(status(), at=0.0)[0]
    assert 'applied aaaaaaaaaaaa "Rename the lab robots"' in line
    assert 'attempted bbbbbbbbbbbb "Break the patrol"' in line
    assert line.count("Break the patrol") == 1  # failed on it: said just before
    assert rev_text(C, status()) == "cccccccccccc"  # a commit the status does not carry


def test_the_rollout_line_names_its_revision_s_commit() -> None:
    found = status(rollout={"revision": A, "state": "Progressing", "waves": 2})
    assert found.rollout is not None
    assert rollout_line(found.rollout, found).startswith(
        'rollout: aaaaaaaaaaaa "Rename the lab robots" Progressing'
    )


def test_the_browser_view_escapes_a_subject_and_links_the_revision() -> None:
    hostile = status(commits=[{"revision": A, "subject": '<script>alert("x")</script>'}])
    html = revision_link(A, hostile)
    assert "<script>" not in html and "&lt;script&gt;" in html
    assert f'href="/revisions/{A}"' in html and 'class="subject"' in html
    assert revision_link(None, hostile) == "-"


def test_the_revisions_a_status_names_are_each_described_once() -> None:
    rollout = RolloutStatus(
        revision=C,
        stable_revision=A,
        state="Progressing",
        stages=[StageState(name="sim", state="rolling", verified_revision=A, rollback_revision=A)],
    )
    found = status(rollout=rollout.model_dump())
    assert named_revisions(found) == [B, A, C]
    odd = status(last_attempted_revision="--upload-pack=x", failed_revision=None)
    assert named_revisions(odd) == [A]  # only a commit's 40 hex digits go to git
