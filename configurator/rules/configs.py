"""Configuration rules (RC2xx-RC5xx): every capability, scenario and robot is buildable."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from robotconf.configurator.composition import (
    find_location,
    implementation_for,
    missing_requires,
    scheme_gaps,
    setting_problem,
    template_gaps,
)
from robotconf.configurator.repository import Entry, Repository
from robotconf.configurator.resolve import ResolvedCapability, resolve_capability
from robotconf.configurator.rules.report import Reporter
from robotconf.configurator.types import (
    CapabilityConfiguration,
    Environment,
    Goal,
    JsonScalar,
    ScenarioConfiguration,
    SettingDefinition,
    is_robot_id,
    reserved_robot_id,
)
from robotconf.contract.diagnostics import closest


def check_capability(
    repo: Repository, entry: Entry[CapabilityConfiguration], report: Reporter
) -> ResolvedCapability:
    config = entry.model
    resolved = resolve_capability(repo, config)
    platform = resolved.platform
    if platform is None:
        report.unknown(
            entry,
            ["platform"],
            "RC201",
            f"unknown platform '{config.platform}'",
            config.platform,
            repo.platforms,
        )
        return resolved
    scheme_name = config.mapping_scheme
    if resolved.scheme is None:
        report.unknown(
            entry,
            ["mapping_scheme"],
            "RC202",
            f"platform {platform.name} has no mapping scheme '{scheme_name}'",
            scheme_name,
            platform.schemes,
            unreadable=repo.is_broken("mapping-scheme", f"{platform.name}/{scheme_name}"),
        )
    template_name = config.robot_template
    if template_name is not None and resolved.template is None:
        report.unknown(
            entry,
            ["robot_template"],
            "RC203",
            f"platform {platform.name} has no robot template '{template_name}'",
            template_name,
            platform.templates,
            unreadable=repo.is_broken("robot-template", f"{platform.name}/{template_name}"),
        )

    for action_name in config.actions:
        _check_action(repo, entry, resolved, action_name, report)

    _check_mappings(entry, resolved, report)
    return resolved


def logic_loc(config: CapabilityConfiguration, action: str, index: int) -> list[str | int]:
    """Where the capability names the action's `index`-th logic: its list item, or the value
    itself when it names one logic."""
    if isinstance(config.actions.get(action), list):
        return ["actions", action, index]
    return ["actions", action]


def _check_action(
    repo: Repository,
    entry: Entry[CapabilityConfiguration],
    resolved: ResolvedCapability,
    action_name: str,
    report: Reporter,
) -> None:
    """One action of the capability: known, for its platform, each of its logics known, and
    the actions it requires selected."""
    config = entry.model
    action_entry = repo.actions.get(action_name)
    if action_entry is None:
        report.unknown(
            entry,
            ["actions", action_name],
            "RC204",
            f"unknown action '{action_name}'",
            action_name,
            repo.actions,
            unreadable=repo.is_broken("action", action_name),
            key=True,
        )
        return
    action = action_entry.model
    if config.platform not in action.platforms:
        report.add(
            entry,
            ["actions", action_name],
            "RC204",
            f"action '{action_name}' is for {', '.join(action.platforms)}, "
            f"not platform {config.platform}",
            key=True,
        )
    for index, logic_name in enumerate(config.logics_of(action_name)):
        if logic_name not in action.logics:
            report.unknown(
                entry,
                logic_loc(config, action_name, index),
                "RC205",
                f"action '{action_name}' has no logic '{logic_name}'",
                logic_name,
                action.logics,
            )
    if action_name not in resolved.selections:
        return
    meant = meant_actions(repo, config)
    for required in missing_requires(action, config.actions):
        if required in meant:
            continue  # the RC204 of the name misspelling it says it
        report.add(
            entry,
            ["actions", action_name],
            "RC303",
            f"action '{action_name}' requires action '{required}', which is not selected; "
            f"add it under actions",
            key=True,
        )


def _check_mappings(
    entry: Entry[CapabilityConfiguration], resolved: ResolvedCapability, report: Reporter
) -> None:
    """Every mapping a selected logic needs is in the template and bound by the scheme."""
    config = entry.model
    if resolved.template is not None:
        needers: dict[str, list[str]] = {}
        for selection in resolved.all_selections():
            for mapping in template_gaps(selection.logic, resolved.template):
                needers.setdefault(mapping, []).append(selection.logic_name)
        if needers:
            listing = "; ".join(f"'{m}' needed by {', '.join(ls)}" for m, ls in needers.items())
            report.add(
                entry,
                ["robot_template"],
                "RC301",
                f"robot template '{config.robot_template}' lacks mappings the selected logics "
                f"need: {listing}",
            )
    if resolved.scheme is not None:
        for selection in resolved.all_selections():
            unbound = scheme_gaps(selection.logic, resolved.scheme)
            if unbound:
                index = config.logics_of(selection.action_name).index(selection.logic_name)
                report.add(
                    entry,
                    logic_loc(config, selection.action_name, index),
                    "RC302",
                    f"logic '{selection.logic_name}' needs {', '.join(unbound)}, which mapping "
                    f"scheme '{config.mapping_scheme}' does not bind",
                )


def _check_setting(
    report: Reporter,
    entry: Entry[Any],
    loc: list[str | int],
    name: str,
    value: JsonScalar,
    definitions: dict[str, SettingDefinition],
    owner: str,
) -> None:
    definition = definitions.get(name)
    if definition is None:
        report.unknown(
            entry, loc, "RC401", f"{owner} has no setting '{name}'", name, definitions, key=True
        )
        return
    problem = setting_problem(definition, value)
    if problem is not None:
        report.add(entry, loc, problem[0], f"setting '{name}' {problem[1]}")


def meant_actions(repo: Repository, config: CapabilityConfiguration) -> set[str]:
    """The actions the capability's unknown action names (RC204) were meant to be, as their
    did-you-mean names them: a requirement or a task missing one of them is not reported
    again (RC303, RC304) while the typo stands."""
    return {
        meant
        for name in config.actions
        if name not in repo.actions and (meant := closest(name, repo.actions)) is not None
    }


def _logics_maybe_meant(repo: Repository, config: CapabilityConfiguration) -> set[str]:
    """Every logic of an action whose selection names a logic it lacks (RC205): the
    capability may have meant any of them, so settings for them are not also RC406."""
    meant: set[str] = set()
    for action_name, logic_name in config.selected_logics():
        action = repo.actions.get(action_name)
        if action is not None and logic_name not in action.model.logics:
            meant.update(action.model.logics)
    return meant


@dataclass(frozen=True)
class _Scenario:
    """A scenario configuration with what its checks look up: its capability, resolved, and
    its environment, each None when it is unknown or unreadable (the environment also when
    none is named)."""

    repo: Repository
    entry: Entry[ScenarioConfiguration]
    resolved: ResolvedCapability | None
    environment: Environment | None

    @property
    def model(self) -> ScenarioConfiguration:
        return self.entry.model


def check_scenario(
    repo: Repository,
    entry: Entry[ScenarioConfiguration],
    capabilities: dict[str, ResolvedCapability],
    report: Reporter,
) -> None:
    """Every check of `_SCENARIO_CHECKS` on the scenario, in that order."""
    scenario = entry.model
    environment = None
    if scenario.environment is not None:
        environment = repo.environments.get(scenario.environment)
    subject = _Scenario(
        repo,
        entry,
        capabilities.get(scenario.capability),
        environment.model if environment is not None else None,
    )
    for check in _SCENARIO_CHECKS:
        check(subject, report)


def _check_capability_known(subject: _Scenario, report: Reporter) -> None:
    """RC206: the capability configuration the scenario names exists."""
    scenario = subject.model
    if subject.resolved is None:
        report.unknown(
            subject.entry,
            ["capability"],
            "RC206",
            f"unknown capability configuration '{scenario.capability}'",
            scenario.capability,
            subject.repo.capabilities,
            unreadable=subject.repo.is_broken("capability", scenario.capability),
        )


def _check_robot_settings(subject: _Scenario, report: Reporter) -> None:
    """RC405, RC401, RC4xx: robot settings go with a robot template, which defines them."""
    scenario, resolved = subject.model, subject.resolved
    if resolved is None:
        return
    template = resolved.template
    if scenario.robot_settings and resolved.config.robot_template is None:
        report.add(
            subject.entry,
            ["robot_settings"],
            "RC405",
            f"robot settings need a robot template, and capability '{scenario.capability}' "
            "names none; set robot_template there or remove robot_settings",
            key=True,
        )
    elif template is not None:
        for name, value in scenario.robot_settings.items():
            _check_setting(
                report,
                subject.entry,
                ["robot_settings", name],
                name,
                value,
                template.settings,
                f"robot template '{resolved.config.robot_template}'",
            )


def _check_logic_settings(subject: _Scenario, report: Reporter) -> None:
    """RC406, RC401, RC4xx: logic settings are for logics the capability selects, which
    define them."""
    scenario, resolved = subject.model, subject.resolved
    if resolved is None:
        return
    selected_logics = {s.logic_name: s for s in resolved.all_selections()}
    named = {logic for _, logic in resolved.config.selected_logics()}
    meant = _logics_maybe_meant(subject.repo, resolved.config)
    for logic_name, values in scenario.logic_settings.items():
        selection = selected_logics.get(logic_name)
        if selection is None and logic_name in named:
            continue  # its action is unknown or unreadable: reported at the capability
        if selection is None and logic_name in meant:
            continue  # the capability's RC205 (a misspelt logic of its action) says it
        if selection is None:
            report.unknown(
                subject.entry,
                ["logic_settings", logic_name],
                "RC406",
                f"logic '{logic_name}' is not selected by capability '{scenario.capability}'",
                logic_name,
                selected_logics,
                key=True,
            )
            continue
        for name, value in values.items():
            _check_setting(
                report,
                subject.entry,
                ["logic_settings", logic_name, name],
                name,
                value,
                selection.logic.settings,
                f"logic '{logic_name}'",
            )


def _check_environment_known(subject: _Scenario, report: Reporter) -> None:
    """RC207: the environment the scenario names, if any, exists."""
    name = subject.model.environment
    if name is not None and subject.environment is None:
        report.unknown(
            subject.entry,
            ["environment"],
            "RC207",
            f"unknown environment '{name}'",
            name,
            subject.repo.environments,
            unreadable=subject.repo.is_broken("environment", name),
        )


def _check_knowledge_sets(subject: _Scenario, report: Reporter) -> None:
    """RC208: each knowledge set is one of the scenario's environment."""
    scenario, environment = subject.model, subject.environment
    for i, set_name in enumerate(scenario.knowledge_sets):
        if scenario.environment is None:
            report.add(
                subject.entry,
                ["knowledge_sets", i],
                "RC208",
                f"knowledge set '{set_name}' needs an environment; set 'environment'",
            )
        elif environment is not None and set_name not in environment.knowledge_sets:
            report.unknown(
                subject.entry,
                ["knowledge_sets", i],
                "RC208",
                f"environment '{scenario.environment}' has no knowledge set '{set_name}'",
                set_name,
                environment.knowledge_sets,
            )


