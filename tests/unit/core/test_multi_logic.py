"""An action selecting several logics (the thesis' autofill): the capability's list form is
validated per logic, resolved, rendered (a list only when several), drawn and planned; a
request with one logic per action keeps the bytes and digest it always had."""

from __future__ import annotations

from typing import Any

import jsonschema
import pytest

from robotconf.configurator.autofill import select_logics, template_fit, to_yaml
from robotconf.configurator.plan import (
    format_plan_markdown,
    format_plan_text,
    make_plan,
    plan_as_json,
)
from robotconf.configurator.render import bound_mappings, render_fleet
from robotconf.configurator.resolve import resolve_capability
from robotconf.configurator.schemas import generate
from robotconf.configurator.tree import action_label, build_tree, logic_label
from robotconf.configurator.types import Action, CapabilityConfiguration, Logic
from robotconf.configurator.workspace import check
from tests.support.lab import ROOT, Lab

EITHER = "configs/capabilities/turtlebot3-follow-either.yaml"
CAMERA = "configs/capabilities/turtlebot3-camera.yaml"
DELIVERY = "configs/scenarios/delivery-gazebo.yaml"
FOLLOW = "models/actions/Follow.yaml"
GAZEBO = "models/platforms/ROS2/mapping-schemes/gazebo.yaml"
BOTH = "Follow: [follow_with_poses, follow_with_bluetooth]"


def block_list(lab: Lab, *logics: str) -> None:
    """tb3-01's capability with Follow's logics as a block list: one line per logic."""
    items = "".join(f"    - {name}\n" for name in logics)
    lab.write(
        CAMERA,
        "platform: ROS2\nmapping_scheme: gazebo\nrobot_template: turtlebot3-waffle-pi\n"
        f"actions:\n  AskHelp: ask_help_broadcast\n  SendGoalId: send_goal_id\n  Follow:\n{items}",
    )


# ------------------------------------------------------------------ the document


def test_the_example_lab_selects_both_follow_logics(lab: Lab) -> None:
    checked = lab.check()
    assert checked.diagnostics == []
    config = checked.repo.capabilities["turtlebot3-follow-either"].model
    assert config.logics_of("Follow") == ["follow_with_poses", "follow_with_bluetooth"]
    assert config.logics_of("AskHelp") == ["ask_help_broadcast"] and config.logics_of("X") == []
    resolved = resolve_capability(checked.repo, config)
    assert [s.logic_name for s in resolved.selections["Follow"]] == config.logics_of("Follow")
    assert {s.logic_name for s in resolved.all_selections()} == {
        "ask_help_broadcast",
        "send_goal_id",
        "follow_with_poses",
        "follow_with_bluetooth",
    }
    # The mappings both logics need, as the scheme binds them.
    assert sorted(bound_mappings(resolved)) == ["bluetooth_rssi", "camera", "cmd_vel", "odometry"]


@pytest.mark.parametrize(
    ("value", "words"),
    [
        ("[]", "actions.Follow must be text or a list of one or more logic names, got a list"),
        (
            "[follow_with_poses, follow_with_poses]",
            "a list of distinct logic names ('follow_with_poses' is named twice)",
        ),
    ],
)
def test_an_empty_list_or_a_logic_named_twice_is_refused_at_its_line(
    lab: Lab, value: str, words: str
) -> None:
    lab.replace(EITHER, BOTH, f"Follow: {value}")
    d = lab.only("RC103")
    assert d.path == EITHER and d.line == lab.line_of(EITHER, "Follow: [")
    assert words in d.message


def test_a_list_item_that_is_no_name_is_reported_once_at_the_item(lab: Lab) -> None:
    """Not also "must be text" for the list: it is a list, of which one item is wrong."""
    lab.replace(EITHER, BOTH, "Follow: [follow_with_poses, 1]")
    d = lab.only("RC103")
    assert d.message == "actions.Follow[1] must be text, got 1 (a whole number)"
    assert lab.read(EITHER).splitlines()[d.line - 1][d.col - 1 :].startswith("1]")


def test_each_unknown_logic_is_reported_at_its_item(lab: Lab) -> None:
    block_list(lab, "follow_with_pose", "follow_with_bluetooth", "follow_by_smell")
    found = lab.diagnostics("RC205")
    assert [(d.line, d.col) for d in found] == [
        (lab.line_of(CAMERA, "- follow_with_pose"), 7),
        (lab.line_of(CAMERA, "- follow_by_smell"), 7),
    ]
    assert "has no logic 'follow_with_pose'; did you mean 'follow_with_poses'?" in found[0].message
    assert "has no logic 'follow_by_smell'" in found[1].message
    # The known logic still counts: the scenario's Delivery is achievable, nothing else found;
    # its settings for follow_with_poses (what the typo meant) are not also RC406.
    assert {d.code for d in lab.check().diagnostics} == {"RC205"}


