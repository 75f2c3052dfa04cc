"""ROS 2 names in the fleet (RC503-RC505): namespaces, `{namespace}`, and robots of one world
and ROS domain whose names clash."""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from robotconf.configurator.repository import Entry, Repository
from robotconf.configurator.resolve import bound_mappings, resolve_capability
from robotconf.configurator.rosnames import (
    NAME_BUDGET,
    NAMESPACE_SUBSTITUTION,
    absolute_namespace,
    length_problem,
    mapping_name_problem,
    name_cost,
    namespace_problem,
    needs_namespace,
    resolve_name,
    suggest_namespace,
)
from robotconf.configurator.rules.report import Reporter
from robotconf.configurator.types import MAX_ROS_DOMAIN_ID, Fleet, MappingBinding

# A service is a server the robots call: one of the world (a door controller) is shared on
# purpose, and two clients calling it do not drive each other. Topics and actions are a robot's
# own (its velocity, its navigation), so two robots on one name is the mistake to catch.
CLASHING_KINDS = ("topic", "action_client")
# The domain of a robot that names none, nor its environment: ROS's default.
DEFAULT_ROS_DOMAIN = 0


# A mapping as a robot resolves it: (key, kind, name as written, written absolute, tail). The
# tail is what follows the robot's namespace ('/' + a relative name, what follows
# `{namespace}`); None for an absolute name, which no namespace changes.
_Binding = tuple[str, str, str, bool, "str | None"]


@dataclass(frozen=True)
class _Robot:
    robot_id: str
    namespace: str | None
    # (environment, platform, ROS domain): robots that share one ROS graph
    world: tuple[str, str, int]
    domain_set: bool  # by the robot or its environment; else ROS's default
    scheme: str
    # The namespace written absolute, and the scenario's names: the robot's fully qualified
    # names are worked out when asked (`names`), as most are never compared.
    absolute: str | None
    scenario: ScenarioNames

    def names(self, all_names: bool = True) -> Iterator[tuple[str, str, str, bool]]:
        """(key, kind, fully qualified name, written absolute) of each mapping that may clash;
        with all_names False only those outside the robot's own namespace."""
        absolute = self.absolute
        if absolute is None:  # relative names at the root (`{namespace}` ones: see RC504)
            for key, kind, name, written_absolute, tail in self.scenario.clashing:
                yield key, kind, name if tail is None else tail, written_absolute
        elif all_names:
            for key, kind, name, written_absolute, tail in self.scenario.clashing:
                yield key, kind, name if tail is None else absolute + tail, written_absolute
        else:
            for key, kind, name, written_absolute, _ in self.scenario.fixed:
                yield key, kind, name, written_absolute


@dataclass(frozen=True)
class ScenarioNames:
    """What a scenario gives each of its robots to name: the same for all of them until each
    robot's namespace resolves the names."""

    world: tuple[str, str]  # (environment, platform)
    scheme: str  # platform/scheme, as messages name it
    bindings: dict[str, MappingBinding]  # the valid names the selected logics need
    domain: int | None = None  # the environment's ROS domain: its robots' default

    @functools.cached_property
    def resolvable(self) -> tuple[_Binding, ...]:
        """Each binding with its tail (see `_Binding`), in the bindings' order."""
        return tuple(_binding(key, b.kind, b.name) for key, b in self.bindings.items())

    @functools.cached_property
    def clashing(self) -> tuple[_Binding, ...]:
        """Those of `resolvable` two robots must not share (CLASHING_KINDS)."""
        return tuple(b for b in self.resolvable if b[1] in CLASHING_KINDS)

    @functools.cached_property
    def fixed(self) -> tuple[_Binding, ...]:
        """Those of `clashing` written absolute: the same for every robot."""
        return tuple(b for b in self.clashing if b[4] is None)

    @functools.cached_property
    def longest_tail(self) -> int:
        """The most a tail adds to a namespace, counted as DDS's limit counts a name."""
        tails = [t for *_, t in self.resolvable if t is not None]
        return max((name_cost(t) for t in tails), default=0)


