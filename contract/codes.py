"""Every diagnostic code, declared once: its severity and the rule it stands for.

Diagnostics refuse a code that is not declared here, and the docs' table of rule codes
(docs/reference/rules.md) is generated from it: `python -m robotconf.contract.codes FILE`
rewrites the table in any file, found by its head row (`python -m robotconf.workstation.docs`
writes every page).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

from robotconf.contract.errors import ExitCode


class Severity(str, Enum):
    ERROR = "error"
    WARNING = "warning"


# Why a lab cannot tune a rule (configurator/ruleconfig.py): each group's reason, in the docs'
# table. A rule without one may be set to error, warning or off in `.robotconf.yaml` and
# silenced in place by `# robotconf: ignore CODE`.
UNREAD = "the file is not read: nothing in it is checked"
SCHEMA = "a value of the wrong type or place would reach the robot, or be dropped"
NO_FLEET = "without a fleet no robot gets a request"
REFERENCE = "a name that resolves to nothing: nothing to render"
COMPOSITION = "logics would run without the mappings or actions they need"
GOAL = "the robot would get a goal it cannot carry out, or a wrong place"
SETTING = "the value reaches the robot: types and ranges are its limits (speeds)"
ROS_NAME = "ids, labels and names become MQTT topic levels and ROS names"
ROLLOUT = "the rollout could not run, or a robot would never get a commit"
CONFIGURATION = "a typo must not silently keep or drop a rule"
TUNABLE = ""


@dataclass(frozen=True)
class Rule:
    code: str
    severity: Severity
    summary: str  # the docs' row for the code: what it refuses, in a line
    fixed: str  # why a lab cannot tune it; TUNABLE (empty) when it can

    @property
    def tunable(self) -> bool:
        return not self.fixed


RULES: dict[str, Rule] = {
    rule.code: rule
    for rule in (
        Rule("RC001", Severity.ERROR, "file is not valid UTF-8", UNREAD),
        Rule("RC002", Severity.ERROR, "tab in indentation", UNREAD),
        Rule(
            "RC003",
            Severity.ERROR,
            "YAML syntax error; also a line break only YAML sees (lone CR, NEL, U+2028, U+2029), "
            "refused so that every reported line is the line editors and git show",
            UNREAD,
        ),
        Rule("RC004", Severity.ERROR, "duplicate key", UNREAD),
        Rule(
            "RC005",
            Severity.ERROR,
            "YAML alias (`*name`, `<<: *name`): refused, so an alias bomb fails at once in bounded "
            "memory",
            UNREAD,
        ),
        Rule("RC006", Severity.ERROR, "more than one YAML document in a file", UNREAD),
        Rule("RC007", Severity.ERROR, "empty file, or the top level is not a mapping", UNREAD),
        Rule(
            "RC008",
            Severity.ERROR,
            "not read: larger than 8 MiB (checked before reading), unreadable, or not a regular "
            "file — a symbolic link, FIFO, device, socket or git submodule is refused and never "
            "opened, in the work tree and in a commit alike",
            UNREAD,
        ),
        Rule(
            "RC009",
            Severity.ERROR,
            "unsupported YAML value: tags (a standard tag only when its value fits it: `!!float "
            "abc` is refused), keys that are not text (`1:`, `yes:`, `~:` — quote them), integers "
            "beyond 64 bits, NaN/infinity, nesting deeper than 64 (block or flow; checked before "
            "parsing)",
            UNREAD,
        ),
        Rule(
            "RC101",
            Severity.ERROR,
            'unknown field (with the allowed fields, or "did you mean")',
            SCHEMA,
        ),
        Rule("RC102", Severity.ERROR, "missing required field", SCHEMA),
        Rule("RC103", Severity.ERROR, "wrong type or value for a field", SCHEMA),
        Rule("RC104", Severity.ERROR, "`name:` differs from the file name", SCHEMA),
        Rule(
            "RC105",
            Severity.ERROR,
            "YAML file in an unknown place, or ending in `.yml`, `.YAML` or any spelling but "
            "`.yaml` (not read)",
            SCHEMA,
        ),
        Rule(
            "RC106",
            Severity.ERROR,
            "`configs/fleet.yaml` is missing (the reconciler would refuse the commit too)",
            NO_FLEET,
        ),
        Rule("RC201", Severity.ERROR, "capability: unknown platform", REFERENCE),
        Rule(
            "RC202",
            Severity.ERROR,
            "capability: the platform has no such mapping scheme",
            REFERENCE,
        ),
        Rule(
            "RC203",
            Severity.ERROR,
            "capability: the platform has no such robot template",
            REFERENCE,
        ),
        Rule(
            "RC204",
            Severity.ERROR,
            "capability: unknown action, or an action not available on the platform",
            REFERENCE,
        ),
        Rule(
            "RC205",
            Severity.ERROR,
            "capability: the action has no such logic (each unknown logic of an action's list, "
            "at its item)",
            REFERENCE,
        ),
        Rule("RC206", Severity.ERROR, "scenario: unknown capability configuration", REFERENCE),
        Rule("RC207", Severity.ERROR, "scenario: unknown environment", REFERENCE),
        Rule(
            "RC208",
            Severity.ERROR,
            "scenario: the environment has no such knowledge set (or there is no environment)",
            REFERENCE,
        ),
        Rule("RC209", Severity.ERROR, "fleet: unknown scenario", REFERENCE),
        Rule("RC210", Severity.ERROR, "scenario: a goal names an unknown task", REFERENCE),
        Rule(
            "RC301",
            Severity.ERROR,
            "a selected logic needs a mapping the robot template lacks (lists each missing mapping "
            "and the logics needing it)",
            COMPOSITION,
        ),
        Rule(
            "RC302",
            Severity.ERROR,
            "a selected logic needs a mapping the mapping scheme does not bind",
            COMPOSITION,
        ),
        Rule(
            "RC303",
            Severity.ERROR,
            "a selected action requires an action that is not selected",
            COMPOSITION,
        ),
        Rule(
            "RC304",
            Severity.ERROR,
            "a goal's task is not achievable: no implementation is a subset of the selected "
            "actions",
            GOAL,
        ),
        Rule(
            "RC305",
            Severity.ERROR,
            "a goal's location is not a `Location` object of the environment",
            GOAL,
        ),
        Rule(
            "RC306",
            Severity.ERROR,
            "a goal has a location but the scenario has no environment",
            GOAL,
        ),
        Rule("RC401", Severity.ERROR, "unknown robot or logic setting", SETTING),
        Rule("RC402", Severity.ERROR, "setting value of the wrong type", SETTING),
        Rule("RC403", Severity.ERROR, "setting value out of range", SETTING),
        Rule("RC404", Severity.ERROR, "setting value not one of the choices", SETTING),
        Rule("RC405", Severity.ERROR, "robot settings without a robot template", SETTING),
        Rule(
            "RC406",
            Severity.ERROR,
            "logic settings for a logic the capability does not select",
            SETTING,
        ),
        Rule(
            "RC501",
            Severity.ERROR,
            "robot id not usable as an MQTT topic level (matched in full: a trailing newline is not"
            " an id), or reserved: a service user name (`reconciler`, `viewer`, `operator`, in any"
            " case)",
            ROS_NAME,
        ),
        Rule(
            "RC502",
            Severity.ERROR,
            "fleet: a label key or value not written like a robot id (letters, digits, `_`, `.`, "
            "`-`; 1-64, starting with a letter or digit)",
            ROS_NAME,
        ),
        Rule(
            "RC503",
            Severity.ERROR,
            "fleet: a robot's `namespace` is not a ROS 2 namespace (tokens of letters, digits and "
            "single `_`, not starting with a digit, separated by `/`; `tb3-01` -> `tb3_01`), or "
            "makes a mapping name too long for DDS",
            ROS_NAME,
        ),
        Rule(
            "RC504",
            Severity.ERROR,
            "fleet: a robot without `namespace` runs a mapping scheme whose names start with "
            "`{namespace}`",
            ROS_NAME,
        ),
        Rule(
            "RC505",
            Severity.ERROR,
            "fleet: two robots in one environment (one world), on one platform and one ROS "
            "domain, bind a topic or action mapping to the same fully qualified name: they would "
            "drive each other (give them namespaces and the scheme relative names, or different "
            "domains: `ros_domain_id`); a robot whose `ros_domain_id` is unset, and its "
            "environment's too, is on ROS's default domain 0; suspended robots are left out",
            TUNABLE,
        ),
        Rule(
            "RC601", Severity.ERROR, "a setting's default does not fit its own definition", SETTING
        ),
        Rule(
            "RC602",
            Severity.ERROR,
            "a setting definition contradicts itself (minimum > maximum, enum without choices, "
            "bounds on text)",
            SETTING,
        ),
        Rule("RC603", Severity.ERROR, "a task implementation names an unknown action", REFERENCE),
        Rule("RC604", Severity.ERROR, "an action requires an unknown action, or itself", REFERENCE),
        Rule("RC605", Severity.ERROR, "an action lists an unknown platform", TUNABLE),
        Rule("RC606", Severity.ERROR, "an object id is used twice in an environment", GOAL),
        Rule("RC607", Severity.ERROR, "a robot template lists a mapping twice", TUNABLE),
        Rule(
            "RC608",
            Severity.WARNING,
            "a mapping scheme does not bind a mapping of a robot template of its platform",
            TUNABLE,
        ),
        Rule(
            "RC609",
            Severity.ERROR,
            "a mapping scheme's name is not a ROS 2 topic, service or action name: absolute "
            "(`/cmd_vel`), relative (`cmd_vel`) or `{namespace}/...`; no `~`, other "
            "substitutions, `//`, trailing `/` or `_`, `__`, or token starting with a digit",
            ROS_NAME,
        ),
        Rule(
            "RC701",
            Severity.ERROR,
            "rollout: a wave name not written like a robot id, or used twice",
            ROLLOUT,
        ),
        Rule(
            "RC702",
            Severity.ERROR,
            "rollout: a number out of range: `percent` 1-100, `healthy_after` >= 0, "
            "`wave_timeout` > 0, `max_failures` a count >= 0 or a share `0%`-`100%`",
            ROLLOUT,
        ),
        Rule(
            "RC703",
            Severity.ERROR,
            "rollout: a wave's selector names a label key no robot has (did you mean)",
            TUNABLE,
        ),
        Rule(
            "RC704",
            Severity.ERROR,
            "rollout: a wave's selector asks for a label value no robot has (did you mean)",
            TUNABLE,
        ),
        Rule(
            "RC705",
            Severity.ERROR,
            "rollout: a robot falls in no wave, so no commit would reach it (end with a wave "
            "without selector, e.g. `{name: all}`)",
            ROLLOUT,
        ),
        Rule(
            "RC706",
            Severity.WARNING,
            "rollout: a wave takes no robot (earlier waves take all it selects)",
            TUNABLE,
        ),
        Rule(
            "RC707",
            Severity.ERROR,
            "stages: a stage without environments or selector (or with both), a bad selector, "
            "an environment no scenario names, a name used twice, or stages without a rollout",
            ROLLOUT,
        ),
        Rule(
            "RC708",
            Severity.ERROR,
            "stages: a robot falls in no stage, so no revision would be promoted to it",
            ROLLOUT,
        ),
        Rule(
            "RC709",
            Severity.ERROR,
            "groups: a name not written like a robot id, a robot that is not assigned (did you "
            "mean), a bad selector, a robot in two groups, or a group across stages",
            ROLLOUT,
        ),
        Rule(
            "RC801",
            Severity.ERROR,
            "`.robotconf.yaml`: an unknown rule code (did you mean), a severity other than "
            "`error`, `warning` or `off`, or a rule that cannot be tuned",
            CONFIGURATION,
        ),
        Rule(
            "RC802",
            Severity.WARNING,
            "`# robotconf: ignore` names an unknown code, or a rule that cannot be tuned (it "
            "silences nothing)",
            TUNABLE,
        ),
        Rule(
            "RC803",
            Severity.WARNING,
            "`# robotconf: ignore CODE` silences nothing: no finding of CODE on its line",
            TUNABLE,
        ),
    )
}


class UnregisteredCode(ValueError):
    """A diagnostic with a code that is not in RULES, or with another severity than its rule's."""


