"""Build step: one git commit -> the validated, rendered fleet, or why it cannot be applied."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from configurator.render import FleetRender, RenderError, render_fleet
from configurator.source import SourceError
from configurator.workspace import check

MAX_DIAGNOSTICS = 50  # a retained status message must stay small


@dataclass
class Desired:
    """What one commit asks for: `fleet` when it is applicable, else the errors that stop it."""

    revision: str
    fleet: FleetRender | None
    errors: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.fleet is not None


def load_desired(root: Path, revision: str) -> Desired:
    """Reads the commit itself (never the work tree), validates it and renders every robot."""
    try:
        checked = check(root, revision)
    except SourceError as exc:
        return Desired(revision, None, [f"cannot read {revision}: {exc}"])
    if not checked.ok:
        errors = [str(d) for d in checked.errors]
        if len(errors) > MAX_DIAGNOSTICS:
            more = len(errors) - MAX_DIAGNOSTICS
            errors = [
                *errors[:MAX_DIAGNOSTICS],
                f"... and {more} more (robotconf validate --rev {revision})",
            ]
        return Desired(revision, None, errors)
    try:
        fleet = render_fleet(checked.repo)
    except RenderError as exc:
        return Desired(revision, None, [f"configs/fleet.yaml: {exc}"])
    return Desired(revision, fleet)
