"""One failing case per validation rule, on a copy of the example lab: code and place."""

from __future__ import annotations

import pytest

from tests.support.lab import Lab

CAMERA = "configs/capabilities/turtlebot3-camera.yaml"
BLUETOOTH = "configs/capabilities/turtlebot3-bluetooth.yaml"
EITHER = "configs/capabilities/turtlebot3-follow-either.yaml"
DELIVERY = "configs/scenarios/delivery-gazebo.yaml"
FLEET = "configs/fleet.yaml"
FOLLOW = "models/actions/Follow.yaml"
BURGER = "models/platforms/ROS2/robot-templates/turtlebot3-burger.yaml"
GAZEBO = "models/platforms/ROS2/mapping-schemes/gazebo.yaml"


def test_example_lab_is_clean(lab: Lab) -> None:
    checked = lab.check()
    assert checked.diagnostics == []
    assert checked.repo.files_read > 20
    assert set(checked.repo.platforms) == {"ROS1", "ROS2"}


# ------------------------------------------------------------------ references


def test_unknown_platform(lab: Lab) -> None:
    lab.replace(CAMERA, "platform: ROS2", "platform: ROS3")
    d = lab.only("RC201")
    assert d.path == CAMERA and d.line == lab.line_of(CAMERA, "platform: ROS3")
    assert d.col == len("platform: ") + 1
    assert "did you mean 'ROS2'" in d.message


def test_unknown_mapping_scheme_of_platform(lab: Lab) -> None:
    lab.replace(CAMERA, "mapping_scheme: gazebo", "mapping_scheme: gazebo-classic")
    d = lab.only("RC202")
    assert "platform ROS2 has no mapping scheme 'gazebo-classic'" in d.message
    assert d.line == lab.line_of(CAMERA, "mapping_scheme:")


def test_unknown_robot_template_of_platform(lab: Lab) -> None:
    lab.replace(
        CAMERA, "robot_template: turtlebot3-waffle-pi", "robot_template: turtlebot3-wafle-pi"
    )
    d = lab.only("RC203")
    assert "did you mean 'turtlebot3-waffle-pi'" in d.message


def test_unknown_action_points_at_the_key(lab: Lab) -> None:
    lab.replace(CAMERA, "Follow: follow_with_poses", "Folow: follow_with_poses")
    found = lab.check().diagnostics
    rc204 = [d for d in found if d.code == "RC204"]
    assert len(rc204) == 1
    assert "unknown action 'Folow'; did you mean 'Follow'?" in rc204[0].message
    text = lab.read(CAMERA).splitlines()[rc204[0].line - 1]
    assert text[rc204[0].col - 1 :].startswith("Folow")
    # One typo, one error: the scenario's Delivery, which needs Follow, is not also "not
    # achievable" (RC304), nor are its follow_with_poses settings reported.
    assert [d.code for d in found] == ["RC204"]


def test_a_misspelt_action_is_not_also_a_missing_requirement(lab: Lab) -> None:
    """SendGoalId requires AskHelp: `AskHlp` is RC204 alone, not also RC303 and RC304."""
    lab.replace(CAMERA, "AskHelp: ask_help_broadcast", "AskHlp: ask_help_broadcast")
    assert "did you mean 'AskHelp'?" in lab.only("RC204").message


def test_what_a_typo_does_not_explain_is_still_reported(lab: Lab) -> None:
    """Follow misspelt and AskHelp gone: AskHelp's absence is no typo's, RC303 and RC304 stay."""
    lab.replace(CAMERA, "AskHelp: ask_help_broadcast, ", "")
    lab.replace(CAMERA, "Follow: follow_with_poses", "Folow: follow_with_poses")
    found = lab.check().diagnostics
    assert sorted(d.code for d in found) == ["RC204", "RC303", "RC304"]
    assert "requires action 'AskHelp'" in next(d for d in found if d.code == "RC303").message


def test_action_not_on_platform(lab: Lab) -> None:
    lab.replace(FOLLOW, "platforms: [ROS2]", "platforms: [ROS1]")
    d = lab.diagnostics("RC204")
    assert d and all("is for ROS1, not platform ROS2" in x.message for x in d)


def test_unknown_logic_of_action(lab: Lab) -> None:
    """One typo, one error: the scenario's settings for follow_with_poses (which the typo
    meant) are not also "not selected" (RC406)."""
    assert "follow_with_poses:" in lab.read(DELIVERY)
    lab.replace(CAMERA, "Follow: follow_with_poses", "Follow: follow_with_pose")
    d = lab.only("RC205")
    assert "did you mean 'follow_with_poses'" in d.message


