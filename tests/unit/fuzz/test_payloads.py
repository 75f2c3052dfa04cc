"""Property: MQTT payloads (statuses, descriptions, launch requests) parse or fail cleanly."""

from __future__ import annotations

import json
from typing import Any

from hypothesis import given
from hypothesis import strategies as st
from pydantic import BaseModel, ValidationError

from robotconf.configurator.types import MappingBinding
from robotconf.contract.launch import (
    DIGEST_EXCLUDED,
    LaunchCapability,
    LaunchRequest,
    LaunchScenario,
    canonical_json,
    make_launch_request,
)
from robotconf.contract.safejson import PayloadError, parse_json, parse_object
from robotconf.contract.wire import AgentStatus, ReconcilerStatus, RobotDescription
from tests.unit.fuzz.strategies import json_values, mutated

MODELS: list[type[BaseModel]] = [AgentStatus, ReconcilerStatus, RobotDescription, LaunchRequest]


def parse_message(model: type[BaseModel], payload: bytes) -> BaseModel | None:
    """What every reader does with a retained payload: bounded parse, then the model."""
    try:
        return model.model_validate(parse_object(payload))
    except (PayloadError, ValidationError):
        return None


@given(st.sampled_from(MODELS), st.binary(max_size=300))
def test_any_bytes(model: type[BaseModel], payload: bytes) -> None:
    parse_message(model, payload)


@given(st.sampled_from(MODELS), json_values)
def test_any_json(model: type[BaseModel], value: Any) -> None:
    parse_message(model, json.dumps(value).encode())


@given(
    st.sampled_from(MODELS),
    st.dictionaries(
        st.sampled_from(
            [
                "robot_id",
                "state",
                "seq",
                "since",
                "digest",
                "pid",
                "restarts",
                "id",
                "name",
                "ready",
                "diagnostics",
                "apiVersion",
                "kind",
                "scenario",
                "issued_at",
                "signature",
                "message",
            ]
        ),
        json_values,
        max_size=8,
    ),
)
def test_known_fields_with_any_values(model: type[BaseModel], value: dict[str, Any]) -> None:
    parse_message(model, json.dumps(value).encode())


@given(st.integers(min_value=0, max_value=20_000), st.sampled_from(["[", '{"a":']))
def test_deep_payloads_are_refused_before_parsing(depth: int, opener: str) -> None:
    closer = "]" if opener == "[" else "}"
    payload = (opener * depth + "1" + closer * depth).encode()
    try:
        parse_json(payload)
    except PayloadError:
        assert depth > 64
    else:
        assert depth <= 64


def request_with(knowledge: dict[str, Any], settings: dict[str, Any]) -> LaunchRequest:
    capability = LaunchCapability(
        name="c",
        platform="ROS2",
        robot_template=None,
        mapping_scheme="gazebo",
        tasks=[],
        actions=[],
        logics={},
        mappings={"cmd_vel": MappingBinding(kind="topic", name="/cmd_vel", type="T")},
    )
    scenario = LaunchScenario(
        name="s",
        capability=capability,
        environment_name=None,
        environment_type=None,
        robot_settings=settings,
        logic_settings={},
        environment_knowledge=knowledge,
        goals=[],
    )
    return make_launch_request("tb3-01", "bot", "rev", scenario)


json_objects = st.dictionaries(st.text(max_size=10), json_values, max_size=5)


@given(json_objects, json_objects)
def test_a_rendered_request_round_trips(
    knowledge: dict[str, Any], settings: dict[str, Any]
) -> None:
    request = request_with(knowledge, settings)
    payload = request.payload()
    again = LaunchRequest.model_validate(parse_object(payload))
    assert again == request
    assert again.digest_matches()
    assert again.payload() == payload == canonical_json(json.loads(payload))


@given(json_objects.flatmap(lambda k: mutated(request_with(k, {}).payload())))
def test_a_mutated_request_never_passes_as_another(payload: bytes) -> None:
    """Whatever a flipped byte does, a request that still parses and matches its digest says
    exactly what its digest covers."""
    message = parse_message(LaunchRequest, payload)
    if isinstance(message, LaunchRequest) and message.digest_matches():
        assert canonical_json(message.content()) == canonical_json(
            {k: v for k, v in parse_object(payload).items() if k not in DIGEST_EXCLUDED}
        )


@given(st.one_of(st.binary(max_size=300), json_values.map(lambda v: json.dumps(v).encode())))
def test_an_interfaces_report_is_read_or_an_error_never_a_crash(payload: bytes) -> None:
    """A robot's interfaces report: a model, or `error` with a reason; drift then claims
    nothing from an unreadable one."""
    from robotconf.configurator.drift import Need, drift_of
    from robotconf.contract.wire import Topics
    from robotconf.readmodel.observed import parse_retained

    topics = Topics()
    robot = parse_retained({topics.interfaces("r1"): payload}, topics).robots.get("r1")
    if not payload:
        assert robot is None  # an empty retained message clears it: nothing reported
        return
    assert robot is not None
    assert (robot.interfaces is None) != (robot.interfaces_error is None)
    need = Need("odometry", "/odom", "topic", "nav_msgs/msg/Odometry")
    drift = drift_of("r1", [need], robot.interfaces, robot.interfaces_error)
    if robot.interfaces_error is not None:
        assert drift.interfaces == "error" and drift.items == ()
