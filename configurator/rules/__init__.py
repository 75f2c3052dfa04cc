"""Whole-repository validation: every cross-file rule, from one entry point."""

from __future__ import annotations

from configurator.diagnostics import Diagnostic
from configurator.repository import Repository
from configurator.resolve import ResolvedCapability
from configurator.rules.catalogue import check_catalogue
from configurator.rules.configs import check_capability, check_fleet, check_scenario
from configurator.rules.namespaces import check_namespaces
from configurator.rules.report import Reporter
from configurator.rules.rollout import check_labels, check_rollout


def check_repository(repo: Repository) -> list[Diagnostic]:
    """Every cross-file rule over a loaded repository (the loader reports per-file problems)."""
    report = Reporter()
    check_catalogue(repo, report)
    capabilities: dict[str, ResolvedCapability] = {}
    for name, capability in repo.capabilities.items():
        capabilities[name] = check_capability(repo, capability, report)
    for scenario in repo.scenarios.values():
        check_scenario(repo, scenario, capabilities, report)
    check_fleet(repo, report)
    check_namespaces(repo, report)
    if repo.fleet is not None:
        check_labels(repo.fleet, report)
        check_rollout(repo.fleet, report)
    return report.found
