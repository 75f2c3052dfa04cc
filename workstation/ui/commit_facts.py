"""What a revision's page says of its commit, pure: the commit's facts (subject, author, time,
the files it changed, the revision before it) and what it changes on the fleet — `plan`'s
robot-level diff against the revision before, or why there is none (the diagnostics of a
commit that does not validate). Commit text is data: every string goes through `esc`."""

from __future__ import annotations

from dataclasses import dataclass, field

from robotconf.configurator.plan import Plan, format_plan_text
from robotconf.contract.diagnostics import Diagnostic
from robotconf.readmodel.verdicts import short_rev
from robotconf.workstation.ui.goals_html import revision_link
from robotconf.workstation.ui.pages import diagnostics
from robotconf.workstation.ui.text import esc, when

MAX_FILES = 200  # files listed; the rest counted
MAX_PLAN_LINES = 300  # plan lines shown; the rest counted


@dataclass(frozen=True)
class ChangedFile:
    status: str  # A, M, D, R (git's name-status letter)
    path: str


@dataclass(frozen=True)
class CommitFacts:
    """A commit as its page shows it; `plan` against `parent`, or `problems` (it does not
    validate), or `no_plan` (why neither: the first commit, a parent that does not build)."""

    revision: str
    subject: str
    author: str
    at: float
    parent: str | None
    files: tuple[ChangedFile, ...] = ()
    more_files: int = 0
    plan: Plan | None = None
    problems: tuple[Diagnostic, ...] = field(default=())
    no_plan: str = ""


def commit_section(facts: CommitFacts | None, why: str | None = None) -> str:
    """The commit behind the revision: who, when, what files, what it changes per robot."""
    if facts is None:
        text = why or "The repository here has no such commit."
        return f'<section data-commit="unknown"><h2>Commit</h2><p>{esc(text)}</p></section>'
    head = (
        f'<p class="subject" data-subject>{esc(facts.subject)}</p>'
        f"<p>by {esc(facts.author, 100)}, {when(facts.at)}; the revision before: "
        f"{revision_link(facts.parent)}</p>"
    )
    return (
        f'<section data-commit="{esc(facts.revision, 64)}"><h2>Commit</h2>{head}'
        f"{_files(facts)}{_changes(facts)}</section>"
    )


def _files(facts: CommitFacts) -> str:
    if not facts.files:
        return "<p>It changes no file.</p>"
    items = "".join(
        f"<li><code>{esc(f.status, 4)}</code> <code>{esc(f.path, 300)}</code></li>"
        for f in facts.files
    )
    more = f"<p>… {facts.more_files} more files</p>" if facts.more_files else ""
    return f"<h3>Files changed</h3><ul data-files>{items}</ul>{more}"


def _changes(facts: CommitFacts) -> str:
    if facts.problems:
        return diagnostics(facts.problems, 0).replace(
            "Why the commit was refused", "Why it does not validate (the reconciler refuses it)"
        )
    if facts.plan is None:
        return f"<h3>What it changes on the fleet</h3><p>{esc(facts.no_plan)}</p>"
    lines = format_plan_text(facts.plan).splitlines()
    shown = lines[:MAX_PLAN_LINES]
    more = len(lines) - len(shown)
    if more > 0:
        shown.append(f"… {more} more lines (robotconf plan)")
    text = "\n".join(esc(line, 1000) for line in shown)  # esc writes a line break as \n
    return (
        "<h3>What it changes on the fleet</h3>"
        f"<p>Against {esc(short_rev(facts.parent))}, as <code>robotconf plan</code> says it:</p>"
        f"<pre data-plan>{text}</pre>"
    )
