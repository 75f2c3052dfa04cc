"""Renders Launch Requests: fleet -> scenario -> capability -> catalogue, defaults filled.

Pure: the caller has validated the repository; a request is never rendered from a bad one.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from robotconf.configurator.composition import achievable_tasks, find_location
from robotconf.configurator.drift import logics_needing
from robotconf.configurator.gcpause import collector_paused
from robotconf.configurator.rendered import FleetRequests, RenderedRequest, ScenarioRequests
from robotconf.configurator.repository import Repository
from robotconf.configurator.resolve import bound_mappings, resolve_capability
from robotconf.configurator.rosnames import UnresolvableName, absolute_namespace
from robotconf.configurator.types import (
    Action,
    JsonObject,
    RobotAssignment,
    RolloutPolicy,
    SettingDefinition,
    Stage,
    logic_choice,
    logic_names,
)
from robotconf.contract.diagnostics import did_you_mean
from robotconf.contract.launch import LaunchCapability, LaunchGoal, LaunchRequest, LaunchScenario


class RenderError(Exception):
    """The repository does not describe this robot (unknown id, no fleet)."""


@dataclass
class FleetRender:
    """Every assigned robot's request; suspended robots are rendered but flagged."""

    revision: str
    # Each stamped with `revision` as it is read (FleetRequests).
    requests: FleetRequests = field(default_factory=lambda: FleetRequests(""))
    suspended: set[str] = field(default_factory=set)
    scenario_of: dict[str, str] = field(default_factory=dict)
    labels: dict[str, dict[str, str]] = field(default_factory=dict)  # every robot's, maybe {}
    allow_empty: bool = False
    rollout: RolloutPolicy | None = None  # None: every robot at once
    stages: list[Stage] = field(default_factory=list)  # the promotion ladder; [] none
    groups: dict[str, list[str] | str] = field(default_factory=dict)  # fleet.yaml's groups
    drift: str = "warn"  # fleet.yaml's drift policy: warn or hold
    # capability -> mapping -> the selected logics that need it (drift messages name them)
    needed_by: dict[str, dict[str, tuple[str, ...]]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if isinstance(self.requests, FleetRequests) and not self.requests:
            self.requests.revision = self.revision


def deep_merge(base: JsonObject, over: JsonObject) -> JsonObject:
    """`over` merged into `base`: mappings merge key by key, anything else replaces. Neither
    is changed; the result shares what it does not merge with them (rendered content is
    never changed in place, and 10,000 robots' knowledge need not be 10,000 copies)."""
    merged: JsonObject = dict(base)
    for key, value in over.items():
        current = merged.get(key)
        if isinstance(value, dict) and isinstance(current, dict):
            merged[key] = deep_merge(current, value)
        else:
            merged[key] = value
    return merged


def _settings(definitions: dict[str, SettingDefinition], chosen: dict[str, Any]) -> JsonObject:
    values: JsonObject = {name: d.default for name, d in definitions.items()}
    values.update(chosen)
    return values


def request_for(
    repo: Repository,
    robot_id: str,
    assignment: RobotAssignment,
    scenario: ScenarioRequests | None = None,
) -> RenderedRequest:
    """The robot's request from its scenario's shared content (`scenario`: that of the
    robot's scenario, rendered once for all its robots; by default rendered here)."""
    if scenario is None:
        scenario = scenario_requests(repo, assignment.scenario)
    namespace = assignment.namespace
    try:
        return scenario.request(
            robot_id,
            assignment.name or robot_id,
            repo.revision,
            absolute_namespace(namespace) if namespace is not None else None,
            assignment.ros_domain_id,
        )
    except UnresolvableName as e:
        raise RenderError(f"robot '{robot_id}': {e}") from None


def scenario_requests(repo: Repository, scenario_name: str) -> ScenarioRequests:
    """The scenario's content and the ROS domain of its robots that name none (that of the
    environment it runs in, if any), for its robots' requests."""
    return ScenarioRequests(
        render_scenario(repo, scenario_name), environment_domain(repo, scenario_name)
    )


def environment_domain(repo: Repository, scenario_name: str) -> int | None:
    """The ROS domain the scenario's environment names (the default of its robots), or None."""
    environment = repo.scenarios[scenario_name].model.environment
    if environment is None:
        return None
    return repo.environments[environment].model.ros_domain_id


def render_scenario(repo: Repository, scenario_name: str) -> LaunchScenario:
    """A scenario's content, shared by its robots: mapping names as the scheme writes them
    (`for_robot` resolves them per robot)."""
    scenario = repo.scenarios[scenario_name].model
    capability = repo.capabilities[scenario.capability].model
    resolved = resolve_capability(repo, capability)
    if resolved.scheme is None:
        raise RenderError(f"capability '{scenario.capability}' has no usable mapping scheme")
    tasks = {name: entry.model for name, entry in repo.tasks.items()}
    logic_settings = {
        s.logic_name: _settings(s.logic.settings, scenario.logic_settings.get(s.logic_name, {}))
        for s in resolved.all_selections()
        if s.logic.settings or s.logic_name in scenario.logic_settings
    }
    robot_settings = (
        _settings(resolved.template.settings, scenario.robot_settings) if resolved.template else {}
    )

    environment = None
    knowledge: JsonObject = {}
    if scenario.environment is not None:
        environment = repo.environments[scenario.environment].model
        for set_name in scenario.knowledge_sets:
            knowledge = deep_merge(knowledge, environment.knowledge_sets[set_name])
    knowledge = deep_merge(knowledge, scenario.knowledge)

    goals = []
    for goal in scenario.goals:
        location = None
        if goal.location is not None and environment is not None:
            location = find_location(environment, goal.location)[0].model_dump(mode="json")
        goals.append(LaunchGoal(task=goal.task, location=location))

    return LaunchScenario(
        name=scenario_name,
        capability=LaunchCapability(
            name=scenario.capability,
            platform=capability.platform,
            robot_template=capability.robot_template,
            mapping_scheme=capability.mapping_scheme,
            tasks=achievable_tasks(tasks, capability.actions),
            actions=sorted(capability.actions),
            logics={a: logic_choice(logic_names(c)) for a, c in capability.actions.items()},
            mappings=bound_mappings(resolved),
        ),
        environment_name=scenario.environment,
        environment_type=environment.type if environment else None,
        robot_settings=robot_settings,
        logic_settings=logic_settings,
        environment_knowledge=knowledge,
        goals=goals,
    )


ScenarioOf = Callable[[str], ScenarioRequests]
RequestOf = Callable[[str, RobotAssignment, ScenarioRequests], RenderedRequest]
NeedsOf = Callable[[LaunchCapability, Mapping[str, Action]], dict[str, tuple[str, ...]]]


def render_fleet(
    repo: Repository,
    scenario_of: ScenarioOf | None = None,
    request_of: RequestOf | None = None,
    needs_of: NeedsOf = logics_needing,
) -> FleetRender:
    """Every robot's request. `scenario_of`, `request_of` and `needs_of` may serve what an
    earlier build worked out (configurator/incremental.py); by default each scenario is
    rendered once here."""
    with collector_paused():
        return _render_fleet(repo, scenario_of, request_of, needs_of)


def _render_fleet(
    repo: Repository,
    scenario_of: ScenarioOf | None,
    request_of: RequestOf | None,
    needs_of: NeedsOf,
) -> FleetRender:
    if repo.fleet is None:
        raise RenderError("configs/fleet.yaml does not exist: no robot is assigned")
    fleet = repo.fleet.model
    result = FleetRender(
        revision=repo.revision,
        requests=FleetRequests(repo.revision),
        allow_empty=fleet.allow_empty,
        rollout=fleet.rollout,
        stages=fleet.stages,
        groups=fleet.groups,
        drift=fleet.drift,
    )
    scenarios: dict[str, ScenarioRequests] = {}

    def each_once(name: str) -> ScenarioRequests:
        scenario = scenarios.get(name)
        if scenario is None:
            scenario = scenarios[name] = scenario_requests(repo, name)
        return scenario

    scenario_for = scenario_of or each_once
    requests, scenario_names, labels = result.requests, result.scenario_of, result.labels
    used: dict[int, ScenarioRequests] = {}  # the scenarios robots use, in the fleet's order
    for robot_id, assignment in fleet.robots.items():
        scenario = scenario_for(assignment.scenario)
        used.setdefault(id(scenario), scenario)
        requests[robot_id] = (
            request_for(repo, robot_id, assignment, scenario)
            if request_of is None
            else request_of(robot_id, assignment, scenario)
        )
        scenario_names[robot_id] = assignment.scenario
        labels[robot_id] = dict(assignment.labels)
        if assignment.suspended:
            result.suspended.add(robot_id)
    result.needed_by = needed_by(repo, used.values(), needs_of)
    return result


def needed_by(
    repo: Repository, scenarios: Iterable[ScenarioRequests], needs_of: NeedsOf
) -> dict[str, dict[str, tuple[str, ...]]]:
    """Per capability the fleet uses (that of the scenarios its robots use), which of its
    logics need each mapping: what drift messages name (a request says which logics, not
    which needs what)."""
    actions = {name: entry.model for name, entry in repo.actions.items()}
    found: dict[str, dict[str, tuple[str, ...]]] = {}
    for scenario in scenarios:
        capability = scenario.scenario.capability
        if capability.name not in found:
            found[capability.name] = needs_of(capability, actions)
    return found


def render_robot(repo: Repository, robot_id: str) -> LaunchRequest:
    if repo.fleet is None:
        raise RenderError("configs/fleet.yaml does not exist: no robot is assigned")
    assignment = repo.fleet.model.robots.get(robot_id)
    if assignment is None:
        raise RenderError(
            f"robot '{robot_id}' is not in configs/fleet.yaml"
            f"{did_you_mean(robot_id, repo.fleet.model.robots)}"
        )
    return request_for(repo, robot_id, assignment).model()
