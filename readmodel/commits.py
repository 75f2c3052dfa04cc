"""The commits behind the revisions a status names: subject, author and time, read from the
source's repository once per revision (a commit never changes), so that every reader of the
status (`status`, `up`, the browser view, notifications) shows what a revision is, not only
its hash."""

from __future__ import annotations

import logging
import math
import time
from collections import OrderedDict
from collections.abc import Iterable
from pathlib import Path

from robotconf.contract.wire import MAX_COMMITS, CommitLine, ReconcilerStatus, is_commit

log = logging.getLogger("robotconf.reconciler")

KEPT = 64  # commit lines remembered; a status names a handful
RETRY = 30.0  # seconds before a revision the repository lacked is looked for again


def named_revisions(status: ReconcilerStatus) -> list[str]:
    """The revisions `status` names, most telling first, each once, at most MAX_COMMITS."""
    found: list[str | None] = [
        status.last_attempted_revision,
        status.last_applied_revision,
        status.failed_revision,
    ]
    rollout = status.rollout
    if rollout is not None:
        found += [rollout.revision, rollout.stable_revision]
        for stage in rollout.stages:
            found += [stage.verified_revision, stage.rollback_revision]
    named: list[str] = []
    for revision in found:
        if revision and is_commit(revision) and revision not in named:
            named.append(revision)
    return named[:MAX_COMMITS]


class CommitBook:
    """Commit lines of one repository, remembered (a bounded number) once read."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self._known: OrderedDict[str, CommitLine] = OrderedDict()
        self._missing: dict[str, float] = {}  # revision -> when it was last looked for

    def lines(self, revisions: Iterable[str]) -> list[CommitLine]:
        """The commit line of each revision the repository has; the others are left out."""
        found = [self.line(revision) for revision in revisions]
        return [line for line in found if line is not None]

    def line(self, revision: str) -> CommitLine | None:
        """`revision`'s commit line; None when it is not a whole commit id or not here."""
        if not is_commit(revision):
            return None
        known = self._known.get(revision)
        if known is not None:
            self._known.move_to_end(revision)
            return known
        now = time.monotonic()
        if now - self._missing.get(revision, -math.inf) < RETRY:
            return None  # not in the repository a moment ago: not a git process per step
        line = self._read(revision)
        if line is None:
            if len(self._missing) >= KEPT:
                self._missing.clear()
            self._missing[revision] = now
            return None
        self._missing.pop(revision, None)
        self._known[revision] = line
        while len(self._known) > KEPT:
            self._known.popitem(last=False)
        return line

    def _read(self, revision: str) -> CommitLine | None:
        try:
            import git

            with git.Repo(self.root) as repo:
                commit = repo.commit(revision)
                return CommitLine(
                    revision=revision,
                    subject=str(commit.summary),
                    author=str(commit.author.name or ""),
                    at=float(commit.committed_date),
                )
        except Exception as exc:  # a missing commit, a broken repository: shown without it
            log.debug("no commit line for %s: %s", revision[:12], exc)
            return None
