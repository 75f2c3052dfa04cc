"""ROS 2 names validated: mapping names (RC609), namespaces (RC503), `{namespace}` without one
(RC504) and robots of one world on the same names (RC505): code, place and words."""

from __future__ import annotations

from tests.support.lab import Lab

FLEET = "configs/fleet.yaml"
GAZEBO = "models/platforms/ROS2/mapping-schemes/gazebo.yaml"


def column_of(lab: Lab, rel: str, line: int, needle: str) -> int:
    return lab.read(rel).splitlines()[line - 1].index(needle) + 1


def test_a_mapping_name_is_a_ros2_name_located_at_the_name(lab: Lab) -> None:
    lab.replace(GAZEBO, "name: camera/image_raw,", "name: camera/1raw,")
    d = lab.only("RC609")
    assert d.path == GAZEBO and d.line == lab.line_of(GAZEBO, "camera/1raw")
    assert d.col == column_of(lab, GAZEBO, d.line, "camera/1raw")
    assert d.message == (
        "mapping 'camera': name 'camera/1raw' has token '1raw' starting with a digit"
    )


def test_a_private_name_is_refused_with_the_reason(lab: Lab) -> None:
    lab.replace(GAZEBO, "name: scan,", "name: ~/scan,")
    assert "private ('~'): it depends on the brain's node name" in lab.only("RC609").message


def test_a_bad_namespace_is_located_at_the_value_with_a_fix(lab: Lab) -> None:
    lab.replace(FLEET, "namespace: tb3_02}", "namespace: tb3-02}")
    d = lab.only("RC503")
    assert d.path == FLEET and d.line == lab.line_of(FLEET, "tb3-02:")
    assert d.col == column_of(lab, FLEET, d.line, "tb3-02}")
    assert "namespace 'tb3-02' has token 'tb3-02' with '-'" in d.message
    assert d.message.endswith("e.g. `namespace: tb3_02`")


def test_the_root_namespace_is_written_by_leaving_it_out(lab: Lab) -> None:
    lab.replace(FLEET, "namespace: tb3_02}", "namespace: /}")
    assert "leave `namespace` out" in lab.only("RC503").message


def test_a_namespace_that_makes_a_name_too_long_for_dds(lab: Lab) -> None:
    long = "/".join(["n" * 57] * 4)  # valid alone, and with /odom; not with /navigate_to_pose
    lab.replace(FLEET, "namespace: tb3_02}", f"namespace: {long}}}")
    d = lab.only("RC503")
    assert "mapping 'navigate_to_pose' is too long for DDS" in d.message
    assert d.line == lab.line_of(FLEET, "tb3-02:")


def test_namespace_substitution_needs_a_namespace_at_the_robot(lab: Lab) -> None:
    lab.replace(GAZEBO, "name: odom,", "name: '{namespace}/odom',")
    assert lab.check().diagnostics == []  # every robot using it has a namespace
    lab.replace(FLEET, "Guide bot, namespace: tb3_02}", "Guide bot}")
    d = lab.only("RC504")
    assert (d.path, d.line, d.col) == (FLEET, lab.line_of(FLEET, "tb3-02:"), 3)
    assert d.message == (
        "robot 'tb3-02' has no namespace, and mapping scheme ROS2/gazebo names odometry in it "
        "('{namespace}/odom'): give the robot one, e.g. `namespace: tb3_02`"
    )


def test_two_robots_of_one_world_on_the_same_names_would_drive_each_other(lab: Lab) -> None:
    lab.replace(FLEET, ", namespace: tb3_01, name: Delivery bot}", ", name: Delivery bot}")
    lab.replace(FLEET, "Guide bot, namespace: tb3_02}", "Guide bot}")
    d = lab.only("RC505")
    # At the second robot: the first keeps its place, the message names both.
    assert (d.path, d.line, d.col) == (FLEET, lab.line_of(FLEET, "tb3-02:"), 3)
    assert d.message == (
        "robots 'tb3-01' and 'tb3-02' both use /odom (odometry) in environment GazeboDemo1 "
        "(ROS2) on ROS domain 0 (ROS's default, where a robot without `ros_domain_id` runs): "
        "they would drive each other; give them namespaces (`namespace: tb3_01`, "
        "`namespace: tb3_02`), or put them on different domains (e.g. `ros_domain_id: 1` for "
        "'tb3-02')"
    )