def test_settings_of_another_actions_logic_are_still_refused_beside_a_typo(lab: Lab) -> None:
    """Only logics of the action whose selection has the typo are spared RC406."""
    lab.replace(CAMERA, "Follow: follow_with_poses", "Follow: follow_with_pose")
    lab.replace(DELIVERY, "logic_settings:\n", "logic_settings:\n  open_by_sending_signal: {}\n")
    assert sorted(d.code for d in lab.check().diagnostics) == ["RC205", "RC406"]


def test_unknown_capability(lab: Lab) -> None:
    lab.replace(DELIVERY, "capability: turtlebot3-camera", "capability: turtlebot3-camra")
    d = lab.only("RC206")
    assert d.path == DELIVERY and "did you mean 'turtlebot3-camera'" in d.message


def test_unknown_environment(lab: Lab) -> None:
    lab.replace(DELIVERY, "environment: GazeboDemo1", "environment: GazeboDemo2")
    d = lab.only("RC207")
    assert "unknown environment 'GazeboDemo2'" in d.message


def test_unknown_knowledge_set(lab: Lab) -> None:
    lab.replace(DELIVERY, "knowledge_sets: [Delivery]", "knowledge_sets: [Delivry]")
    d = lab.only("RC208")
    assert "did you mean 'Delivery'" in d.message
    assert lab.read(DELIVERY).splitlines()[d.line - 1][d.col - 1 :].startswith("Delivry")


def test_knowledge_set_without_environment(lab: Lab) -> None:
    lab.write(
        "configs/scenarios/no-env.yaml",
        "capability: turtlebot3-camera\nknowledge_sets: [Delivery]\n",
    )
    d = lab.only("RC208")
    assert "needs an environment" in d.message


def test_unknown_scenario_in_fleet(lab: Lab) -> None:
    lab.replace(FLEET, "scenario: delivery-gazebo", "scenario: delivery-gazbo")
    d = lab.only("RC209")
    assert d.path == FLEET and "did you mean 'delivery-gazebo'" in d.message


def test_unknown_goal_task(lab: Lab) -> None:
    lab.replace(DELIVERY, "task: Delivery", "task: Delivry")
    d = lab.only("RC210")
    assert "did you mean 'Delivery'" in d.message


# ------------------------------------------------------------------ composition


def test_logic_needs_mapping_the_template_lacks(lab: Lab) -> None:
    """follow_with_poses needs camera; the Burger has none."""
    lab.replace(CAMERA, "robot_template: turtlebot3-waffle-pi", "robot_template: turtlebot3-burger")
    found = lab.check().diagnostics
    rc301 = [d for d in found if d.code == "RC301"]
    assert len(rc301) == 1
    assert "'camera' needed by follow_with_poses" in rc301[0].message
    assert rc301[0].line == lab.line_of(CAMERA, "robot_template:")


def test_missing_mappings_list_each_needing_logic(lab: Lab) -> None:
    lab.replace(BURGER, "mappings: [cmd_vel, odometry,", "mappings: [odometry,")
    found = [d for d in lab.check().diagnostics if d.code == "RC301" and d.path == BLUETOOTH]
    assert len(found) == 1
    assert "'cmd_vel' needed by follow_with_bluetooth" in found[0].message


def test_logic_needs_mapping_the_scheme_does_not_bind(lab: Lab) -> None:
    text = lab.read(GAZEBO)
    kept = [line for line in text.splitlines() if not line.strip().startswith("bluetooth_rssi")]
    lab.write(GAZEBO, "\n".join(kept) + "\n")
    found = lab.check().diagnostics
    rc302 = [d for d in found if d.code == "RC302"]
    # The Bluetooth robot's capability, and the one that selects both Follow logics.
    assert sorted(d.path for d in rc302) == [BLUETOOTH, EITHER]
    assert all("follow_with_bluetooth' needs bluetooth_rssi" in d.message for d in rc302)
    # The catalogue itself also warns that the scheme cannot serve the templates.
    assert any(d.code == "RC608" and d.severity.value == "warning" for d in found)


def test_required_action_not_selected(lab: Lab) -> None:
    lab.replace(CAMERA, "AskHelp: ask_help_broadcast, ", "")
    found = lab.check().diagnostics
    rc303 = [d for d in found if d.code == "RC303"]
    assert len(rc303) == 1
    assert "'SendGoalId' requires action 'AskHelp'" in rc303[0].message


def test_goal_task_not_achievable(lab: Lab) -> None:
    lab.replace(DELIVERY, "task: Delivery", "task: Patrol")
    d = lab.only("RC304")
    assert "task 'Patrol' is not achievable" in d.message
    assert "[NavigateToLocation] or [OpenDoor, NavigateToLocation]" in d.message


def test_goal_location_not_in_environment(lab: Lab) -> None:
    lab.replace(DELIVERY, "location: BallContainer", "location: BallContainr")
    d = lab.only("RC305")
    assert "did you mean 'BallContainer'" in d.message


