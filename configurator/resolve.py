"""Looks up what a capability configuration names in the catalogue (no judgement, no errors)."""

from __future__ import annotations

from dataclasses import dataclass, field

from robotconf.configurator.repository import Platform, Repository
from robotconf.configurator.types import (
    Action,
    CapabilityConfiguration,
    Logic,
    MappingBinding,
    MappingScheme,
    RobotTemplate,
    logic_names,
)


@dataclass(frozen=True)
class Selection:
    """One selected logic of an action (an action may select several)."""

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
    # action -> its selected logics that exist, in the order written (an unknown one is left
    # out: validation reports it); an action with none of them known is absent.
    selections: dict[str, list[Selection]] = field(default_factory=dict)

    def all_selections(self) -> list[Selection]:
        """Every selected logic that exists, action by action."""
        return [s for found in self.selections.values() for s in found]


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
    for action_name, choice in config.actions.items():
        action_entry = repo.actions.get(action_name)
        if action_entry is None:
            continue
        action = action_entry.model
        found = [
            Selection(action_name, action, logic_name, action.logics[logic_name])
            for logic_name in logic_names(choice)
            if logic_name in action.logics
        ]
        if found:
            resolved.selections[action_name] = found
    return resolved


def bound_mappings(resolved: ResolvedCapability) -> dict[str, MappingBinding]:
    """The mappings the selected logics need, as the scheme binds them (names unresolved);
    one the scheme does not bind is left out (validation reports it)."""
    if resolved.scheme is None:
        return {}
    needed = sorted({m for s in resolved.all_selections() for m in s.logic.mappings})
    bindings = resolved.scheme.mappings
    return {m: bindings[m] for m in needed if m in bindings}