def _check_goals(subject: _Scenario, report: Reporter) -> None:
    """Each goal's task, then its location, goal after goal."""
    resolved = subject.resolved
    meant = meant_actions(subject.repo, resolved.config) if resolved is not None else set()
    for i, goal in enumerate(subject.model.goals):
        _check_goal_task(subject, i, goal, meant, report)
        _check_goal_location(subject, i, goal, report)


def _check_goal_task(
    subject: _Scenario, i: int, goal: Goal, meant: set[str], report: Reporter
) -> None:
    """RC210, RC304: the goal's task exists and the capability's actions achieve it (or would,
    with the actions its misspelt names were `meant` to be)."""
    resolved = subject.resolved
    task_entry = subject.repo.tasks.get(goal.task)
    if task_entry is None:
        report.unknown(
            subject.entry,
            ["goals", i, "task"],
            "RC210",
            f"unknown task '{goal.task}'",
            goal.task,
            subject.repo.tasks,
            unreadable=subject.repo.is_broken("task", goal.task),
        )
    elif (
        resolved is not None
        and implementation_for(task_entry.model, resolved.config.actions) is None
        # a misspelt action (RC204) may be what the task misses: once is enough
        and implementation_for(task_entry.model, {*resolved.config.actions, *meant}) is None
    ):
        options = " or ".join(
            "[" + ", ".join(impl) + "]" for impl in task_entry.model.implementations
        )
        report.add(
            subject.entry,
            ["goals", i, "task"],
            "RC304",
            f"task '{goal.task}' is not achievable by capability '{subject.model.capability}': "
            f"it needs the actions {options}",
        )