def test_goal_location_must_be_a_location(lab: Lab) -> None:
    env = "models/environments/GazeboDemo1.yaml"
    lab.replace(env, "objects:", "objects:\n  - {id: d1, name: FrontDoor, type: Door}")
    lab.replace(DELIVERY, "location: BallContainer", "location: FrontDoor")
    d = lab.only("RC305")
    assert "is a Door, not a Location" in d.message


def test_goal_location_without_environment(lab: Lab) -> None:
    lab.write(
        "configs/scenarios/nowhere.yaml",
        "capability: turtlebot3-camera\ngoals: [{task: Delivery, location: BallContainer}]\n",
    )
    assert "needs an environment" in lab.only("RC306").message


# ------------------------------------------------------------------ settings


def test_unknown_robot_setting(lab: Lab) -> None:
    lab.replace(DELIVERY, "max_angular_speed:", "max_angular_sped:")
    d = lab.only("RC401")
    assert "did you mean 'max_angular_speed'" in d.message


def test_unknown_logic_setting(lab: Lab) -> None:
    lab.replace(DELIVERY, "follow_distance:", "follow_distanse:")
    assert "did you mean 'follow_distance'" in lab.only("RC401").message


def test_setting_of_wrong_type(lab: Lab) -> None:
    lab.replace(DELIVERY, "move_speed: 0.1", "move_speed: fast")
    d = lab.only("RC402")
    assert d.message.endswith("must be a number, got 'fast' (text)")
    assert lab.read(DELIVERY).splitlines()[d.line - 1][d.col - 1 :].startswith("fast")


def test_integer_setting_refuses_a_fraction_and_a_boolean(lab: Lab) -> None:
    lab.write(
        "configs/scenarios/bt.yaml",
        "capability: turtlebot3-bluetooth\nlogic_settings:\n"
        "  follow_with_bluetooth: {rssi_threshold: -50.5}\n",
    )
    assert lab.only("RC402").message.endswith("must be a whole number, got -50.5 (a number)")
    lab.replace("configs/scenarios/bt.yaml", "-50.5", "true")
    assert lab.only("RC402").message.endswith("must be a whole number, got true")


@pytest.mark.parametrize(
    ("value", "code", "expected"),
    [
        ("[1, 2]", "RC103", "or text, got a list"),
        ("{a: 1}", "RC103", "or text, got a mapping"),
        ("'yes'", "RC402", "must be true or false, got 'yes' (text)"),
        ("2", "RC402", "must be true or false, got 2 (a whole number)"),
        ("0.5", "RC402", "must be true or false, got 0.5 (a number)"),
    ],
)
def test_type_errors_name_what_was_given(lab: Lab, value: str, code: str, expected: str) -> None:
    """Booleans, lists, mappings, text and numbers each read as `must be X, got V (kind)`."""
    guide = "configs/scenarios/guide-gazebo.yaml"
    lab.replace(guide, "{open_timeout: 15}", f"{{open_timeout: 15, wait_until_open: {value}}}")
    assert lab.only(code).message.endswith(expected)


def test_setting_out_of_range(lab: Lab) -> None:
    lab.replace(DELIVERY, "max_linear_speed: 0.2", "max_linear_speed: 0.3")
    d = lab.only("RC403")
    assert "0.3 is outside 0..0.26 m/s" in d.message


def test_setting_not_in_choices(lab: Lab) -> None:
    template = "models/platforms/ROS2/robot-templates/turtlebot3-waffle-pi.yaml"
    assert "camera_resolution" in lab.read(template)
    lab.replace(DELIVERY, "robot_settings: {", "robot_settings: {camera_resolution: 4k, ")
    assert "is not one of the choices" in lab.only("RC404").message


def test_robot_settings_need_a_template(lab: Lab) -> None:
    lab.replace(CAMERA, "robot_template: turtlebot3-waffle-pi\n", "")
    d = lab.only("RC405")
    assert d.path == DELIVERY and "names none" in d.message


def test_logic_settings_for_unselected_logic(lab: Lab) -> None:
    lab.replace(DELIVERY, "follow_with_poses: {", "follow_with_bluetooth: {")
    assert "not selected by capability 'turtlebot3-camera'" in lab.only("RC406").message


# ------------------------------------------------------------------ fleet


@pytest.mark.parametrize("robot_id", ["tb3/01", "tb3+", "-tb3", "tb3 01", "#", "x" * 65])
def test_robot_id_must_be_a_topic_level(lab: Lab, robot_id: str) -> None:
    lab.replace(FLEET, "tb3-01:", f"{robot_id!r}:")
    d = lab.only("RC501")
    assert "not usable as an MQTT topic level" in d.message
    assert d.line == lab.line_of(FLEET, repr(robot_id))


# ------------------------------------------------------------------ catalogue sanity