def test_absolute_names_clash_whatever_the_namespaces(lab: Lab) -> None:
    lab.replace(GAZEBO, "name: cmd_vel,", "name: /cmd_vel,")
    d = lab.only("RC505")
    assert d.line == lab.line_of(FLEET, "tb3-03:")
    assert "robots 'tb3-01' and 'tb3-03' both use /cmd_vel (cmd_vel)" in d.message
    # Both have namespaces already: an absolute name ignores them, the scheme is the fix.
    assert d.message.endswith(
        "would drive each other; write these names relative in mapping scheme ROS2/gazebo "
        "(cmd_vel, not /cmd_vel), or put them on different domains (e.g. `ros_domain_id: 1` "
        "for 'tb3-03')"
    )


def test_one_namespace_for_two_robots_clashes(lab: Lab) -> None:
    lab.replace(FLEET, "namespace: tb3_02}", "namespace: /tb3_01}")
    d = lab.only("RC505")
    assert "both use /tb3_01/odom (odometry)" in d.message
    assert "give them different namespaces, or put them on different domains" in d.message


def test_a_namespace_nested_in_another_clashes_where_their_names_meet(lab: Lab) -> None:
    lab.replace(GAZEBO, "name: camera/image_raw,", "name: camera/odom,")
    assert lab.check().diagnostics == []
    # tb3-01's camera/odom in tb3_01 is tb3-02's odom in tb3_01/camera.
    lab.replace(FLEET, "namespace: tb3_02}", "namespace: tb3_01/camera}")
    d = lab.only("RC505")
    assert d.line == lab.line_of(FLEET, "tb3-02:")
    assert "robots 'tb3-01' and 'tb3-02' both use /tb3_01/camera/odom (odometry)" in d.message


def test_a_name_at_the_root_clashes_with_one_in_a_namespace(lab: Lab) -> None:
    lab.replace(GAZEBO, "name: sim/bluetooth_rssi,", "name: sim/odom,")
    assert lab.check().diagnostics == []
    # tb3-03 without a namespace has /sim/odom, as tb3-02 has its odom in namespace sim.
    lab.replace(FLEET, ", namespace: tb3_03}", "}")
    lab.replace(FLEET, "namespace: tb3_02}", "namespace: sim}")
    d = lab.only("RC505")
    assert d.line == lab.line_of(FLEET, "tb3-03:")
    assert "robots 'tb3-02' and 'tb3-03' both use /sim/odom (bluetooth_rssi)" in d.message


def test_shared_services_other_worlds_and_platforms_do_not_clash(lab: Lab) -> None:
    # Two guides call the world's door controller (a service): shared on purpose.
    lab.replace(
        FLEET, "  tb3-04:", "  tb3-09: {scenario: guide-gazebo, namespace: guide2}\n  tb3-04:"
    )
    # One robot at the root of the world: alone there, nothing to clash with; the ROS 1 robot
    # (tb3-05: /cmd_vel, /odom) is on another graph, tb3-04 in another environment.
    lab.replace(FLEET, ", namespace: tb3_03}", "}")
    assert lab.check().diagnostics == []
    render = lab.render("tb3-09")
    assert render.scenario.capability.mappings["door_opener"].name == "/sim/door_controller/open"


def test_a_suspended_robot_clashes_with_no_one(lab: Lab) -> None:
    # tb3-04 patrols the lab at the root on absolute names; a second patroller there would
    # drive it, but a suspended one is left as it is: its assignment reaches it only later.
    clash = "  tb3-09: {scenario: patrol-real, namespace: other}\n  tb3-04:"
    lab.replace(FLEET, "  tb3-04:", clash)
    assert "robots 'tb3-09' and 'tb3-04' both use /navigate_to_pose" in lab.only("RC505").message
    lab.replace(FLEET, "namespace: other}", "namespace: other, suspended: true}")
    assert lab.check().diagnostics == []


