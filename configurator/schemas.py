"""JSON Schemas for editors and external tools, generated from the types and the catalogue.

The configuration schemas list exactly the platforms, schemes, templates, actions, logics,
scenarios and environments that exist, so an editor completes only what would validate.
"""

from __future__ import annotations

import copy
import json
from typing import Any

from pydantic import BaseModel

from robotconf.configurator.loader import KIND_BY_NAME
from robotconf.configurator.repository import Repository
from robotconf.configurator.resolve import resolve_capability
from robotconf.configurator.types import ROBOT_ID_PATTERN, RuleConfiguration, SettingDefinition
from robotconf.contract.codes import RULES
from robotconf.contract.launch import LaunchRequest

# "0%" to "100%": the plain spellings of what configurator.waves.failure_budget reads
SHARE_PATTERN = r"^(100|[1-9]?[0-9])%$"
SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"

# kind -> where its files live, relative to the repository root (for modelines)
DEPTH = {
    "fleet": 1,
    "capability": 2,
    "scenario": 2,
    "action": 2,
    "task": 2,
    "environment": 2,
    "platform": 3,
    "robot-template": 4,
    "mapping-scheme": 4,
}


def schema_file(kind: str) -> str:
    return f"{kind}.schema.json"


def modeline_ref(kind: str) -> str:
    """The relative `$schema=` path from a file of this kind to its schema."""
    return "../" * DEPTH[kind] + "schemas/" + schema_file(kind)


def _base(model: type[BaseModel], title: str) -> dict[str, Any]:
    schema = model.model_json_schema()
    schema["$schema"] = SCHEMA_DIALECT
    schema["title"] = title
    return schema


def _choices(values: dict[str, str]) -> list[dict[str, Any]]:
    """anyOf entries that editors show with a description beside each completion."""
    return [
        {"const": value, "description": about} if about else {"const": value}
        for value, about in sorted(values.items())
    ]


def _enum_or_nothing(values: dict[str, str], description: str) -> dict[str, Any]:
    if not values:
        return {"description": description + " (none exist yet)", "type": "string"}
    return {"description": description, "anyOf": _choices(values)}


def _logic_choice(about: str, logics: dict[str, str]) -> dict[str, Any]:
    """One logic, or a list of distinct ones (the action is lit when any of them is)."""
    several = {
        "type": "array",
        "description": "several logics, each once",
        "items": {"enum": sorted(logics)},
        "minItems": 1,
        "uniqueItems": True,
    }
    return {"description": about, "anyOf": [*_choices(logics), several]}


def _capability_schema(repo: Repository) -> dict[str, Any]:
    schema = _base(KIND_BY_NAME["capability"].model, "Capability configuration")
    props = schema["properties"]
    platforms = {
        name: (p.info.model.description if p.info else "") for name, p in repo.platforms.items()
    }
    props["platform"] = _enum_or_nothing(platforms, "the robot's software platform")
    schemes: dict[str, str] = {}
    templates: dict[str, str] = {}
    for pname, p in sorted(repo.platforms.items()):
        for s, scheme in p.schemes.items():
            schemes.setdefault(s, f"{pname}: {scheme.model.description}".rstrip(": "))
        for t, template in p.templates.items():
            mappings = ", ".join(template.model.mappings)
            templates.setdefault(t, f"{pname}: {template.model.description} (mappings: {mappings})")
    props["mapping_scheme"] = _enum_or_nothing(schemes, "how mappings are bound on the platform")
    template_choice = _enum_or_nothing(templates, "the robot model this configuration must fit")
    props["robot_template"] = {"anyOf": [template_choice, {"type": "null"}], "default": None}
    action_props: dict[str, Any] = {}
    for name, entry in sorted(repo.actions.items()):
        action = entry.model
        logics = {
            lname: (
                f"{logic.description + ' ' if logic.description else ''}"
                f"(needs mappings: {', '.join(logic.mappings) or 'none'})"
            )
            for lname, logic in action.logics.items()
        }
        about = f"{action.description} [platforms: {', '.join(action.platforms)}]"
        if action.requires:
            about += f" [requires: {', '.join(action.requires)}]"
        action_props[name] = _logic_choice(about.strip(), logics)
    props["actions"] = {
        "description": "action -> chosen logic, or a list of several logics",
        "type": "object",
        "properties": action_props,
        "additionalProperties": False,
    }
    # Narrow scheme and template to the chosen platform.
    rules = []
    for pname, p in sorted(repo.platforms.items()):
        then: dict[str, Any] = {}
        if p.schemes:
            then["mapping_scheme"] = {"enum": sorted(p.schemes)}
        if p.templates:
            then["robot_template"] = {"anyOf": [{"enum": sorted(p.templates)}, {"type": "null"}]}
        if then:
            rules.append(
                {
                    "if": {"properties": {"platform": {"const": pname}}, "required": ["platform"]},
                    "then": {"properties": then},
                }
            )
    if rules:
        schema["allOf"] = rules
    return schema


