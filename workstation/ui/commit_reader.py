"""The commit behind a revision page, read from the repository the UI serves (the edge of
`commit_facts`): its facts by git, and `plan` against the revision before by building both
(incrementally, the second from what the first proved). Each revision is read once (a commit
never changes) and a few are kept; a page asks under a lock, so two pages never build twice."""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from dataclasses import replace
from pathlib import Path

from robotconf.configurator.incremental import BuildCache
from robotconf.configurator.plan import make_plan
from robotconf.configurator.render import RenderError
from robotconf.configurator.source import SourceError
from robotconf.configurator.workspace import check
from robotconf.contract.textsafe import printable
from robotconf.workstation.ui.commit_facts import MAX_FILES, ChangedFile, CommitFacts

log = logging.getLogger("robotconf.ui")

KEPT = 8  # commits whose facts are kept: a 10,000-robot plan is worth keeping, not many


class CommitError(Exception):
    """The repository cannot say (it is not a repository, git failed): the page says why."""


class CommitReader:
    def __init__(self, repo: Path) -> None:
        self.repo = repo
        self._lock = threading.Lock()
        self._kept: OrderedDict[str, CommitFacts | None] = OrderedDict()

    def read(self, revision: str) -> CommitFacts | None:
        """The commit's facts; None when the repository has no such commit."""
        with self._lock:
            if revision in self._kept:
                self._kept.move_to_end(revision)
                return self._kept[revision]
            facts = self._read(revision)
            self._kept[revision] = facts
            while len(self._kept) > KEPT:
                self._kept.popitem(last=False)
            return facts

    def _read(self, revision: str) -> CommitFacts | None:
        try:
            import git

            with git.Repo(self.repo) as repo:
                try:
                    commit = repo.commit(revision)
                    commit.summary  # noqa: B018 (reads the object: a full hash need not name one)
                except (ValueError, git.BadName, git.BadObject, git.GitCommandError):
                    return None
                listing = repo.git.diff_tree(
                    "--no-commit-id", "--name-status", "-r", "--root", "-M", commit.hexsha
                )
                parent = commit.parents[0].hexsha if commit.parents else None
                facts = CommitFacts(
                    revision=commit.hexsha,
                    subject=str(commit.summary),
                    author=str(commit.author.name or ""),
                    at=float(commit.committed_date),
                    parent=parent,
                )
        except Exception as exc:  # not a repository, git missing or failing
            raise CommitError(
                f"the repository cannot be read: {printable(str(exc))[:200]}"
            ) from None
        files = _files(listing)
        facts = _with_files(facts, files)
        return self._with_plan(facts)

    def _with_plan(self, facts: CommitFacts) -> CommitFacts:
        """`plan` against the revision before, or why not: the commit's own diagnostics when it
        does not validate."""
        cache = BuildCache()
        try:
            # The cache renders the build it checked last: the base first, then the head.
            base = check(self.repo, facts.parent, cache.check) if facts.parent else None
            before = cache.render(base) if base is not None and base.ok else None
            head = check(self.repo, facts.revision, cache.check)
            if not head.ok:
                return replace(facts, problems=tuple(head.errors))
            if base is None:
                return replace(facts, no_plan="The first commit: no revision before it.")
            if before is None:
                why = "The revision before does not validate: no robot ran it to compare with."
                return replace(facts, no_plan=why)
            fleet = head.repo.fleet
            rollout = fleet.model.rollout if fleet is not None else None
            return replace(facts, plan=make_plan(before, cache.render(head), rollout))
        except (SourceError, RenderError) as exc:
            return replace(facts, no_plan=f"It cannot be built: {printable(str(exc))[:300]}")
        except Exception:  # a bug in a build: the commit's facts are still worth showing
            log.exception("ui: building %s for its page failed", facts.revision[:12])
            return replace(facts, no_plan="Building it failed (the UI's log says why).")


def _files(listing: str) -> list[ChangedFile]:
    """`git diff-tree --name-status` lines: `M\\tpath`, `R100\\told\\tnew`."""
    files = []
    for line in listing.splitlines():
        parts = line.split("\t")
        if len(parts) >= 2 and parts[0]:
            files.append(ChangedFile(parts[0][:1], parts[-1]))
    return files


def _with_files(facts: CommitFacts, files: list[ChangedFile]) -> CommitFacts:
    shown = tuple(files[:MAX_FILES])
    return replace(facts, files=shown, more_files=len(files) - len(shown))
