"""Drafting a robot template and mapping scheme from reported interfaces (configurator/draft.py),
against the example lab's catalogue."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import pytest
import yaml

from robotconf.configurator.draft import (
    Bound,
    Draft,
    ReportError,
    catalogue,
    derive_name,
    draft,
    report_from,
    scheme_yaml,
    template_yaml,
)
from robotconf.configurator.loader import KIND_BY_NAME, load_file
from robotconf.configurator.types import (
    MappingBinding,
    MappingScheme,
    RobotTemplate,
    SettingDefinition,
)
from robotconf.configurator.workspace import check
from robotconf.contract.interfaces import MAX_INTERFACES, RobotInterfaces
from robotconf.contract.yamlio import parse_document
from tests.support.lab import ROOT


@pytest.fixture(scope="module")
def lab_catalogue() -> list[Bound]:
    return catalogue(check(ROOT).repo, "ROS2")


def report(
    topics: Sequence[tuple[str, str]] = (),
    services: Sequence[tuple[str, str]] = (),
    actions: Sequence[tuple[str, str]] = (),
) -> RobotInterfaces:
    def entries(pairs: Sequence[tuple[str, str]]) -> list[dict[str, str]]:
        return [{"name": name, "type": type_} for name, type_ in pairs]

    return RobotInterfaces.model_validate(
        {"topics": entries(topics), "services": entries(services), "actions": entries(actions)}
    )


def by_mapping(result: Draft) -> dict[str, MappingBinding]:
    return dict(result.scheme.mappings)


def test_interfaces_that_fit_take_the_catalogues_names(lab_catalogue: list[Bound]) -> None:
    """In namespace tb3_04 the gazebo scheme's relative names resolve to /tb3_04/...: those
    interfaces get its mapping names, written relative; /door_bridge/open fits real-world's
    absolute binding and stays absolute."""
    found = report(
        topics=[
            ("/tb3_04/scan", "sensor_msgs/msg/LaserScan"),
            ("/tb3_04/odom", "nav_msgs/msg/Odometry"),
            ("/tb3_04/cmd_vel", "geometry_msgs/Twist"),  # the short form is the same type
        ],
        services=[("/door_bridge/open", "std_srvs/srv/Trigger")],
        actions=[("/tb3_04/navigate_to_pose", "nav2_msgs/action/NavigateToPose")],
    )
    result = draft(found, lab_catalogue, "tb3_04")
    scheme = by_mapping(result)
    assert set(scheme) == {"scan", "odometry", "cmd_vel", "door_opener", "navigate_to_pose"}
    assert scheme["scan"] == MappingBinding(
        kind="topic", name="scan", type="sensor_msgs/msg/LaserScan"
    )
    assert scheme["odometry"].name == "odom"
    assert scheme["door_opener"] == MappingBinding(
        kind="service", name="/door_bridge/open", type="std_srvs/srv/Trigger"
    )
    assert scheme["navigate_to_pose"].kind == "action_client"
    assert sorted(result.template.mappings) == sorted(scheme)
    fits = {m.mapping: m.fits for m in result.mappings}
    assert fits["scan"] == ("ROS2/gazebo",) and fits["door_opener"] == ("ROS2/real-world",)


def test_without_a_namespace_absolute_names_fit_and_stay_absolute(
    lab_catalogue: list[Bound],
) -> None:
    result = draft(report(topics=[("/scan", "sensor_msgs/msg/LaserScan")]), lab_catalogue, None)
    assert by_mapping(result)["scan"].name == "/scan"
    # gazebo's relative `scan`, real-world's and ROS 1's `/scan` all resolve to /scan there.
    assert result.mappings[0].fits == ("ROS2/gazebo", "ROS2/real-world", "ROS1/gazebo-classic")


def test_a_name_outside_the_namespace_stays_absolute(lab_catalogue: list[Bound]) -> None:
    found = report(topics=[("/tb3_04x/scan", "sensor_msgs/msg/LaserScan"), ("/tb3_04", "a/B")])
    scheme = by_mapping(draft(found, lab_catalogue, "/tb3_04"))
    assert {b.name for b in scheme.values()} == {"/tb3_04x/scan", "/tb3_04"}


def test_another_type_or_name_gets_a_new_name_with_a_did_you_mean(
    lab_catalogue: list[Bound],
) -> None:
    found = report(
        topics=[
            ("/tb3_04/scan", "sensor_msgs/msg/PointCloud2"),  # the catalogue's scan is a LaserScan
            ("/tb3_04/front/scan", "sensor_msgs/msg/LaserScan"),
            ("/tb3_04/odometry", "nav_msgs/msg/Odometri"),
        ]
    )
    result = draft(found, lab_catalogue, "tb3_04")
    drafted = {m.reported: m for m in result.mappings}
    renamed = drafted["/tb3_04/scan"]
    # Never the catalogue's name for another type: logics needing `scan` expect a LaserScan.
    assert renamed.mapping == "scan_point_cloud2" and renamed.fits == ()
    front = drafted["/tb3_04/front/scan"]
    assert front.mapping == "front_scan"
    assert front.hint == "; did you mean 'scan' (same kind and type in the catalogue)?"
    assert drafted["/tb3_04/odometry"].hint == "; did you mean 'odometry'?"
    assert "scan" not in result.template.mappings


def test_one_catalogue_name_binds_one_interface(lab_catalogue: list[Bound]) -> None:
    """Two interfaces fitting `scan` (relative in the namespace, and the root's /scan): the
    first keeps it, the other gets a name of its own (RC607 would refuse a name twice)."""
    found = report(
        topics=[
            ("/scan", "sensor_msgs/msg/LaserScan"),
            ("/tb3_04/scan", "sensor_msgs/msg/LaserScan"),
        ]
    )
    result = draft(found, lab_catalogue, "tb3_04")
    names = [m.mapping for m in result.mappings]
    assert names == ["scan", "scan_laser_scan"]
    assert len(set(result.template.mappings)) == len(result.template.mappings)


def test_infrastructure_is_left_out(lab_catalogue: list[Bound]) -> None:
    found = report(
        topics=[
            ("/rosout", "rcl_interfaces/msg/Log"),
            ("/parameter_events", "rcl_interfaces/msg/ParameterEvent"),
            ("/tb3_04/controller_server/transition_event", "lifecycle_msgs/msg/TransitionEvent"),
            ("/bond", "bond/msg/Status"),
            ("/tb3_04/_hidden/debug", "std_msgs/msg/String"),
            ("/tb3_04/scan", "sensor_msgs/msg/LaserScan"),
        ],
        services=[
            ("/tb3_04/turtlebot3_node/get_parameters", "rcl_interfaces/srv/GetParameters"),
            ("/tb3_04/turtlebot3_node/set_parameters_atomically", "x/srv/Odd"),
            ("/tb3_04/node/get_type_description", "type_description_interfaces/srv/Get"),
            ("/tb3_04/controller_server/get_state", "lifecycle_msgs/srv/GetState"),
        ],
    )
    result = draft(found, lab_catalogue, "tb3_04")
    assert [m.mapping for m in result.mappings] == ["scan"]
    assert result.infrastructure == 9 and result.left_out == []


def test_invalid_names_and_types_are_left_out_with_why(lab_catalogue: list[Bound]) -> None:
    found = report(
        topics=[
            ("/a: b", "std_msgs/msg/String"),
            ("/x__y", "std_msgs/msg/String"),
            ("relative", "std_msgs/msg/String"),
            ("/ok", "std_msgs/msg/String\n- evil: 1"),
            ("/fine", "std_msgs/msg/String"),
        ]
    )
    result = draft(found, lab_catalogue, None)
    assert [m.mapping for m in result.mappings] == ["fine"]
    why = {out.name: out.reason for out in result.left_out}
    assert "':'" in why["/a: b"] and "repeated underscore" in why["/x__y"]
    assert "fully qualified" in why["relative"] and "not an interface type" in why["/ok"]


def test_derived_names_are_snake_case_and_unique() -> None:
    assert derive_name("camera/image_raw/compressed", "x/msg/Y", set()) == "image_raw_compressed"
    assert derive_name("/Lidar/PointCloudFront", "x/msg/Y", set()) == "lidar_point_cloud_front"
    assert derive_name("/3d/9points", "x/msg/Y", set()) == "m_3d_9points"
    taken = {"scan", "scan_laser_scan", "scan_laser_scan_2"}
    assert derive_name("scan", "sensor_msgs/msg/LaserScan", taken) == "scan_laser_scan_3"


def load_text(kind: str, path: str, text: str) -> Any:
    loaded = load_file(path, text.encode("utf-8"), KIND_BY_NAME[kind], ("ROS2", "drafted"))
    assert loaded.diagnostics == (), loaded.diagnostics
    assert loaded.entry is not None
    return loaded.entry.model


ODD_NAMES = [
    "yes",
    "on",
    "1.0",
    "0x10",
    "~",
    "null",
    "a: b",
    "#x",
    "- y",
    "'q'",
    '"d"',
    "é",
    "{z}",
    "line\u2028sep",
    "bell\x07",
]


def test_odd_catalogue_names_are_quoted_and_read_back_the_same() -> None:
    """Catalogue names are any text: each reads back from the drafted files as itself."""
    bounds = [
        Bound(name, MappingBinding(kind="topic", name=f"/t{i}", type="std_msgs/msg/String"), "P/s")
        for i, name in enumerate(ODD_NAMES)
    ]
    found = report(topics=[(f"/t{i}", "std_msgs/msg/String") for i in range(len(ODD_NAMES))])
    settings = {
        "yes": SettingDefinition(type="enum", default="on", choices=["on", "off", 1.5, True])
    }
    result = draft(found, bounds, None, description="a: b # not a comment\nnext", settings=settings)
    assert sorted(result.template.mappings) == sorted(ODD_NAMES)
    template = load_text(
        "robot-template",
        "models/platforms/ROS2/robot-templates/d.yaml",
        template_yaml(result.template, "../s", "line one\nline two"),
    )
    scheme = load_text(
        "mapping-scheme",
        "models/platforms/ROS2/mapping-schemes/d.yaml",
        scheme_yaml(result.scheme, "../s", "c"),
    )
    assert template == result.template and scheme == result.scheme
    assert isinstance(template, RobotTemplate) and isinstance(scheme, MappingScheme)


def test_the_files_carry_the_editor_modeline() -> None:
    text = template_yaml(RobotTemplate(mappings=["scan"]), "../../../../schemas/x.json", "c")
    assert text.startswith("# yaml-language-server: $schema=../../../../schemas/x.json\n# c\n")


def test_a_long_report_drafts_every_interface_within_the_reader_s_bounds() -> None:
    found = report(
        topics=[(f"/sensor_{i}/data", "std_msgs/msg/Float32") for i in range(MAX_INTERFACES)]
    )
    result = draft(found, [], "robot")
    assert len(result.mappings) == MAX_INTERFACES
    text = scheme_yaml(result.scheme, "../s", "c")
    doc = parse_document("models/platforms/P/mapping-schemes/s.yaml", text.encode("utf-8"))
    assert len(doc.data["mappings"]) == MAX_INTERFACES
    assert yaml.safe_load(template_yaml(result.template, "../s", "c"))["mappings"][-1] == (
        "sensor_999_data"
    )


def test_the_report_is_bounded_and_checked() -> None:
    entry = {"name": "/a", "type": "std_msgs/msg/String"}
    with pytest.raises(ReportError, match="over the bound"):
        report_from({"topics": [entry] * (MAX_INTERFACES + 1)})
    with pytest.raises(ReportError, match=r"topics\.0\.name"):
        report_from({"topics": [{"name": "/" + "a" * 300, "type": "x/y"}]})
    with pytest.raises(ReportError, match="topics"):
        report_from({"topics": "nope"})
    assert report_from({"topics": [entry], "future_field": 1}).topics[0].name == "/a"


def test_the_catalogue_lists_the_platform_s_schemes_first() -> None:
    bounds = catalogue(check(ROOT).repo, "ROS2")
    assert bounds[0].where.startswith("ROS2/") and bounds[-1].where == "ROS1/gazebo-classic"
    assert {b.mapping for b in bounds} >= {"scan", "cmd_vel", "door_opener"}
