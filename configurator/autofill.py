"""Autofill: a capability configuration that picks, per action, the logics the robot can run.

The selection is pure and takes "does this logic fit" as a parameter: a robot template and
mapping scheme answer it here (`template_fit`); a robot's reported interfaces may as well.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from robotconf.configurator.composition import missing_requires, why_unavailable
from robotconf.configurator.repository import Repository
from robotconf.configurator.types import (
    Action,
    CapabilityConfiguration,
    Logic,
    MappingScheme,
    RobotTemplate,
    logic_choice,
    logic_names,
)
from robotconf.contract.yamlio import document_text

# (action name, action, logic name, logic) -> why the logic cannot run; empty: it fits.
LogicFit = Callable[[str, Action, str, Logic], list[str]]


@dataclass
class FittingLogics:
    """What autofill selects: action -> its fitting logics (in the action's order), and why
    each action left out was left out."""

    chosen: dict[str, list[str]] = field(default_factory=dict)
    skipped: dict[str, list[str]] = field(default_factory=dict)  # action -> why not


def select_logics(
    actions: Mapping[str, Action], platform: str, fits: LogicFit, *, every: bool = False
) -> FittingLogics:
    """Per action of the platform, the first logic (in the action's order) that `fits`, or
    with `every` each one that does (the thesis' autofill: an action is lit when any of its
    logics is); then drop, until none is left, actions whose `requires` are not selected."""
    found = FittingLogics()
    for name, action in sorted(actions.items()):
        if platform not in action.platforms:
            continue
        fitting: list[str] = []
        reasons: list[str] = []
        for logic_name, logic in action.logics.items():
            why = fits(name, action, logic_name, logic)
            if why:
                reasons.append(f"{logic_name}: {'; '.join(why)}")
                continue
            fitting.append(logic_name)
            if not every:
                break
        if fitting:
            found.chosen[name] = fitting
        else:
            found.skipped[name] = reasons
    changed = True
    while changed:
        changed = False
        for name in list(found.chosen):
            missing = missing_requires(actions[name], found.chosen)
            if missing:
                del found.chosen[name]
                found.skipped[name] = [f"requires {', '.join(missing)}, which cannot be selected"]
                changed = True
    return found


def template_fit(platform: str, template: RobotTemplate, scheme: MappingScheme) -> LogicFit:
    """A logic fits when the template has, and the scheme binds, every mapping it needs."""

    def fits(_name: str, action: Action, _logic_name: str, logic: Logic) -> list[str]:
        return why_unavailable(action, logic, platform, template, scheme)

    return fits


@dataclass
class AutofillResult:
    config: CapabilityConfiguration
    skipped: dict[str, list[str]] = field(default_factory=dict)  # action -> why not


def both_fit(first: LogicFit, second: LogicFit) -> LogicFit:
    """A logic fits when it fits both (a template, and a live robot's interfaces)."""

    def fits(name: str, action: Action, logic_name: str, logic: Logic) -> list[str]:
        return first(name, action, logic_name, logic) + second(name, action, logic_name, logic)

    return fits


def autofill(
    repo: Repository,
    platform_name: str,
    scheme_name: str,
    template_name: str | None,
    *,
    every: bool = False,
    robot_fit: LogicFit | None = None,
) -> AutofillResult:
    """The capability configuration of what the template and scheme can run (and, with
    `robot_fit`, what a live robot's interfaces serve too): per action the first fitting
    logic, or with `every` each fitting logic. The caller has checked that platform, scheme
    and template exist, and gives a template or `robot_fit`."""
    platform = repo.platforms[platform_name]
    scheme = platform.schemes[scheme_name].model
    actions = {name: entry.model for name, entry in repo.actions.items()}
    fit = robot_fit
    if template_name is not None:
        template = platform.templates[template_name].model
        fit = template_fit(platform_name, template, scheme)
        if robot_fit is not None:
            fit = both_fit(fit, robot_fit)
    if fit is None:
        raise ValueError("autofill needs a robot template or a robot's interfaces")
    found = select_logics(actions, platform_name, fit, every=every)
    config = CapabilityConfiguration(
        name=None,
        platform=platform_name,
        mapping_scheme=scheme_name,
        robot_template=template_name,
        actions={name: logic_choice(logics) for name, logics in found.chosen.items()},
    )
    return AutofillResult(config, found.skipped)


def to_yaml(config: CapabilityConfiguration, schema_ref: str, comment: str) -> str:
    """The file text, with the editor modeline, written by the emitter (contract.yamlio): names
    are quoted only where YAML needs it, and an action's logics are a list only when it selects
    several."""
    body: dict[str, Any] = {"platform": config.platform, "mapping_scheme": config.mapping_scheme}
    if config.robot_template is not None:
        body["robot_template"] = config.robot_template
    body["actions"] = {}
    for action, choice in config.actions.items():
        names = logic_names(choice)
        body["actions"][action] = names[0] if len(names) == 1 else list(names)
    return document_text([f"yaml-language-server: $schema={schema_ref}", comment], body)