def _scenario_schema(repo: Repository) -> dict[str, Any]:
    schema = _base(KIND_BY_NAME["scenario"].model, "Scenario configuration")
    props = schema["properties"]
    capabilities = {
        name: f"{e.model.platform}, {e.model.robot_template or 'no template'}: "
        f"{', '.join(e.model.actions)}"
        for name, e in repo.capabilities.items()
    }
    props["capability"] = _enum_or_nothing(capabilities, "the capability configuration it runs")
    environments = {
        name: f"{e.model.type}: {e.model.description}".rstrip(": ")
        for name, e in repo.environments.items()
    }
    props["environment"] = {
        "anyOf": [_enum_or_nothing(environments, "the world it runs in"), {"type": "null"}],
        "default": None,
    }
    sets = sorted({s for e in repo.environments.values() for s in e.model.knowledge_sets})
    if sets:
        props["knowledge_sets"]["items"] = {"enum": sets}
    _settings_schemas(repo, schema)
    goal = schema["$defs"]["Goal"]["properties"]
    tasks = {name: e.model.description for name, e in repo.tasks.items()}
    goal["task"] = _enum_or_nothing(tasks, "the task to achieve")
    locations = {
        o.name: f"{env}: Location id {o.id}"
        for env, e in sorted(repo.environments.items())
        for o in e.model.objects
        if o.type == "Location"
    }
    if locations:
        goal["location"] = {
            "anyOf": [
                {
                    "description": "a Location object of the environment",
                    "anyOf": _choices(locations),
                },
                {"type": "string", "description": "or a Location object's id"},
                {"type": "null"},
            ],
            "default": None,
        }
    return schema


def _settings_schemas(repo: Repository, schema: dict[str, Any]) -> None:
    """A scenario's robot_settings and logic_settings: the names that exist anywhere, and per
    capability which it takes, with their types, bounds and hover texts."""
    props = schema["properties"]
    robot_settings = sorted(
        {s for p in repo.platforms.values() for t in p.templates.values() for s in t.model.settings}
    )
    if robot_settings:
        props["robot_settings"]["propertyNames"] = {"enum": robot_settings}
    logics_with_settings = sorted(
        {
            lname
            for a in repo.actions.values()
            for lname, logic in a.model.logics.items()
            if logic.settings
        }
    )
    if logics_with_settings:
        props["logic_settings"]["propertyNames"] = {"enum": logics_with_settings}
    scalars = _any_scalar(props["robot_settings"].pop("additionalProperties"))
    props["logic_settings"].pop("additionalProperties")
    _settings_per_capability(repo, schema)
    # Whatever the capability, values are scalars: checked after the capability's rules, so
    # that yaml-language-server's hover, which shows the first title and description it meets,
    # shows the setting's own (it checks properties before allOf: in `properties` these would
    # come first, under the title "Robot Settings").
    schema.setdefault("allOf", []).append(
        {
            "properties": {
                "robot_settings": {"additionalProperties": scalars},
                "logic_settings": {
                    "additionalProperties": {"type": "object", "additionalProperties": scalars}
                },
            }
        }
    )


def _any_scalar(schema: dict[str, Any]) -> dict[str, Any]:
    """`{"anyOf": [{"type": T1}, {"type": T2}, …]}` as `{"type": [T1, T2, …]}`: the hover of
    yaml-language-server shows an anyOf whose branches all match as their titles joined (as
    "Robot Settings || Robot Settings || …")."""
    branches = schema.get("anyOf")
    if not branches or set(schema) != {"anyOf"} or any(set(b) != {"type"} for b in branches):
        raise ValueError(f"not an anyOf of plain types: {schema}")  # the types changed
    return {"type": [branch["type"] for branch in branches]}


