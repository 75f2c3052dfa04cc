"""Strict means strict, everywhere (issue 10, item 6): ids in full, reserved ids, booleans that
are booleans, numbers that are numbers, choices compared by type and value."""

from __future__ import annotations

import pytest

from robotconf.contract.diagnostics import Diagnostic
from tests.support.lab import Lab

FLEET = "configs/fleet.yaml"
TEMPLATE = "models/platforms/ROS2/robot-templates/turtlebot3-waffle-pi.yaml"


def only(lab: Lab) -> Diagnostic:
    found = lab.check().diagnostics
    assert len(found) == 1, "\n".join(map(str, found))
    return found[0]


@pytest.mark.parametrize(
    "robot_id",
    ["tb3-01\\n", "tb3\\u0661", "a/b", "a+b", "a#b", "a\\x00b", "x" * 65, "-lead", ".hidden"],
)
def test_robot_ids_are_matched_in_full(lab: Lab, robot_id: str) -> None:
    lab.replace(FLEET, "tb3-01:", f'"{robot_id}":')
    d = only(lab)
    assert (d.code, d.line) == ("RC501", lab.line_of(FLEET, robot_id[:3]))
    assert "not usable as an MQTT topic level" in d.message


@pytest.mark.parametrize("robot_id", ["reconciler", "viewer", "Reconciler", "VIEWER"])
def test_service_user_names_are_reserved(lab: Lab, robot_id: str) -> None:
    lab.replace(FLEET, "tb3-01:", f"{robot_id}:")
    d = only(lab)
    assert d.code == "RC501" and "is reserved" in d.message and "choose another id" in d.message


@pytest.mark.parametrize("value", ['"yes"', '"true"', "1", "0", '"false"'])
def test_fleet_booleans_are_yaml_booleans(lab: Lab, value: str) -> None:
    lab.replace(FLEET, "tb3-01: {", f"tb3-01: {{suspended: {value}, ")
    d = only(lab)
    assert d.code == "RC103" and "must be true or false" in d.message


def test_allow_empty_is_a_boolean(lab: Lab) -> None:
    lab.write(FLEET, lab.read(FLEET) + 'allow_empty: "true"\n')
    d = only(lab)
    assert (d.code, d.line) == ("RC103", lab.line_of(FLEET, "allow_empty"))


@pytest.mark.parametrize(
    ("field", "value"),
    [("minimum", "true"), ("maximum", "false"), ("minimum", '"0"'), ("maximum", "[1]")],
)
def test_bounds_are_numbers(lab: Lab, field: str, value: str) -> None:
    text = lab.read(TEMPLATE)
    lab.write(
        TEMPLATE,
        text.rstrip("\n") + f"\n  strict_probe: {{type: number, default: 0.1, {field}: {value}}}\n",
    )
    d = only(lab)
    assert d.code == "RC103" and d.path == TEMPLATE
    assert d.line == lab.line_of(TEMPLATE, "strict_probe")


def _setting(lab: Lab, definition: str, value: str) -> Diagnostic:
    text = lab.read(TEMPLATE)
    lab.write(TEMPLATE, text.rstrip("\n") + f"\n  strict_probe: {definition}\n")
    scenario = "configs/scenarios/delivery-gazebo.yaml"
    lab.replace(scenario, "robot_settings: {", f"robot_settings: {{strict_probe: {value}, ")
    return only(lab)


@pytest.mark.parametrize(
    ("definition", "value", "code"),
    [
        ("{type: boolean, default: false}", '"yes"', "RC402"),
        ("{type: boolean, default: false}", "1", "RC402"),
        ("{type: integer, default: 1}", "1.0", "RC402"),
        ("{type: integer, default: 1}", "true", "RC402"),
        ("{type: number, default: 1}", "true", "RC402"),
        ("{type: number, default: 1}", '"0.2"', "RC402"),
        ("{type: enum, default: 1, choices: [1, 2]}", "true", "RC404"),
        ("{type: enum, default: 1, choices: [1, 2]}", "1.0", "RC404"),
        ("{type: enum, default: '1', choices: ['1', '2']}", "1", "RC404"),
        ("{type: enum, default: true, choices: [true]}", "1", "RC404"),
    ],
)
def test_setting_values_have_their_type(lab: Lab, definition: str, value: str, code: str) -> None:
    d = _setting(lab, definition, value)
    assert d.code == code, d


def test_a_default_is_a_choice_by_type_too(lab: Lab) -> None:
    text = lab.read(TEMPLATE)
    lab.write(
        TEMPLATE,
        text.rstrip("\n") + "\n  strict_probe: {type: enum, default: true, choices: [1, 2]}\n",
    )
    d = only(lab)
    assert d.code == "RC601"
