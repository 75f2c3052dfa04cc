"""Whole-repository validation: every cross-file rule, as units of one rule on one subject.

A unit looks its subject up by name in the repository it is given, so whatever it reads goes
through the repository: the incremental build (configurator/incremental.py) records it, and
runs a unit again only when something it read has changed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from robotconf.configurator.repository import Repository
from robotconf.configurator.resolve import ResolvedCapability, resolve_capability
from robotconf.configurator.rules.catalogue import (
    check_action,
    check_environment,
    check_scheme,
    check_task,
    check_template,
)
from robotconf.configurator.rules.configs import check_capability, check_fleet, check_scenario
from robotconf.configurator.rules.namespaces import ScenarioNames, check_namespaces, scenario_names
from robotconf.configurator.rules.report import Reporter
from robotconf.configurator.rules.rollout import (
    check_groups,
    check_labels,
    check_rollout,
    check_stages,
)
from robotconf.contract.diagnostics import Diagnostic

# Values worked out from the repository once per name and argument (a scenario's ROS names),
# shared by the units that need them: memoised in one build, and across builds by the
# incremental build, which works one out again only when something it read has changed.
DERIVED: dict[str, Callable[[Repository, str], Any]] = {"scenario-names": scenario_names}

Derive = Callable[[str, str], Any]  # (name in DERIVED, argument) -> the value
Run = Callable[[Repository, Reporter, Derive], None]


@dataclass(frozen=True)
class Unit:
    """One rule on one subject: `key` names it (("capability", name)...), `run` checks it."""

    key: tuple[str, ...]
    run: Run


def rule_units(repo: Repository) -> list[Unit]:
    """Every unit the repository's files call for."""
    units: list[Unit] = []
    for platform_name, platform in repo.platforms.items():
        for name in platform.templates:
            units.append(
                Unit(("robot-template", platform_name, name), _template(platform_name, name))
            )
        for name in platform.schemes:
            units.append(
                Unit(("mapping-scheme", platform_name, name), _scheme(platform_name, name))
            )
    units += [Unit(("action", name), _action(name)) for name in repo.actions]
    units += [Unit(("task", name), _task(name)) for name in repo.tasks]
    units += [Unit(("environment", name), _environment(name)) for name in repo.environments]
    units += [Unit(("capability", name), _capability(name)) for name in repo.capabilities]
    units += [Unit(("scenario", name), _scenario(name)) for name in repo.scenarios]
    units.append(Unit(("fleet",), _fleet))
    units.append(Unit(("namespaces",), _namespaces))
    return units


def check_repository(repo: Repository) -> list[Diagnostic]:
    """Every cross-file rule over a loaded repository (the loader reports per-file problems)."""
    report = Reporter()
    derived: dict[tuple[str, str], Any] = {}

    def derive(name: str, argument: str) -> Any:
        key = (name, argument)
        if key not in derived:
            derived[key] = DERIVED[name](repo, argument)
        return derived[key]

    for unit in rule_units(repo):
        unit.run(repo, report, derive)
    return report.found


def _template(platform: str, name: str) -> Run:
    def run(repo: Repository, report: Reporter, derive: Derive) -> None:
        check_template(repo.platforms[platform].templates[name], report)

    return run


def _scheme(platform: str, name: str) -> Run:
    def run(repo: Repository, report: Reporter, derive: Derive) -> None:
        found = repo.platforms[platform]
        check_scheme(found, found.schemes[name], report)

    return run


def _action(name: str) -> Run:
    def run(repo: Repository, report: Reporter, derive: Derive) -> None:
        check_action(repo, name, repo.actions[name], report)

    return run


def _task(name: str) -> Run:
    def run(repo: Repository, report: Reporter, derive: Derive) -> None:
        check_task(repo, repo.tasks[name], report)

    return run


def _environment(name: str) -> Run:
    def run(repo: Repository, report: Reporter, derive: Derive) -> None:
        check_environment(repo.environments[name], report)

    return run


def _capability(name: str) -> Run:
    def run(repo: Repository, report: Reporter, derive: Derive) -> None:
        check_capability(repo, repo.capabilities[name], report)

    return run


def _scenario(name: str) -> Run:
    def run(repo: Repository, report: Reporter, derive: Derive) -> None:
        entry = repo.scenarios[name]
        wanted = entry.model.capability
        capability = repo.capabilities.get(wanted)
        resolved: dict[str, ResolvedCapability] = {}
        if capability is not None:
            resolved[wanted] = resolve_capability(repo, capability.model)
        check_scenario(repo, entry, resolved, report)

    return run


def _fleet(repo: Repository, report: Reporter, derive: Derive) -> None:
    fleet = repo.fleet
    if fleet is None:
        return
    check_fleet(repo, report)
    check_labels(fleet, report)
    check_rollout(fleet, report)
    check_stages(repo, fleet, report)
    check_groups(repo, fleet, report)


def _namespaces(repo: Repository, report: Reporter, derive: Derive) -> None:
    def names_of(scenario: str) -> ScenarioNames | None:
        found: ScenarioNames | None = derive("scenario-names", scenario)
        return found

    check_namespaces(repo, report, names_of)
