"""Catalogue sanity (RC6xx): the models under models/ are consistent with themselves."""

from __future__ import annotations

from typing import Any

from robotconf.configurator.composition import definition_problems
from robotconf.configurator.repository import Entry, Platform, Repository
from robotconf.configurator.rosnames import mapping_name_problem
from robotconf.configurator.rules.report import Reporter
from robotconf.configurator.types import (
    Action,
    Environment,
    MappingScheme,
    RobotTemplate,
    SettingDefinition,
    Task,
)


def _settings(
    report: Reporter,
    entry: Entry[Any],
    base: list[str | int],
    settings: dict[str, SettingDefinition],
) -> None:
    for name, definition in settings.items():
        for field, code, message in definition_problems(definition):
            report.add(entry, [*base, name, field], code, f"setting '{name}': {message}")


def check_template(template: Entry[RobotTemplate], report: Reporter) -> None:
    _settings(report, template, ["settings"], template.model.settings)
    seen: set[str] = set()
    for i, mapping in enumerate(template.model.mappings):
        if mapping in seen:
            report.add(template, ["mappings", i], "RC607", f"mapping '{mapping}' is listed twice")
        seen.add(mapping)


def check_scheme(platform: Platform, scheme: Entry[MappingScheme], report: Reporter) -> None:
    for template in platform.templates.values():
        unbound = [m for m in template.model.mappings if m not in scheme.model.mappings]
        if unbound:
            report.add(
                scheme,
                ["mappings"],
                "RC608",
                f"does not bind {', '.join(unbound)} of robot template "
                f"'{template.name}' ({platform.name}); logics needing them cannot run "
                "under this scheme",
            )
    for key, binding in scheme.model.mappings.items():
        problem = mapping_name_problem(binding.name)
        if problem is not None:
            report.add(
                scheme,
                ["mappings", key, "name"],
                "RC609",
                f"mapping '{key}': name '{binding.name}' {problem}",
            )


def check_action(repo: Repository, name: str, action: Entry[Action], report: Reporter) -> None:
    actions = repo.actions
    model = action.model
    for i, platform_name in enumerate(model.platforms):
        if platform_name not in repo.platforms:
            report.unknown(
                action,
                ["platforms", i],
                "RC605",
                f"unknown platform '{platform_name}'",
                platform_name,
                repo.platforms,
            )
    for i, required in enumerate(model.requires):
        if required == name:
            report.add(action, ["requires", i], "RC604", f"action '{name}' requires itself")
        elif required not in actions:
            report.unknown(
                action,
                ["requires", i],
                "RC604",
                f"requires unknown action '{required}'",
                required,
                actions,
                unreadable=repo.is_broken("action", required),
            )
    for logic_name, logic in model.logics.items():
        _settings(report, action, ["logics", logic_name, "settings"], logic.settings)


def check_task(repo: Repository, task: Entry[Task], report: Reporter) -> None:
    actions = repo.actions
    for i, implementation in enumerate(task.model.implementations):
        if not implementation:
            report.add(task, ["implementations", i], "RC603", "an implementation lists no actions")
        for j, action_name in enumerate(implementation):
            if action_name not in actions:
                report.unknown(
                    task,
                    ["implementations", i, j],
                    "RC603",
                    f"unknown action '{action_name}'",
                    action_name,
                    actions,
                    unreadable=repo.is_broken("action", action_name),
                )


def check_environment(environment: Entry[Environment], report: Reporter) -> None:
    first: dict[str, int] = {}
    for i, obj in enumerate(environment.model.objects):
        if obj.id in first:
            line, _ = environment.doc.locate(["objects", first[obj.id], "id"])
            report.add(
                environment,
                ["objects", i, "id"],
                "RC606",
                f"object id '{obj.id}' is used twice (first at line {line}); ids are unique",
            )
        else:
            first[obj.id] = i


def check_catalogue(repo: Repository, report: Reporter) -> None:
    for platform in repo.platforms.values():
        for template in platform.templates.values():
            check_template(template, report)
        for scheme in platform.schemes.values():
            check_scheme(platform, scheme, report)
    for name, action in repo.actions.items():
        check_action(repo, name, action, report)
    for task in repo.tasks.values():
        check_task(repo, task, report)
    for environment in repo.environments.values():
        check_environment(environment, report)