ROBOTICS_LAB = "models/environments/RoboticsLab.yaml"
PATROL_CLASH = "robots 'tb3-04' and 'tb3-07' both use /navigate_to_pose (navigate_to_pose), /odom"


def test_two_robots_on_two_domains_share_no_graph_and_on_one_they_clash(lab: Lab) -> None:
    # The example lab: tb3-04 on RoboticsLab's domain (1), tb3-07 on its own (2), the same
    # scenario at the root on the same absolute names.
    assert lab.check().diagnostics == []
    tb3_04, tb3_07 = lab.render("tb3-04"), lab.render("tb3-07")
    assert (tb3_04.ros_domain_id, tb3_07.ros_domain_id) == (1, 2)
    assert tb3_04.scenario.capability.mappings == tb3_07.scenario.capability.mappings
    lab.replace(FLEET, "ros_domain_id: 2}", "ros_domain_id: 1}")
    d = lab.only("RC505")
    assert d.line == lab.line_of(FLEET, "tb3-07:")
    assert d.message == (
        f"{PATROL_CLASH} (odometry) in environment RoboticsLab (ROS2) on ROS domain 1: they "
        "would drive each other; write these names relative in mapping scheme ROS2/real-world "
        "(cmd_vel, not /cmd_vel) and give them namespaces (`namespace: tb3_04`, `namespace: "
        "tb3_07`), or put them on different domains (e.g. `ros_domain_id: 2` for 'tb3-07')"
    )


def test_an_environments_domain_is_the_default_of_its_robots(lab: Lab) -> None:
    lab.replace(FLEET, ", ros_domain_id: 2}", "}")  # tb3-07 on the lab's domain too
    assert "in environment RoboticsLab (ROS2) on ROS domain 1: " in lab.only("RC505").message
    lab.replace(ROBOTICS_LAB, "ros_domain_id: 1", "ros_domain_id: 7")
    assert " on ROS domain 7: " in lab.only("RC505").message
    lab.replace(FLEET, "name: Lab patrol,", "name: Lab patrol, ros_domain_id: 1,")  # its own wins
    assert lab.check().diagnostics == []
    assert (lab.render("tb3-04").ros_domain_id, lab.render("tb3-07").ros_domain_id) == (1, 7)


def test_an_unset_domain_is_ross_default_0(lab: Lab) -> None:
    lab.replace(ROBOTICS_LAB, "ros_domain_id: 1", "")
    lab.replace(FLEET, "ros_domain_id: 2}", "ros_domain_id: 0}")  # tb3-04 names none
    message = lab.only("RC505").message
    assert message.startswith(
        f"{PATROL_CLASH} (odometry) in environment RoboticsLab (ROS2) on ROS domain 0 (ROS's "
        "default, where a robot without `ros_domain_id` runs): they would drive each other"
    )
    assert message.endswith("(e.g. `ros_domain_id: 1` for 'tb3-07')")
    lab.replace(FLEET, "ros_domain_id: 0}", "ros_domain_id: 1}")
    assert lab.check().diagnostics == []
    assert lab.render("tb3-04").ros_domain_id is None  # not sent: the robot keeps its own


def test_a_domain_out_of_range_is_located_with_the_bound(lab: Lab) -> None:
    lab.replace(FLEET, "ros_domain_id: 2}", "ros_domain_id: 233}")
    d = lab.only("RC103")
    assert (d.path, d.line) == (FLEET, lab.line_of(FLEET, "tb3-07:"))
    assert d.message == "robots.tb3-07.ros_domain_id must be less than or equal to 232, got 233"
    lab.replace(FLEET, "ros_domain_id: 233}", "ros_domain_id: 2}")
    lab.replace(ROBOTICS_LAB, "ros_domain_id: 1", "ros_domain_id: '1'")
    d = lab.only("RC103")
    assert (d.path, d.line) == (ROBOTICS_LAB, lab.line_of(ROBOTICS_LAB, "ros_domain_id"))
    assert d.message == "ros_domain_id must be a whole number, got '1' (text)"
