"""Loads and validates a repository at the work tree or a revision: the one entry for commands."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from robotconf.configurator.gcpause import collector_paused
from robotconf.configurator.loader import load_repository
from robotconf.configurator.repository import Repository
from robotconf.configurator.ruleconfig import judge
from robotconf.configurator.rules import check_repository
from robotconf.configurator.source import OverlaySource, Source, open_source
from robotconf.contract.diagnostics import Diagnostic


@dataclass
class Checked:
    """A repository and everything wrong with it, sorted by file and position."""

    repo: Repository
    diagnostics: list[Diagnostic]

    @property
    def errors(self) -> list[Diagnostic]:
        return [d for d in self.diagnostics if d.is_error]

    @property
    def ok(self) -> bool:
        return not self.errors


def judged(repo: Repository, diagnostics: list[Diagnostic]) -> Checked:
    """A build's findings as the lab tuned them (`.robotconf.yaml`, ignore comments): every
    build, full or incremental, ends here, so every command and the reconciler see the same."""
    return Checked(repo, judge(diagnostics, repo.rule_configuration, repo.ignores))


def check_source(source: Source) -> Checked:
    with collector_paused():
        repo, diagnostics = load_repository(source)
        diagnostics.extend(check_repository(repo))
        return judged(repo, diagnostics)


def check(
    root: Path, rev: str | None = None, build: Callable[[Source], Checked] | None = None
) -> Checked:
    """Raises SourceError when the folder or revision cannot be read at all. `build` checks
    the source instead of `check_source` (an incremental build's `BuildCache.check`)."""
    source = open_source(root, rev)
    try:
        return (build or check_source)(source)
    finally:
        close = getattr(source, "close", None)
        if close is not None:
            close()


def check_with(root: Path, files: dict[str, bytes]) -> Checked:
    """The work tree at `root` checked as if `files` (repository-relative paths) were written:
    what a command writes is proved valid before it is."""
    return check(root, build=lambda source: check_source(OverlaySource(source, files)))
