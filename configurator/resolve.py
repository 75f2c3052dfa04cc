"""Looks up what a capability configuration names in the catalogue (no judgement, no errors)."""

from __future__ import annotations

from dataclasses import dataclass, field

from configurator.repository import Platform, Repository
from configurator.types import Action, CapabilityConfiguration, Logic, MappingScheme, RobotTemplate


@dataclass(frozen=True)
class Selection:
    action_name: str
    action: Action
    logic_name: str
    logic: Logic


@dataclass
class ResolvedCapability:
    """The catalogue pieces a capability configuration names; None where a name is unknown."""

    config: CapabilityConfiguration
    platform: Platform | None
    template: RobotTemplate | None
    scheme: MappingScheme | None
    selections: dict[str, Selection] = field(default_factory=dict)


def resolve_capability(repo: Repository, config: CapabilityConfiguration) -> ResolvedCapability:
    platform = repo.platform(config.platform)
    template = scheme = None
    if platform is not None:
        if config.robot_template is not None:
            entry = platform.templates.get(config.robot_template)
            template = entry.model if entry else None
        scheme_entry = platform.schemes.get(config.mapping_scheme)
        scheme = scheme_entry.model if scheme_entry else None
    resolved = ResolvedCapability(config, platform, template, scheme)
    for action_name, logic_name in config.actions.items():
        action_entry = repo.actions.get(action_name)
        if action_entry is None:
            continue
        logic = action_entry.model.logics.get(logic_name)
        if logic is not None:
            resolved.selections[action_name] = Selection(
                action_name, action_entry.model, logic_name, logic
            )
    return resolved