_JSON_TYPE = {"number": "number", "integer": "integer", "boolean": "boolean", "string": "string"}


def _facts(definition: SettingDefinition) -> list[tuple[str, str]]:
    """(what, value) of a setting beside its description: unit, range, choices, default."""
    facts: list[tuple[str, str]] = []
    if definition.unit:
        facts.append(("unit", definition.unit))
    if definition.minimum is not None or definition.maximum is not None:
        low = "-inf" if definition.minimum is None else f"{definition.minimum:g}"
        high = "inf" if definition.maximum is None else f"{definition.maximum:g}"
        facts.append(("range", f"{low} to {high}"))
    if definition.type == "enum":
        facts.append(("choices", ", ".join(json.dumps(c) for c in definition.choices or [])))
    facts.append(("default", json.dumps(definition.default)))
    return facts


def setting_schema(
    definition: SettingDefinition, name: str = "", owner: str = ""
) -> dict[str, Any]:
    """One setting as JSON Schema: type, range or choices, default; and for an editor's hover
    its own title and description (unit, range, choices, default), so that the hover names the
    setting rather than the object it sits in. `owner` says whose setting it is."""
    found: dict[str, Any] = {"default": definition.default}
    if definition.type == "enum":
        found["enum"] = list(definition.choices or [])
    else:
        found["type"] = _JSON_TYPE[definition.type]
    if definition.minimum is not None:
        found["minimum"] = definition.minimum
    if definition.maximum is not None:
        found["maximum"] = definition.maximum
    facts = _facts(definition)
    about = (definition.description or "").strip()
    words = [about.rstrip(".")] if about else []
    words += [f"in {value}" if what == "unit" else f"{what} {value}" for what, value in facts]
    found["description"] = "; ".join(words)
    if name:
        found["title"] = f"{name} ({definition.unit})" if definition.unit else name
    lines = [about, ""] if about else []
    lines += [f"- {what}: `{value}`" for what, value in facts]
    if owner:
        lines += ["", owner]
    found["markdownDescription"] = "\n".join(lines)
    return found


def _settings_object(
    definitions: dict[str, SettingDefinition], owner: str, title: str = ""
) -> dict[str, Any]:
    found: dict[str, Any] = {"title": title} if title else {}
    return found | {
        "type": "object",
        "properties": {
            name: setting_schema(d, name, owner) for name, d in sorted(definitions.items())
        },
        "additionalProperties": False,
    }


def _ref(key: str) -> str:
    """A $ref to $defs/key, escaped as a JSON pointer (names come from file names)."""
    return "#/$defs/" + key.replace("~", "~0").replace("/", "~1")


def _settings_per_capability(repo: Repository, schema: dict[str, Any]) -> None:
    """Which settings a scenario may set, with their types and bounds, follow from the
    capability it names: `if capability is C then ...` per capability. The settings of each
    robot template and each logic are written once, in $defs, and referred to."""
    defs = schema.setdefault("$defs", {})
    rules: list[dict[str, Any]] = []
    for name, entry in sorted(repo.capabilities.items()):
        resolved = resolve_capability(repo, entry.model)
        robot: dict[str, Any] = {"type": "object", "maxProperties": 0}
        if resolved.template is not None and entry.model.robot_template is not None:
            key = f"robot-settings.{entry.model.platform}.{entry.model.robot_template}"
            owner = f"A robot setting of {entry.model.robot_template} ({entry.model.platform})."
            defs.setdefault(key, _settings_object(resolved.template.settings, owner))
            robot = {"$ref": _ref(key)}
        logics: dict[str, Any] = {}
        for selection in sorted(
            resolved.all_selections(), key=lambda s: (s.action_name, s.logic_name)
        ):
            key = f"logic-settings.{selection.action_name}.{selection.logic_name}"
            owner = f"A setting of logic {selection.logic_name} (action {selection.action_name})."
            title = f"Settings of {selection.logic_name} (action {selection.action_name})"
            defs.setdefault(key, _settings_object(selection.logic.settings, owner, title))
            logics[selection.logic_name] = {"$ref": _ref(key)}
        rules.append(
            {
                "if": {"properties": {"capability": {"const": name}}, "required": ["capability"]},
                "then": {
                    "properties": {
                        "robot_settings": robot,
                        "logic_settings": {
                            "type": "object",
                            "properties": logics,
                            "additionalProperties": False,
                        },
                    }
                },
            }
        )
    if rules:
        schema["allOf"] = rules