def scenario_names(repo: Repository, scenario_name: str) -> ScenarioNames | None:
    """None when there is nothing (valid) to resolve: an unknown scenario, capability,
    platform or scheme, reported by the other rules."""
    scenario = repo.scenarios.get(scenario_name)
    if scenario is None:
        return None
    capability = repo.capabilities.get(scenario.model.capability)
    if capability is None:
        return None
    resolved = resolve_capability(repo, capability.model)
    if resolved.platform is None or resolved.scheme is None:
        return None
    bindings = {
        key: b
        for key, b in bound_mappings(resolved).items()
        if mapping_name_problem(b.name) is None
    }
    environment_name = scenario.model.environment
    environment = None if environment_name is None else repo.environments.get(environment_name)
    domain = None if environment is None else environment.model.ros_domain_id
    world = (environment_name or "", resolved.platform.name)
    scheme = f"{resolved.platform.name}/{capability.model.mapping_scheme}"
    return ScenarioNames(world, scheme, bindings, domain)


# One tuple per mapping of a scheme, shared by the scenarios that bind it (a 1,000-scenario lab
# binds a few hundred), not one per scenario.
@functools.lru_cache(maxsize=4096)
def _binding(key: str, kind: str, name: str) -> _Binding:
    tail: str | None = None
    if needs_namespace(name):
        tail = name[len(NAMESPACE_SUBSTITUTION) :]
    elif not name.startswith("/"):
        tail = "/" + name
    return key, kind, name, name.startswith("/"), tail


NamesOf = Callable[[str], "ScenarioNames | None"]


def _robot_names(
    fleet: Entry[Fleet], robot_id: str, names_of: NamesOf, report: Reporter
) -> _Robot | None:
    """One robot's mappings, resolved; None when there is nothing (valid) to resolve, or when
    it is reported here (a namespace needed, a name too long) or was (the namespace)."""
    assignment = fleet.model.robots[robot_id]
    namespace = assignment.namespace
    if not _check_namespace(fleet, robot_id, report):
        return None
    found = names_of(assignment.scenario)
    if found is None:
        return None
    bindings = found.bindings
    if namespace is None:
        needing = sorted(key for key, b in bindings.items() if needs_namespace(b.name))
        if needing:
            example = bindings[needing[0]].name
            report.add(
                fleet,
                ["robots", robot_id],
                "RC504",
                f"robot '{robot_id}' has no namespace, and mapping scheme {found.scheme} names "
                f"{', '.join(needing)} in it ('{example}'): give the robot one, e.g. "
                f"`namespace: {suggest_namespace(robot_id)}`",
                key=True,
            )
            return None
    absolute = None if namespace is None else absolute_namespace(namespace)
    # Names without a namespace are the scheme's, checked with it; a namespace adds its own
    # length to every tail: only when the longest tail goes over is each name looked at.
    if absolute is not None and name_cost(absolute) + found.longest_tail > NAME_BUDGET:
        for key, binding in bindings.items():
            problem = length_problem(resolve_name(binding.name, namespace))
            if problem is not None:
                report.add(
                    fleet,
                    ["robots", robot_id, "namespace"],
                    "RC503",
                    f"in namespace '{namespace}', mapping '{key}' {problem}: "
                    "use a shorter namespace",
                )
                return None
    domain = assignment.ros_domain_id if assignment.ros_domain_id is not None else found.domain
    world = (*found.world, DEFAULT_ROS_DOMAIN if domain is None else domain)
    return _Robot(robot_id, namespace, world, domain is not None, found.scheme, absolute, found)


def _check_namespace(fleet: Entry[Fleet], robot_id: str, report: Reporter) -> bool:
    """Whether the robot's namespace is valid (or it has none); RC503 when it is not."""
    namespace = fleet.model.robots[robot_id].namespace
    if namespace is None:
        return True
    problem = namespace_problem(namespace)
    if problem is not None:
        report.add(
            fleet,
            ["robots", robot_id, "namespace"],
            "RC503",
            f"namespace '{namespace}' {problem}; a ROS 2 namespace is tokens of letters, digits "
            f"and single '_', not starting with a digit, separated by '/', e.g. "
            f"`namespace: {suggest_namespace(namespace)}`",
        )
    return problem is None