def test_the_template_must_serve_every_selected_logic(lab: Lab) -> None:
    """The Burger has no camera: follow_with_poses is named, follow_with_bluetooth is not."""
    lab.replace(EITHER, BOTH, "Follow: [follow_with_bluetooth, follow_with_poses]")
    lab.replace(EITHER, "robot_template: turtlebot3-waffle-pi", "robot_template: turtlebot3-burger")
    d = lab.only("RC301")
    assert "'camera' needed by follow_with_poses" in d.message
    assert "follow_with_bluetooth" not in d.message


def test_the_scheme_must_bind_each_logic_reported_at_its_item(lab: Lab) -> None:
    block_list(lab, "follow_with_poses", "follow_with_bluetooth")
    text = lab.read(GAZEBO)
    kept = [line for line in text.splitlines() if not line.strip().startswith("bluetooth_rssi")]
    lab.write(GAZEBO, "\n".join(kept) + "\n")
    found = [d for d in lab.check().diagnostics if d.code == "RC302" and d.path == CAMERA]
    assert len(found) == 1
    assert "logic 'follow_with_bluetooth' needs bluetooth_rssi" in found[0].message
    assert found[0].line == lab.line_of(CAMERA, "- follow_with_bluetooth")


def test_settings_of_every_selected_logic_are_accepted(lab: Lab) -> None:
    """RC406 counts each selected logic; a logic of the action not selected is still refused."""
    lab.replace(DELIVERY, "capability: turtlebot3-camera", "capability: turtlebot3-follow-either")
    lab.replace(DELIVERY, "logic_settings:\n", "logic_settings:\n  follow_with_bluetooth: {}\n")
    assert lab.check().diagnostics == []
    lab.replace(EITHER, BOTH, "Follow: [follow_with_poses]")
    d = lab.only("RC406")
    assert "logic 'follow_with_bluetooth' is not selected" in d.message


def test_requires_and_tasks_count_an_action_with_several_logics_as_selected(lab: Lab) -> None:
    lab.replace(DELIVERY, "capability: turtlebot3-camera", "capability: turtlebot3-follow-either")
    lab.replace(DELIVERY, "logic_settings:\n", "logic_settings:\n  follow_with_bluetooth: {}\n")
    lab.replace(EITHER, "AskHelp: ask_help_broadcast, ", "")
    codes = {d.code for d in lab.check().diagnostics}
    assert codes == {"RC303", "RC304"}  # SendGoalId requires AskHelp; Delivery needs AskHelp


# ------------------------------------------------------------------ rendering


def _scenario_on_either(lab: Lab) -> None:
    lab.replace(DELIVERY, "capability: turtlebot3-camera", "capability: turtlebot3-follow-either")


def test_a_request_lists_several_logics_in_the_order_written(lab: Lab) -> None:
    _scenario_on_either(lab)
    capability = lab.render("tb3-01").scenario.capability
    assert capability.logics == {
        "AskHelp": "ask_help_broadcast",
        "Follow": ["follow_with_poses", "follow_with_bluetooth"],
        "SendGoalId": "send_goal_id",
    }
    assert sorted(capability.mappings) == ["bluetooth_rssi", "camera", "cmd_vel", "odometry"]
    lab.replace(EITHER, BOTH, "Follow: [follow_with_bluetooth, follow_with_poses]")
    assert lab.render("tb3-01").scenario.capability.logics["Follow"] == [
        "follow_with_bluetooth",
        "follow_with_poses",
    ]


def test_settings_of_each_selected_logic_are_rendered(lab: Lab) -> None:
    _scenario_on_either(lab)
    settings = lab.render("tb3-01").scenario.logic_settings
    assert settings["follow_with_poses"]["move_speed"] == 0.1  # the scenario's
    assert settings["follow_with_bluetooth"] == {"move_speed": 0.1, "rssi_threshold": -60}


