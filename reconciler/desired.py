"""Build step: one git commit -> the validated, rendered fleet, or why it cannot be applied;
incrementally, from what the builds before proved."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from robotconf.configurator.incremental import BuildCache
from robotconf.configurator.render import FleetRender, RenderError, render_fleet
from robotconf.configurator.source import SourceError
from robotconf.configurator.workspace import check
from robotconf.contract.wire import ReconcilerReason, StatusDiagnostic

MAX_DIAGNOSTICS = 50  # a retained status message must stay small
FLEET_FILE = "configs/fleet.yaml"


@dataclass
class Desired:
    """What one commit asks for: `fleet` when it is applicable, else the problems that stop it
    (at most MAX_DIAGNOSTICS of them; `omitted` counts the rest)."""

    revision: str
    fleet: FleetRender | None
    problems: list[StatusDiagnostic] = field(default_factory=list)
    omitted: int = 0

    @property
    def ok(self) -> bool:
        return self.fleet is not None


def build_failure(revision: str, message: str, *, path: str | None = None) -> Desired:
    """A commit that cannot be applied for one reason that is not a rule's finding."""
    problem = StatusDiagnostic(path=path, code=ReconcilerReason.BUILD_FAILED.value, message=message)
    return Desired(revision, None, [problem])


def load_desired(root: Path, revision: str, cache: BuildCache | None = None) -> Desired:
    """Reads the commit itself (never the work tree), validates it and renders every robot;
    with `cache`, only what differs from the builds before (the verdict is the same)."""
    try:
        checked = check(root, revision, cache.check if cache is not None else None)
    except SourceError as exc:
        return build_failure(revision, f"cannot read {revision}: {exc}")
    if not checked.ok:
        errors = checked.errors
        problems = [StatusDiagnostic.of(d) for d in errors[:MAX_DIAGNOSTICS]]
        return Desired(revision, None, problems, max(0, len(errors) - MAX_DIAGNOSTICS))
    try:
        fleet = cache.render(checked) if cache is not None else render_fleet(checked.repo)
    except RenderError as exc:
        return build_failure(revision, str(exc), path=FLEET_FILE)
    return Desired(revision, fleet)


class DesiredBuilder:
    """The reconciler's build step: `load_desired` with one cache for the reconciler's
    lifetime, so that a commit costs what it changes. The cache holds what the newest build
    uses and nothing more."""

    def __init__(self) -> None:
        self.cache = BuildCache()

    def __call__(self, root: Path, revision: str) -> Desired:
        return load_desired(root, revision, self.cache)
