"""Launch Requests: defaults, mappings, knowledge, goals, revision and a digest that ignores it."""

from __future__ import annotations

import re

import pytest

from robotconf.configurator.render import RenderError, deep_merge, render_fleet, render_robot
from robotconf.configurator.rendered import RenderedRequest
from robotconf.contract.launch import LaunchRequest
from tests.support.lab import Lab

DELIVERY = "configs/scenarios/delivery-gazebo.yaml"


def test_request_shape_and_defaults(lab: Lab) -> None:
    request = lab.render()
    assert request.apiVersion == "robotconf/v1" and request.kind == "LaunchRequest"
    assert (request.robot_id, request.robot_name) == ("tb3-01", "Delivery bot")
    scenario = request.scenario
    assert scenario.name == "delivery-gazebo"
    cap = scenario.capability
    assert cap.platform == "ROS2" and cap.mapping_scheme == "gazebo"
    assert cap.logics == {
        "AskHelp": "ask_help_broadcast",
        "SendGoalId": "send_goal_id",
        "Follow": "follow_with_poses",
    }
    assert cap.tasks == ["Delivery"]
    assert cap.actions == ["AskHelp", "Follow", "SendGoalId"]
    # Chosen values override, defaults fill the rest.
    assert scenario.robot_settings["max_linear_speed"] == 0.2
    assert scenario.robot_settings["camera_resolution"] == "640x480"
    assert scenario.logic_settings["follow_with_poses"] == {
        "move_speed": 0.1,
        "follow_distance": 0.6,
    }
    assert scenario.logic_settings["ask_help_broadcast"] == {"answer_timeout": 30}
    assert scenario.environment_name == "GazeboDemo1" and scenario.environment_type == "Gazebo"


def test_mappings_are_the_needed_ones_bound_by_the_scheme(lab: Lab) -> None:
    cap = lab.render().scenario.capability
    assert set(cap.mappings) == {"odometry", "cmd_vel", "camera"}
    # The gazebo scheme's names are relative: resolved in the robot's namespace.
    assert cap.mappings["cmd_vel"].name == "/tb3_01/cmd_vel"
    lab.replace(
        "configs/capabilities/turtlebot3-camera.yaml",
        "mapping_scheme: gazebo",
        "mapping_scheme: real-world",
    )
    real = lab.render().scenario.capability.mappings["camera"]
    sim = cap.mappings["camera"]
    assert (real.name, real.type) != (sim.name, sim.type)


def test_knowledge_sets_merge_in_order_then_inline_knowledge(lab: Lab) -> None:
    env = "models/environments/GazeboDemo1.yaml"
    lab.replace(
        env,
        "knowledge_sets:",
        "knowledge_sets:\n  A: {TARGET: {GOAL_ID: '1', KEEP: a}, ONLY_A: 1}\n"
        "  B: {TARGET: {GOAL_ID: '3', FROM_B: b}}",
    )
    lab.replace(DELIVERY, "knowledge_sets: [Delivery]", "knowledge_sets: [A, B]")
    knowledge = lab.render().scenario.environment_knowledge
    assert knowledge == {"ONLY_A": 1, "TARGET": {"GOAL_ID": "2", "KEEP": "a", "FROM_B": "b"}}


def test_deep_merge_does_not_touch_its_inputs() -> None:
    base = {"a": {"b": 1}}
    merged = deep_merge(base, {"a": {"c": 2}, "d": [1]})
    assert merged == {"a": {"b": 1, "c": 2}, "d": [1]} and base == {"a": {"b": 1}}


def test_goal_locations_expand_to_their_objects(lab: Lab) -> None:
    goals = lab.render().scenario.goals
    assert goals[0].task == "Delivery"
    location = goals[0].location
    assert location is not None
    assert location["name"] == "BallContainer" and location["type"] == "Location"
    assert "id" in location and len(location) > 3  # free extra fields (coordinates) come along


GAZEBO = "models/platforms/ROS2/mapping-schemes/gazebo.yaml"
FLEET = "configs/fleet.yaml"


def names(request: RenderedRequest | LaunchRequest) -> dict[str, str]:
    model = request.model() if isinstance(request, RenderedRequest) else request
    return {key: b.name for key, b in model.scenario.capability.mappings.items()}


def test_each_robot_gets_its_fully_qualified_names_and_namespace(lab: Lab) -> None:
    rendered = render_fleet(lab.check().repo).requests
    guide, delivery = rendered["tb3-02"], rendered["tb3-01"]
    assert guide.namespace == "/tb3_02" and delivery.namespace == "/tb3_01"
    assert names(guide) == {
        "navigate_to_pose": "/tb3_02/navigate_to_pose",
        "odometry": "/tb3_02/odom",
        "door_opener": "/sim/door_controller/open",  # absolute: the world's, shared
    }
    assert names(delivery)["odometry"] == "/tb3_01/odom"
    assert render_robot(lab.check().repo, "tb3-02") == guide.model()  # as in the fleet
    # A robot of another scenario keeps its absolute names, and has no namespace.
    assert rendered["tb3-04"].namespace is None
    assert names(rendered["tb3-04"])["odometry"] == "/odom"


def test_a_namespace_written_relative_is_carried_absolute(lab: Lab) -> None:
    lab.replace(FLEET, "namespace: tb3_02}", "namespace: /lab/tb3_02}")
    request = lab.render("tb3-02")
    assert request.namespace == "/lab/tb3_02"
    assert names(request)["odometry"] == "/lab/tb3_02/odom"


def test_without_a_namespace_relative_names_resolve_at_the_root(lab: Lab) -> None:
    lab.replace(FLEET, ", namespace: tb3_02}", "}")
    request = lab.render("tb3-02")
    assert request.namespace is None and names(request)["odometry"] == "/odom"
    assert "namespace" not in request.wire()


def test_namespace_substitution(lab: Lab) -> None:
    lab.replace(GAZEBO, "name: odom,", "name: '{namespace}/odometry/filtered',")
    assert names(lab.render("tb3-02"))["odometry"] == "/tb3_02/odometry/filtered"
    # Rendering refuses, rather than guess, what validation reports (RC504).
    lab.replace(FLEET, ", namespace: tb3_02}", "}")
    repo = lab.check().repo
    needs = re.escape("robot 'tb3-02': '{namespace}/odometry/filtered' needs the robot's namespace")
    with pytest.raises(RenderError, match=needs):
        render_robot(repo, "tb3-02")