def test_default_outside_its_bounds(lab: Lab) -> None:
    lab.replace(FOLLOW, "default: 0.15", "default: 0.5")
    d = lab.only("RC601")
    assert d.path == FOLLOW and "setting 'move_speed': default 0.5 is outside" in d.message
    assert d.line == lab.line_of(FOLLOW, "default: 0.5")


def test_default_of_wrong_type(lab: Lab) -> None:
    lab.replace("models/actions/OpenDoor.yaml", "default: true", "default: 3")
    assert "must be true or false" in lab.only("RC601").message


def test_contradictory_setting_definition(lab: Lab) -> None:
    lab.replace(FOLLOW, "minimum: 0.2\n        maximum: 2.0", "minimum: 2.0\n        maximum: 0.2")
    found = lab.check().diagnostics
    assert any(d.code == "RC602" and "minimum is greater than maximum" in d.message for d in found)


def test_enum_without_choices(lab: Lab) -> None:
    lab.replace("models/actions/OpenDoor.yaml", "type: boolean", "type: enum")
    assert "needs 'choices'" in lab.only("RC602").message


def test_task_implementation_names_unknown_action(lab: Lab) -> None:
    lab.replace(
        "models/tasks/Patrol.yaml",
        "[OpenDoor, NavigateToLocation]",
        "[OpenDor, NavigateToLocation]",
    )
    d = lab.only("RC603")
    assert "unknown action 'OpenDor'; did you mean 'OpenDoor'?" in d.message


def test_action_requires_unknown_action(lab: Lab) -> None:
    lab.replace("models/actions/SendGoalId.yaml", "requires: [AskHelp]", "requires: [AskHelpp]")
    found = lab.check().diagnostics
    assert any(d.code == "RC604" and "did you mean 'AskHelp'" in d.message for d in found)


def test_action_requires_itself(lab: Lab) -> None:
    lab.replace(
        "models/actions/SendGoalId.yaml", "requires: [AskHelp]", "requires: [AskHelp, SendGoalId]"
    )
    assert "requires itself" in lab.only("RC604").message


def test_action_lists_unknown_platform(lab: Lab) -> None:
    lab.replace("models/actions/OpenDoor.yaml", "platforms: [ROS2]", "platforms: [ROS2, ROS7]")
    assert "unknown platform 'ROS7'" in lab.only("RC605").message


def test_duplicate_object_id(lab: Lab) -> None:
    env = "models/environments/GazeboDemo1.yaml"
    lab.replace(env, "objects:", "objects:\n  - {id: '1', name: Twin, type: Location}")
    d = lab.only("RC606")
    assert "object id '1' is used twice (first at line" in d.message


def test_template_lists_mapping_twice(lab: Lab) -> None:
    lab.replace(BURGER, "mappings: [cmd_vel,", "mappings: [cmd_vel, cmd_vel,")
    assert "'cmd_vel' is listed twice" in lab.only("RC607").message


# ------------------------------------------------------------------ typing and names


def test_unknown_field_is_an_error_with_a_hint(lab: Lab) -> None:
    lab.replace(DELIVERY, "knowledge_sets:", "knowledge_set:")
    d = lab.only("RC101")
    assert (
        "unknown field 'knowledge_set'" in d.message
        and "did you mean 'knowledge_sets'" in d.message
    )
    assert d.col == 1


def test_unknown_nested_field(lab: Lab) -> None:
    lab.replace(FOLLOW, "unit: m/s", "units: m/s")
    d = lab.only("RC101")
    assert "in logics.follow_with_poses.settings.move_speed" in d.message


def test_missing_required_field(lab: Lab) -> None:
    lab.replace(CAMERA, "mapping_scheme: gazebo\n", "")
    assert "missing required field 'mapping_scheme'" in lab.only("RC102").message


def test_wrong_type_of_field(lab: Lab) -> None:
    lab.replace(CAMERA, "platform: ROS2", "platform: [ROS2]")
    d = lab.only("RC103")
    assert d.message == "platform must be text, got a list"


def test_name_must_equal_file_name(lab: Lab) -> None:
    lab.replace(CAMERA, "platform: ROS2", "name: camera-bot\nplatform: ROS2")
    assert "differs from the file name 'turtlebot3-camera'" in lab.only("RC104").message


def test_broken_file_is_not_reported_again_through_references(lab: Lab) -> None:
    lab.write(CAMERA, "platform: [\n")
    found = lab.check().diagnostics
    assert [d.code for d in found] == ["RC003"]


def test_broken_template_is_not_reported_again_through_its_capabilities(lab: Lab) -> None:
    lab.write("models/platforms/ROS2/robot-templates/turtlebot3-burger.yaml", "mappings: [\n")
    assert [d.code for d in lab.check().diagnostics] == ["RC003"]
