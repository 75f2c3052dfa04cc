"""The scenario schema checks setting values for the capability a scenario names: types, ranges,
choices and unknown names, as validate does (here through the jsonschema library)."""

from __future__ import annotations

from typing import Any

import jsonschema
import pytest

from robotconf.configurator.schemas import generate
from tests.support.lab import Lab


def scenario_schema(lab: Lab) -> dict[str, Any]:
    checked = lab.check()
    assert checked.ok, checked.errors
    return generate(checked.repo)["scenario.schema.json"]


def problems(schema: dict[str, Any], scenario: dict[str, Any]) -> list[str]:
    validator = jsonschema.Draft202012Validator(schema)
    return sorted(e.message for e in validator.iter_errors(scenario))


BASE = {"capability": "turtlebot3-camera", "environment": "GazeboDemo1"}


def test_settings_within_bounds_pass(lab: Lab) -> None:
    schema = scenario_schema(lab)
    good = {
        **BASE,
        "robot_settings": {"max_linear_speed": 0.2},
        "logic_settings": {"follow_with_poses": {"move_speed": 0.1}},
    }
    assert problems(schema, good) == []


@pytest.mark.parametrize(
    ("settings", "words"),
    [
        ({"robot_settings": {"max_linear_speed": 99}}, "99 is greater than the maximum"),
        ({"robot_settings": {"max_linear_speed": "fast"}}, "'fast' is not of type 'number'"),
        ({"robot_settings": {"top_speed": 0.1}}, "'top_speed' was unexpected"),
        ({"logic_settings": {"follow_with_poses": {"speed": 0.1}}}, "'speed' was unexpected"),
        # A logic the capability did not choose has no settings here.
        (
            {"logic_settings": {"follow_with_bluetooth": {}}},
            "'follow_with_bluetooth' was unexpected",
        ),
    ],
)
def test_wrong_values_and_unknown_names_are_flagged(
    lab: Lab, settings: dict[str, Any], words: str
) -> None:
    found = problems(scenario_schema(lab), {**BASE, **settings})
    assert any(words in message for message in found), found


def test_a_wrong_enum_choice_is_flagged_and_hover_text_has_unit_range_and_default(
    lab: Lab,
) -> None:
    lab.replace(
        "models/platforms/ROS2/robot-templates/turtlebot3-waffle-pi.yaml",
        "settings:\n",
        "settings:\n  drive_mode: {type: enum, default: eco, choices: [eco, sport]}\n",
    )
    schema = scenario_schema(lab)
    found = problems(schema, {**BASE, "robot_settings": {"drive_mode": "turbo"}})
    assert any("'turbo' is not one of ['eco', 'sport']" in m for m in found), found
    speed = schema["$defs"]["robot-settings.ROS2.turtlebot3-waffle-pi"]["properties"][
        "max_linear_speed"
    ]
    assert "m/s" in speed["description"] and "default 0.22" in speed["description"]
    # An editor's hover (tests/integration/core/test_editor_schemas.py) shows these two.
    assert speed["title"] == "max_linear_speed (m/s)"
    assert "- range: `0 to 0.26`\n- default: `0.22`" in speed["markdownDescription"]
    drive = schema["$defs"]["robot-settings.ROS2.turtlebot3-waffle-pi"]["properties"]["drive_mode"]
    assert '- choices: `"eco", "sport"`' in drive["markdownDescription"]
    assert speed["maximum"] == 0.26


def test_robot_settings_need_a_template(lab: Lab) -> None:
    schema = scenario_schema(lab)
    rules = [rule for rule in schema["allOf"] if "if" in rule]  # one per capability
    capability = next(rule for rule in rules if "robot_settings" in rule["then"]["properties"])
    assert capability["if"]["required"] == ["capability"]
    no_template = [
        rule
        for rule in rules
        if rule["then"]["properties"]["robot_settings"] == {"type": "object", "maxProperties": 0}
    ]
    for rule in no_template:
        name = rule["if"]["properties"]["capability"]["const"]
        assert problems(schema, {"capability": name, "robot_settings": {"x": 1}})