def _fleet_schema(repo: Repository) -> dict[str, Any]:
    schema = _base(KIND_BY_NAME["fleet"].model, "Fleet")
    scenarios = {name: f"capability {e.model.capability}" for name, e in repo.scenarios.items()}
    schema["$defs"]["RobotAssignment"]["properties"]["scenario"] = _enum_or_nothing(
        scenarios, "the scenario this robot runs"
    )
    schema["properties"]["robots"]["propertyNames"] = {"pattern": ROBOT_ID_PATTERN}
    # What validate checks alone (RC502, RC701, RC702), told to editors as well; which label
    # keys and values exist is not: the schema would go stale with every label edited.
    labels = schema["$defs"]["RobotAssignment"]["properties"]["labels"]
    labels["propertyNames"] = {"pattern": ROBOT_ID_PATTERN}
    labels["additionalProperties"] = {"type": "string", "pattern": ROBOT_ID_PATTERN}
    wave = schema["$defs"]["Wave"]["properties"]
    wave["name"]["pattern"] = ROBOT_ID_PATTERN
    wave["selector"]["propertyNames"] = {"pattern": ROBOT_ID_PATTERN}
    wave["selector"]["additionalProperties"] = {"type": "string", "pattern": ROBOT_ID_PATTERN}
    wave["percent"]["anyOf"][0].update(minimum=1, maximum=100)
    policy = schema["$defs"]["RolloutPolicy"]["properties"]
    policy["healthy_after"]["minimum"] = 0
    policy["wave_timeout"]["exclusiveMinimum"] = 0
    policy["max_failures"]["anyOf"] = [
        {"type": "integer", "minimum": 0, "description": "a count of robots"},
        {
            "type": "string",
            "pattern": SHARE_PATTERN,
            "description": "a share of the wave's robots, 0% to 100%, rounded down",
        },
    ]
    policy["on_failure"]["description"] = (
        "when a wave fails: rollback: the robots it moved get the last complete revision back; "
        "halt: the rollout stops where it is"
    )
    return schema


def _rule_configuration_schema() -> dict[str, Any]:
    """`.robotconf.yaml`: only the rules a lab may tune are offered, each with its row."""
    schema = _base(RuleConfiguration, "Rule configuration (.robotconf.yaml)")
    tunable = {code: rule.summary for code, rule in RULES.items() if rule.tunable}
    schema["properties"]["rules"] = {
        "description": "rule code -> error, warning or off (only rules a lab may tune)",
        "type": "object",
        "propertyNames": {"enum": sorted(tunable)},
        "properties": {
            code: {
                "description": summary,
                "anyOf": [{"enum": ["error", "warning", "off"]}, {"const": False}],
            }
            for code, summary in sorted(tunable.items())
        },
    }
    return schema


def generate(repo: Repository) -> dict[str, dict[str, Any]]:
    """File name -> schema, for every kind plus the Launch Request."""
    out: dict[str, dict[str, Any]] = {}
    for kind_name, kind in KIND_BY_NAME.items():
        if kind_name in ("capability", "scenario", "fleet"):
            continue
        out[schema_file(kind_name)] = _base(kind.model, kind.title.capitalize())
    out[schema_file("capability")] = _capability_schema(repo)
    out[schema_file("scenario")] = _scenario_schema(repo)
    out[schema_file("fleet")] = _fleet_schema(repo)
    out[schema_file("launch-request")] = _base(LaunchRequest, "Launch Request")
    out[schema_file("rule-configuration")] = _rule_configuration_schema()
    return {name: copy.deepcopy(schema) for name, schema in sorted(out.items())}


def dump(schema: dict[str, Any]) -> str:
    return json.dumps(schema, indent=2, sort_keys=True, ensure_ascii=False) + "\n"