def severity_of(code: str) -> Severity:
    """The severity RULES declares for a code; an undeclared code is refused."""
    rule = RULES.get(code)
    if rule is None:
        raise UnregisteredCode(f"{code!r} is not declared in contract/codes.py")
    return rule.severity


def require(code: str, severity: Severity = Severity.ERROR) -> None:
    """Refuse a code RULES does not declare with this severity: a new rule is declared first.
    A rule a lab can tune may also come at the severity its `.robotconf.yaml` sets."""
    declared = severity_of(code)
    if declared is not severity and not RULES[code].tunable:
        raise UnregisteredCode(f"{code} is declared as {declared.value}, not {severity.value}")


TABLE_HEAD = "| code | rule | tunable |\n| --- | --- | --- |\n"


def _row(rule: Rule) -> str:
    warning = "warning: " if rule.severity is Severity.WARNING else ""
    tunable = "yes" if rule.tunable else f"no: {rule.fixed}"
    return f"| {rule.code} | {warning}{rule.summary} | {tunable} |\n"


def readme_table() -> str:
    """The table of rule codes (docs/reference/rules.md), a row per declared code; a warning
    says so, and a rule a lab cannot tune says why."""
    return TABLE_HEAD + "".join(_row(r) for r in RULES.values())


def with_readme_table(readme: str) -> str:
    """The text with its table of rule codes (head and following rows) generated anew."""
    if TABLE_HEAD not in readme:
        head = " ".join(TABLE_HEAD.splitlines())
        raise ValueError(f"no table of rule codes: its head rows `{head}` are missing")
    start = readme.index(TABLE_HEAD)
    end = start + len(TABLE_HEAD)
    while readme.startswith("| RC", end):
        end = readme.index("\n", end) + 1
    return readme[:start] + readme_table() + readme[end:]


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print(
            "usage: python -m robotconf.contract.codes FILE (e.g. docs/reference/rules.md)",
            file=sys.stderr,
        )
        return ExitCode.TOOL
    path = Path(argv[0])
    try:
        path.write_text(with_readme_table(path.read_text(encoding="utf-8")), encoding="utf-8")
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        print(f"python -m robotconf.contract.codes: {path}: {exc}", file=sys.stderr)
        return ExitCode.TOOL
    return ExitCode.OK


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
