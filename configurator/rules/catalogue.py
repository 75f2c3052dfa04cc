"""Catalogue sanity (RC6xx): the models under models/ are consistent with themselves."""

from __future__ import annotations

from typing import Any

from configurator.composition import definition_problems
from configurator.diagnostics import did_you_mean
from configurator.repository import Entry, Repository
from configurator.rules.report import Reporter
from configurator.types import SettingDefinition


def _settings(
    report: Reporter,
    entry: Entry[Any],
    base: list[str | int],
    settings: dict[str, SettingDefinition],
) -> None:
    for name, definition in settings.items():
        for field, code, message in definition_problems(definition):
            report.error(entry, [*base, name, field], code, f"setting '{name}': {message}")


def check_catalogue(repo: Repository, report: Reporter) -> None:
    actions = repo.actions
    known_actions = set(actions) | repo.broken.get("action", set())

    for platform in repo.platforms.values():
        for template in platform.templates.values():
            _settings(report, template, ["settings"], template.model.settings)
            seen: set[str] = set()
            for i, mapping in enumerate(template.model.mappings):
                if mapping in seen:
                    report.error(
                        template, ["mappings", i], "RC607", f"mapping '{mapping}' is listed twice"
                    )
                seen.add(mapping)
            for scheme in platform.schemes.values():
                unbound = [m for m in template.model.mappings if m not in scheme.model.mappings]
                if unbound:
                    report.warning(
                        scheme,
                        ["mappings"],
                        "RC608",
                        f"does not bind {', '.join(unbound)} of robot template "
                        f"'{template.name}' ({platform.name}); logics needing them cannot run "
                        "under this scheme",
                    )

    for name, action in actions.items():
        model = action.model
        for i, platform_name in enumerate(model.platforms):
            if platform_name not in repo.platforms:
                report.error(
                    action,
                    ["platforms", i],
                    "RC605",
                    f"unknown platform '{platform_name}'"
                    f"{did_you_mean(platform_name, repo.platforms)}",
                )
        for i, required in enumerate(model.requires):
            if required == name:
                report.error(action, ["requires", i], "RC604", f"action '{name}' requires itself")
            elif required not in known_actions:
                report.error(
                    action,
                    ["requires", i],
                    "RC604",
                    f"requires unknown action '{required}'{did_you_mean(required, actions)}",
                )
        for logic_name, logic in model.logics.items():
            _settings(report, action, ["logics", logic_name, "settings"], logic.settings)

    for task in repo.tasks.values():
        for i, implementation in enumerate(task.model.implementations):
            if not implementation:
                report.error(
                    task, ["implementations", i], "RC603", "an implementation lists no actions"
                )
            for j, action_name in enumerate(implementation):
                if action_name not in known_actions:
                    report.error(
                        task,
                        ["implementations", i, j],
                        "RC603",
                        f"unknown action '{action_name}'{did_you_mean(action_name, actions)}",
                    )

    for environment in repo.environments.values():
        first: dict[str, int] = {}
        for i, obj in enumerate(environment.model.objects):
            if obj.id in first:
                line, _ = environment.doc.locate(["objects", first[obj.id], "id"])
                report.error(
                    environment,
                    ["objects", i, "id"],
                    "RC606",
                    f"object id '{obj.id}' is used twice (first at line {line}); ids are unique",
                )
            else:
                first[obj.id] = i
