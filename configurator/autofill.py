"""Autofill: a capability configuration that picks, per action, a logic the robot can run."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import yaml

from configurator.composition import missing_requires, why_unavailable
from configurator.repository import Repository
from configurator.types import CapabilityConfiguration


@dataclass
class AutofillResult:
    config: CapabilityConfiguration
    skipped: dict[str, list[str]] = field(default_factory=dict)  # action -> why not


def autofill(
    repo: Repository, platform_name: str, scheme_name: str, template_name: str
) -> AutofillResult:
    """Per action of the platform, the first logic (in the action's order) the template and
    scheme serve; then drop, until none is left, actions whose `requires` are not selected.
    The caller has checked that platform, scheme and template exist."""
    platform = repo.platforms[platform_name]
    template = platform.templates[template_name].model
    scheme = platform.schemes[scheme_name].model
    chosen: dict[str, str] = {}
    skipped: dict[str, list[str]] = {}
    for name, entry in sorted(repo.actions.items()):
        action = entry.model
        if platform_name not in action.platforms:
            continue
        reasons: list[str] = []
        for logic_name, logic in action.logics.items():
            why = why_unavailable(action, logic, platform_name, template, scheme)
            if not why:
                chosen[name] = logic_name
                break
            reasons.append(f"{logic_name}: {'; '.join(why)}")
        else:
            skipped[name] = reasons
    changed = True
    while changed:
        changed = False
        for name in list(chosen):
            missing = missing_requires(repo.actions[name].model, chosen)
            if missing:
                del chosen[name]
                skipped[name] = [f"requires {', '.join(missing)}, which cannot be selected"]
                changed = True
    config = CapabilityConfiguration(
        name=None,
        platform=platform_name,
        mapping_scheme=scheme_name,
        robot_template=template_name,
        actions=chosen,
    )
    return AutofillResult(config, skipped)


def to_yaml(config: CapabilityConfiguration, schema_ref: str, comment: str) -> str:
    """The file text, with the editor modeline; names are quoted only where YAML needs it."""
    lines = [
        f"# yaml-language-server: $schema={schema_ref}",
        f"# {comment}",
        f"platform: {_scalar(config.platform)}",
        f"mapping_scheme: {_scalar(config.mapping_scheme)}",
    ]
    if config.robot_template is not None:
        lines.append(f"robot_template: {_scalar(config.robot_template)}")
    if config.actions:
        lines.append("actions:")
        lines.extend(f"  {_scalar(a)}: {_scalar(lg)}" for a, lg in config.actions.items())
    else:
        lines.append("actions: {}")
    return "\n".join(lines) + "\n"


def _scalar(text: str) -> str:
    try:
        plain = yaml.safe_load(f"k: {text}") if text and text.strip() == text else None
    except yaml.YAMLError:
        plain = None
    if isinstance(plain, dict) and plain.get("k") == text:
        return text
    return json.dumps(text)
