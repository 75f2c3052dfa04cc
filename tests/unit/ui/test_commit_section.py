"""A revision page's commit section, pure: commit text is escaped data, long lists are cut and
counted, and a commit that does not validate says why instead of a plan."""

from __future__ import annotations

from robotconf.configurator.plan import Plan
from robotconf.contract.diagnostics import Diagnostic, Severity
from robotconf.workstation.ui.commit_facts import (
    MAX_FILES,
    ChangedFile,
    CommitFacts,
    commit_section,
)

A, B = "a" * 40, "b" * 40


def facts(**extra: object) -> CommitFacts:
    base = CommitFacts(revision=B, subject="<b>bold</b>\x1b[2J", author="ada", at=1.7e9, parent=A)
    return CommitFacts(**{**base.__dict__, **extra})  # type: ignore[arg-type]


def test_commit_text_is_escaped_and_the_revision_before_linked() -> None:
    html = commit_section(facts(no_plan="nothing to compare"))
    assert "<b>bold</b>" not in html and "&lt;b&gt;bold&lt;/b&gt;" in html
    assert "\x1b" not in html
    assert f'href="/revisions/{A}"' in html and "nothing to compare" in html


def test_files_beyond_the_limit_are_counted() -> None:
    files = tuple(ChangedFile("M", f"configs/f{i}.yaml") for i in range(MAX_FILES))
    html = commit_section(facts(files=files, more_files=5, no_plan="-"))
    assert html.count("<li>") == MAX_FILES and "… 5 more files" in html


def test_a_commit_that_does_not_validate_shows_its_diagnostics() -> None:
    problem = Diagnostic("configs/fleet.yaml", 1, 1, Severity.ERROR, "RC001", "bad <yaml>")
    html = commit_section(facts(problems=(problem,)))
    assert "data-diagnostics" in html and "configs/fleet.yaml" in html
    assert "bad &lt;yaml&gt;" in html and "data-plan" not in html


def test_the_plan_is_shown_as_plan_says_it() -> None:
    html = commit_section(facts(plan=Plan(base=A, head=B, changes=[], unchanged=6)))
    assert "data-plan" in html and "6" in html


def test_no_commit_says_why() -> None:
    assert 'data-commit="unknown"' in commit_section(None, "no repository <here>")
    assert "no repository &lt;here&gt;" in commit_section(None, "no repository <here>")