def test_one_logic_in_a_list_is_the_request_of_that_logic_named(lab: Lab) -> None:
    """Two spellings of one selection: the same request, the same digest."""
    before = lab.render("tb3-01")
    lab.replace(CAMERA, "Follow: follow_with_poses", "Follow: [follow_with_poses]")
    after = lab.render("tb3-01")
    assert after.scenario.capability.logics["Follow"] == "follow_with_poses"
    assert after.payload() == before.payload() and after.digest == before.digest


# Digests of the example lab's requests before actions could select several logics: a
# request of one logic per action must keep its bytes, or upgrading would restart brains.
DIGESTS_BEFORE_MULTI_LOGIC = {
    "tb3-01": "sha256:a78b390ff21ec84c0ef0bcad30347278b6a0c077f4abde6a3742e395725c762b",
    "tb3-02": "sha256:0b641fef098acb076641dda967c2e16c10fc907df6492e1952f5f8d6c8f39741",
    "tb3-03": "sha256:759af42a7d4dd8a51074a0f829dbc398b24ee638b89a508a88070b4ae72f2f06",
}


def test_existing_requests_keep_their_digests(lab: Lab) -> None:
    checked = lab.check()
    assert checked.ok, checked.errors
    rendered = render_fleet(checked.repo).requests
    assert {r: rendered[r].digest for r in DIGESTS_BEFORE_MULTI_LOGIC} == (
        DIGESTS_BEFORE_MULTI_LOGIC
    )


# ------------------------------------------------------------------ tree and plan


def test_tree_marks_every_selected_logic(lab: Lab) -> None:
    tree = build_tree(lab.check().repo, "turtlebot3-follow-either")
    delivery = next(t for t in tree.tasks if t.name == "Delivery")
    follow = next(a for a in delivery.implementations[0] if a.name == "Follow")
    assert [logic_label(node) for node in follow.logics] == [
        "● follow_with_poses (chosen)",
        "● follow_with_bluetooth (chosen)",
    ]
    assert action_label(follow) == "✔ action Follow (selected, 2 logics)"


def test_plan_shows_an_action_s_logics_before_and_after(lab: Lab) -> None:
    checked = lab.check()
    base = render_fleet(checked.repo)
    lab.replace(
        CAMERA, "Follow: follow_with_poses", "Follow: [follow_with_poses, follow_with_bluetooth]"
    )
    head = render_fleet(lab.check().repo)
    plan = make_plan(base, head)
    change = next(c for c in plan.changes if c.robot_id == "tb3-01")
    assert "scenario.capability.logics.Follow" in change.fields
    assert not any("logics.Follow[" in f for f in change.fields)
    line = next(x for x in format_plan_text(plan).splitlines() if "tb3-01" in x)
    assert (
        "logics of Follow: follow_with_poses -> follow_with_poses + follow_with_bluetooth" in line
    )
    assert line.endswith("[restart]")
    markdown = format_plan_markdown(plan)
    assert "logics of Follow: follow_with_poses -> follow_with_poses + follow_with_bluetooth" in (
        markdown
    )
    data = next(c for c in plan_as_json(plan)["changes"] if c["robot_id"] == "tb3-01")
    assert data["logics"] == {
        "Follow": {
            "before": ["follow_with_poses"],
            "after": ["follow_with_poses", "follow_with_bluetooth"],
        }
    }


def test_plan_names_the_action_once_when_one_of_its_logics_changes(lab: Lab) -> None:
    _scenario_on_either(lab)
    base = render_fleet(lab.check().repo)
    lab.replace(EITHER, BOTH, "Follow: [follow_with_bluetooth, follow_with_poses]")
    plan = make_plan(base, render_fleet(lab.check().repo))
    change = next(c for c in plan.changes if c.robot_id == "tb3-01")
    assert [f for f in change.fields if "logics" in f] == ["scenario.capability.logics.Follow"]
    assert change.logics == {
        "Follow": (
            ["follow_with_poses", "follow_with_bluetooth"],
            ["follow_with_bluetooth", "follow_with_poses"],
        )
    }


# ------------------------------------------------------------------ autofill


def _action(*logics: tuple[str, list[str]], requires: list[str] | None = None) -> Action:
    return Action(
        platforms=["ROS2"],
        requires=requires or [],
        logics={name: Logic(mappings=needs) for name, needs in logics},
    )


ACTIONS = {
    "Follow": _action(("by_camera", ["camera"]), ("by_radio", ["radio"]), ("by_lidar", ["scan"])),
    "Guide": _action(("by_camera", ["camera"]), requires=["Follow"]),
    "Dock": _action(("by_dock", ["dock"])),
}


