"""Whole-repository validation: every rule, with its code, and one entry point."""

from __future__ import annotations

from configurator.diagnostics import Diagnostic
from configurator.repository import Repository
from configurator.resolve import ResolvedCapability
from configurator.rules.catalogue import check_catalogue
from configurator.rules.configs import check_capability, check_fleet, check_scenario
from configurator.rules.report import Reporter

RULES: dict[str, str] = {
    "RC001": "file is not valid UTF-8",
    "RC002": "tab in indentation",
    "RC003": "YAML syntax error",
    "RC004": "duplicate key",
    "RC005": "YAML anchor or alias (refused: alias bombs)",
    "RC006": "more than one YAML document in a file",
    "RC007": "empty file, or the top level is not a mapping",
    "RC008": "file too large or unreadable",
    "RC009": "unsupported YAML value (tag, non-text key, NaN/infinity, deep nesting)",
    "RC101": "unknown field",
    "RC102": "missing required field",
    "RC103": "wrong type or value for a field",
    "RC104": "`name:` differs from the file name",
    "RC105": "YAML file in an unknown place, or ending in .yml",
    "RC201": "capability: unknown platform",
    "RC202": "capability: the platform has no such mapping scheme",
    "RC203": "capability: the platform has no such robot template",
    "RC204": "capability: unknown action, or action not available on the platform",
    "RC205": "capability: the action has no such logic",
    "RC206": "scenario: unknown capability configuration",
    "RC207": "scenario: unknown environment",
    "RC208": "scenario: unknown knowledge set of the environment (or no environment)",
    "RC209": "fleet: unknown scenario",
    "RC210": "scenario: goal names an unknown task",
    "RC301": "a selected logic needs a mapping the robot template lacks",
    "RC302": "a selected logic needs a mapping the mapping scheme does not bind",
    "RC303": "a selected action requires an action that is not selected",
    "RC304": "a goal's task is not achievable by the selected actions",
    "RC305": "a goal's location is not a Location object of the environment",
    "RC306": "a goal has a location but the scenario has no environment",
    "RC401": "unknown robot or logic setting",
    "RC402": "setting value of the wrong type",
    "RC403": "setting value out of range",
    "RC404": "setting value not one of the choices",
    "RC405": "robot settings without a robot template",
    "RC406": "logic settings for a logic the capability does not select",
    "RC501": "robot id not usable as an MQTT topic level",
    "RC601": "setting default does not fit its own definition",
    "RC602": "setting definition contradicts itself (bounds, choices)",
    "RC603": "task implementation names an unknown action",
    "RC604": "action requires an unknown action, or itself",
    "RC605": "action lists an unknown platform",
    "RC606": "object id used twice in an environment",
    "RC607": "robot template lists a mapping twice",
    "RC608": "(warning) mapping scheme does not bind a mapping of a template of its platform",
}


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
    return report.found