def _check_goal_location(subject: _Scenario, i: int, goal: Goal, report: Reporter) -> None:
    """RC306, RC305: a goal's location names exactly one Location object of the scenario's
    environment."""
    if goal.location is None:
        return
    environment, name = subject.environment, subject.model.environment
    loc: list[str | int] = ["goals", i, "location"]
    if name is None:
        report.add(
            subject.entry,
            loc,
            "RC306",
            f"goal location '{goal.location}' needs an environment; set 'environment'",
        )
    elif environment is not None:
        matches = find_location(environment, goal.location)
        locations = [o for o in environment.objects if o.type == "Location"]
        if not matches:
            report.unknown(
                subject.entry,
                loc,
                "RC305",
                f"environment '{name}' has no object '{goal.location}'",
                goal.location,
                [o.name for o in locations] + [o.id for o in locations],
            )
        elif len(matches) > 1:
            report.add(
                subject.entry,
                loc,
                "RC305",
                f"'{goal.location}' names {len(matches)} objects of environment '{name}'; "
                "use the object's id",
            )
        elif matches[0].type != "Location":
            report.add(
                subject.entry,
                loc,
                "RC305",
                f"'{goal.location}' is a {matches[0].type}, not a Location",
            )


# The scenario's checks, in the order their diagnostics are listed.
_SCENARIO_CHECKS: tuple[Callable[[_Scenario, Reporter], None], ...] = (
    _check_capability_known,
    _check_robot_settings,
    _check_logic_settings,
    _check_environment_known,
    _check_knowledge_sets,
    _check_goals,
)


def check_fleet(repo: Repository, report: Reporter) -> None:
    fleet = repo.fleet
    if fleet is None:
        return
    for robot_id, assignment in fleet.model.robots.items():
        if not is_robot_id(robot_id):
            report.add(
                fleet,
                ["robots", robot_id],
                "RC501",
                f"robot id {robot_id!r} is not usable as an MQTT topic level: use 1-64 "
                "letters, digits, '_', '.', '-', starting with a letter or digit",
                key=True,
            )
        elif (user := reserved_robot_id(robot_id)) is not None:
            report.add(
                fleet,
                ["robots", robot_id],
                "RC501",
                f"robot id {robot_id!r} is reserved: '{user}' is the broker user of the "
                "service side, and a robot logs in as its id; choose another id",
                key=True,
            )
        if assignment.scenario not in repo.scenarios:
            report.unknown(
                fleet,
                ["robots", robot_id, "scenario"],
                "RC209",
                f"unknown scenario '{assignment.scenario}'",
                assignment.scenario,
                repo.scenarios,
                unreadable=repo.is_broken("scenario", assignment.scenario),
            )