def _having(*mappings: str) -> Any:
    """A fit test that is no template: a robot that has these mappings (as interfaces would)."""

    def fits(_action_name: str, _action: Action, _logic_name: str, logic: Logic) -> list[str]:
        return [f"lacks {m}" for m in logic.mappings if m not in mappings]

    return fits


def test_select_logics_takes_the_fit_test_as_a_parameter() -> None:
    fits = _having("camera", "scan")
    first = select_logics(ACTIONS, "ROS2", fits)
    assert first.chosen == {"Follow": ["by_camera"], "Guide": ["by_camera"]}
    assert first.skipped == {"Dock": ["by_dock: lacks dock"]}
    every = select_logics(ACTIONS, "ROS2", fits, every=True)
    assert every.chosen == {"Follow": ["by_camera", "by_lidar"], "Guide": ["by_camera"]}
    # An action whose requires cannot be selected is dropped either way.
    none_follow = select_logics(ACTIONS, "ROS2", _having("camera"), every=True)
    assert none_follow.chosen == {"Follow": ["by_camera"], "Guide": ["by_camera"]}
    lonely = select_logics({"Guide": ACTIONS["Guide"]}, "ROS2", fits, every=True)
    assert lonely.chosen == {}
    assert lonely.skipped == {"Guide": ["requires Follow, which cannot be selected"]}
    assert select_logics(ACTIONS, "ROS1", fits, every=True).chosen == {}


def test_template_fit_is_the_template_and_scheme_check(lab: Lab) -> None:
    repo = lab.check().repo
    ros2 = repo.platforms["ROS2"]
    fits = template_fit(
        "ROS2",
        ros2.templates["turtlebot3-burger"].model,
        ros2.schemes["gazebo"].model,
    )
    actions = {name: entry.model for name, entry in repo.actions.items()}
    every = select_logics(actions, "ROS2", fits, every=True)
    assert every.chosen["Follow"] == ["follow_with_bluetooth"]
    waffle = template_fit(
        "ROS2", ros2.templates["turtlebot3-waffle-pi"].model, ros2.schemes["gazebo"].model
    )
    assert select_logics(actions, "ROS2", waffle, every=True).chosen["Follow"] == [
        "follow_with_poses",
        "follow_with_bluetooth",
    ]


def test_to_yaml_writes_a_list_only_for_several_logics() -> None:
    config = CapabilityConfiguration(
        platform="ROS2",
        mapping_scheme="gazebo",
        actions={"AskHelp": "ask_help_broadcast", "Follow": ["a", "b: c"]},
    )
    text = to_yaml(config, "../../schemas/capability.schema.json", "test")
    assert text.endswith(
        "actions:\n  AskHelp: ask_help_broadcast\n  Follow:\n    - a\n    - 'b: c'\n"
    )


# ------------------------------------------------------------------ schema


def _capability_schema() -> dict[str, Any]:
    return generate(check(ROOT).repo)["capability.schema.json"]


@pytest.mark.parametrize(
    ("follow", "valid"),
    [
        ("follow_with_poses", True),
        (["follow_with_poses", "follow_with_bluetooth"], True),
        (["follow_with_bluetooth"], True),
        ([], False),
        (["follow_with_poses", "follow_with_poses"], False),
        (["follow_with_poses", "follow_by_smell"], False),
        ("follow_by_smell", False),
    ],
)
def test_the_capability_schema_takes_a_logic_or_a_list_of_them(follow: Any, valid: bool) -> None:
    document = {"platform": "ROS2", "mapping_scheme": "gazebo", "actions": {"Follow": follow}}
    validator = jsonschema.Draft202012Validator(_capability_schema())
    assert (list(validator.iter_errors(document)) == []) is valid


def test_the_scenario_schema_takes_settings_of_every_selected_logic() -> None:
    schema = generate(check(ROOT).repo)["scenario.schema.json"]
    validator = jsonschema.Draft202012Validator(schema)
    scenario = {
        "capability": "turtlebot3-follow-either",
        "logic_settings": {
            "follow_with_poses": {"move_speed": 0.1},
            "follow_with_bluetooth": {"rssi_threshold": -55},
        },
    }
    assert list(validator.iter_errors(scenario)) == []
    scenario["logic_settings"]["follow_with_bluetooth"] = {"rssi_threshold": 5}
    assert [e.message for e in validator.iter_errors(scenario)] == [
        "5 is greater than the maximum of -30.0"
    ]