def _clash_message(
    first: _Robot, second: _Robot, shared: list[tuple[str, str, bool]], free: int
) -> str:
    """`free`: a domain no robot of their world uses, for the other fix."""
    names = ", ".join(f"{name} ({key})" for key, name, _ in shared)
    unnamed = [r.robot_id for r in (first, second) if r.namespace is None]
    examples = ", ".join(f"`namespace: {suggest_namespace(r)}`" for r in unnamed)
    if any(absolute for _, _, absolute in shared):
        # An absolute name ignores namespaces: the scheme has to change first.
        fix = (
            f"write these names relative in mapping scheme {second.scheme} (cmd_vel, not /cmd_vel)"
        )
        if unnamed:
            fix += f" and give them namespaces ({examples})"
    elif unnamed:
        fix = f"give them namespaces ({examples})"
    else:
        fix = "give them different namespaces"
    environment, platform, domain = first.world
    where = f"ROS domain {domain}"
    if not (first.domain_set and second.domain_set):
        where += " (ROS's default, where a robot without `ros_domain_id` runs)"
    return (
        f"robots '{first.robot_id}' and '{second.robot_id}' both use {names} in environment "
        f"{environment} ({platform}) on {where}: they would drive each other; {fix}, or put "
        f"them on different domains (e.g. `ros_domain_id: {free}` for '{second.robot_id}')"
    )


def _free_domain(used: set[int]) -> int:
    """The lowest domain none of `used` is, past the default (where whatever is not configured
    runs): the other fix of a clash."""
    free = (d for d in range(DEFAULT_ROS_DOMAIN + 1, MAX_ROS_DOMAIN_ID + 1) if d not in used)
    return next(free, MAX_ROS_DOMAIN_ID)


def _each_once(repo: Repository) -> NamesOf:
    known: dict[str, ScenarioNames | None] = {}

    def names_of(name: str) -> ScenarioNames | None:
        if name not in known:
            known[name] = scenario_names(repo, name)
        return known[name]

    return names_of


def check_namespaces(repo: Repository, report: Reporter, names_of: NamesOf | None = None) -> None:
    """`names_of` gives a scenario's names (`scenario_names`); by default each scenario's are
    worked out once here."""
    fleet = repo.fleet
    if fleet is None:
        return
    lookup = names_of or _each_once(repo)
    robots: list[_Robot] = []
    domains: dict[tuple[str, str], set[int]] = {}  # (environment, platform) -> domains used
    for robot_id in fleet.model.robots:
        robot = _robot_names(fleet, robot_id, lookup, report)
        if robot is None or robot.world[0] == "":
            continue  # no environment: the robot shares no world with another
        if fleet.model.robots[robot_id].suspended:
            # Left as it is: its assignment does not reach it, so uses none of these names
            # (it is checked when it is resumed).
            continue
        robots.append(robot)
        domains.setdefault(robot.world[:2], set()).add(robot.world[2])
    worlds: dict[tuple[str, str, int], list[_Robot]] = {}
    for robot in robots:
        worlds.setdefault(robot.world, []).append(robot)
    apart = {world: _apart(members) for world, members in worlds.items()}
    # (environment, platform, domain, kind, name) -> the first robot using it
    seen: dict[tuple[str, str, int, str, str], _Robot] = {}
    for robot in robots:
        clashes: dict[str, tuple[_Robot, list[tuple[str, str, bool]]]] = {}
        for key, kind, name, absolute in robot.names(not apart[robot.world]):
            first = seen.setdefault((*robot.world, kind, name), robot)
            if first is not robot:
                clashes.setdefault(first.robot_id, (first, []))[1].append((key, name, absolute))
        free = _free_domain(domains[robot.world[:2]])
        for first, shared in clashes.values():
            report.add(
                fleet,
                ["robots", robot.robot_id],
                "RC505",
                _clash_message(first, robot, shared, free),
                key=True,
            )


def _apart(robots: list[_Robot]) -> bool:
    """Whether no name under one robot's namespace can be another robot's name: no two robots
    of the world share a namespace or nest one in another's, and no name outside the
    namespaces (absolute, or a robot's without one) is under one. Then only the names outside
    can clash, and only they are compared (10,000 robots' names are not all worked out)."""
    spaces: set[str] = set()
    for robot in robots:
        if robot.absolute is not None:
            if robot.absolute in spaces:
                return False
            spaces.add(robot.absolute)
    outside = (name for robot in robots for _, _, name, _ in robot.names(False))
    spaced = (robot.absolute for robot in robots if robot.absolute is not None)
    for name in itertools.chain(spaced, outside):
        # Every '/' past the first ends a namespace the name would be under.
        at = name.find("/", 1)
        while at != -1:
            if name[:at] in spaces:
                return False
            at = name.find("/", at + 1)
    return True
