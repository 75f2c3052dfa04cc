"""The Launch Request's single definitions: what its digest covers, and the template warning
that the agent's admission and the fleet status share."""

from __future__ import annotations

import hashlib
import json
from typing import Any

import pytest
from pydantic import BaseModel, ValidationError

from robotconf.agent.admission import Accept, interpret
from robotconf.contract.launch import (
    CONTENT_WHEN_SET,
    DIGEST_EXCLUDED,
    LaunchRequest,
    content_digest,
    digest_content,
    restart_digest_of,
    template_mismatch,
    with_digest,
)
from robotconf.contract.wire import AgentState, AgentStatus, RobotDescription
from robotconf.readmodel.observed import RobotSeen
from robotconf.readmodel.verdicts import DesiredRobot, template_warning
from tests.support.agents import make_request


class AnnotatedRequest(LaunchRequest):
    """A request as a later version might extend it: one more field of content."""

    note: str = ""


def test_a_field_added_to_the_request_is_covered_by_render_and_check_alike() -> None:
    plain = make_request()
    annotated = with_digest(AnnotatedRequest(**dict(plain), note="lidar recalibrated"))
    assert annotated.digest_matches()  # sealed on rendering's path, verified on the agent's
    assert annotated.digest != plain.digest  # the new field is content
    received = AnnotatedRequest.model_validate_json(annotated.payload())
    assert received == annotated and received.digest_matches()
    tampered = received.model_copy(update={"note": "not recalibrated"})
    assert not tampered.digest_matches()


def _other(name: str, value: Any) -> Any:
    """A different value of the same type; a field of a new type must be taught here."""
    if name == "namespace":  # content only when set: None to a namespace, one to another
        return "/tb3_02" if value is None else value + "_b"
    if name == "ros_domain_id":  # the same: None to a domain, one to another
        return 3 if value is None else value + 1
    if isinstance(value, str):
        return value + "~"
    if isinstance(value, float):
        return value + 1.0
    if isinstance(value, BaseModel) and isinstance(getattr(value, "name", None), str):
        return value.model_copy(update={"name": value.name + "~"})  # type: ignore[attr-defined]
    pytest.fail(f"field {name!r} holds a {type(value).__name__}: teach _other to change it")


def test_every_field_but_the_documented_exclusions_changes_the_digest() -> None:
    assert {"revision", "digest", "restart_digest", "issued_at", "signature"} == DIGEST_EXCLUDED
    request = make_request().model_copy(update={"issued_at": 1.0e9, "signature": "c2ln"})
    assert set(dict(request)) == set(LaunchRequest.model_fields)  # every field is visited
    digest = content_digest(digest_content(request))
    for name, value in request:
        changed = request.model_copy(update={name: _other(name, value)})
        moved = content_digest(digest_content(changed)) != digest
        assert moved is (name not in DIGEST_EXCLUDED), name


def test_restart_digest_covers_the_capability_only() -> None:
    request = make_request()
    assert request.restart_digest == restart_digest_of(request) and request.digest_matches()
    # Settings, knowledge, goals, the robot's name: a new digest, the same restart digest.
    scenario = request.scenario.model_copy(
        update={"environment_knowledge": {"shelf": 3}, "goals": [], "name": "night-shift"}
    )
    reloadable = with_digest(request.model_copy(update={"scenario": scenario, "robot_name": "x"}))
    assert reloadable.digest != request.digest
    assert reloadable.restart_digest == request.restart_digest
    # A logic, the mappings, the platform or scheme: a new restart digest.
    for change in (
        {"logics": {"Follow": "follow_by_spinning"}},
        {"mappings": {}},
        {"platform": "ROS1"},
        {"mapping_scheme": "real-world"},
    ):
        capability = request.scenario.capability.model_copy(update=change)
        moved = with_digest(
            request.model_copy(
                update={"scenario": request.scenario.model_copy(update={"capability": capability})}
            )
        )
        assert moved.restart_digest != request.restart_digest, change
        assert moved.digest != request.digest, change


def test_a_wrong_restart_digest_fails_the_check_and_a_missing_one_passes() -> None:
    request = make_request()
    other = make_request(template=None).restart_digest
    assert other != request.restart_digest
    assert not request.model_copy(update={"restart_digest": other}).digest_matches()
    # An older reconciler's request: no restart_digest on the wire at all, same digest.
    older = request.model_copy(update={"restart_digest": None})
    assert "restart_digest" not in json.loads(older.payload())
    received = LaunchRequest.model_validate_json(older.payload())
    assert received.restart_digest is None and received.digest_matches()
    assert received.digest == request.digest


def test_template_mismatch_words() -> None:
    assert template_mismatch("turtlebot3-burger", None) is None
    assert template_mismatch("turtlebot3-burger", "turtlebot3-burger") is None
    assert template_mismatch("turtlebot3-burger", "turtlebot3-camera") == (
        "assigned robot template 'turtlebot3-burger' differs from the robot's recommended "
        "'turtlebot3-camera'"
    )
    assert template_mismatch(None, "turtlebot3-camera") == (
        "the assigned capability names no robot template; the robot recommends 'turtlebot3-camera'"
    )


@pytest.mark.parametrize("template", ["turtlebot3-burger", None])
def test_agent_and_fleet_status_warn_in_the_same_words_once(template: str | None) -> None:
    robot = RobotDescription(id="tb3-01", platform="ROS2", recommended_template="turtlebot3-camera")
    request = make_request(template=template)
    admitted = interpret(request.payload(), robot)
    assert isinstance(admitted, Accept) and len(admitted.warnings) == 1
    desired = DesiredRobot("tb3-01", "delivery-gazebo", request.digest, template=template)
    before_report = RobotSeen(description=robot)
    assert template_warning(desired, before_report) == admitted.warnings[0]
    status = AgentStatus(
        robot_id="tb3-01",
        state=AgentState.RUNNING,
        digest=request.digest,
        warnings=admitted.warnings,
    )
    # Once the agent reports it, the status row carries the agent's line only.
    assert template_warning(desired, RobotSeen(status=status, description=robot)) is None


def test_strict_requests_still_take_json_as_the_agent_receives_it() -> None:
    signed = make_request().model_copy(update={"issued_at": 1.7e9, "signature": "c2ln"})
    data = json.loads(signed.payload())
    assert LaunchRequest.model_validate(data) == signed
    data["issued_at"] = 1700000000  # JSON has one number type: an integral time is an int
    assert LaunchRequest.model_validate(data).issued_at == 1.7e9
    data["issued_at"] = "1700000000"  # text is no number, on the wire as in YAML
    with pytest.raises(ValidationError, match="issued_at"):
        LaunchRequest.model_validate(data)


def test_a_namespace_is_content_and_restart_content_only_when_set() -> None:
    assert CONTENT_WHEN_SET == ("namespace", "ros_domain_id")
    plain = make_request()
    assert plain.namespace is None
    # Unset: not on the wire and not digested, so an agent that predates the field accepts
    # the request, and a robot without a namespace keeps its digests.
    assert "namespace" not in json.loads(plain.payload())
    assert "namespace" not in digest_content(plain)
    received = LaunchRequest.model_validate_json(plain.payload())
    assert received == plain and received.digest_matches()
    # Set: published, digested, and a restart (a brain's nodes cannot move namespace in place).
    placed = with_digest(plain.model_copy(update={"namespace": "/tb3_01"}))
    assert json.loads(placed.payload())["namespace"] == "/tb3_01"
    assert placed.digest != plain.digest and placed.restart_digest != plain.restart_digest
    moved = with_digest(placed.model_copy(update={"namespace": "/tb3_02"}))
    assert moved.restart_digest != placed.restart_digest
    back = LaunchRequest.model_validate_json(placed.payload())
    assert back == placed and back.digest_matches()
    # Tampering with the namespace on the way fails the agent's check.
    data = json.loads(placed.payload())
    data["namespace"] = "/tb3_09"
    assert not LaunchRequest.model_validate(data).digest_matches()


# The digests and payload of `make_request()` (and with a namespace) before ros_domain_id
# existed: a robot without a domain keeps its request byte for byte, so upgrading the
# reconciler restarts no brain.
BEFORE_DOMAINS = {
    None: (
        "sha256:3f6365fd221ee9a9f73a4e62caa8dd70077fc2bd59ed52132644aa5c355e2745",
        "sha256:d60d5166f7d4c7c0cc08862b3dc5f89a866fb006ec4fe792b03c9953df5914a2",
        "9632729b93c7e80b9fe9c6570d2e4eb252984cdb8fba584fb0338f1ff93e6063",
    ),
    "/tb3_01": (
        "sha256:badf94bbb00de9ba76a3bdb2beda123cc6de8e0ac6c28baf11303f92bc758dd5",
        "sha256:b1437b1801fbe738647089019d26f5ae0f64f1b7e956af511305f5cfd4b6da7e",
        "e762cc3809921621e66fcc67454140bfcca5e45b90e00252b9d6432547fccd09",
    ),
}


@pytest.mark.parametrize("namespace", list(BEFORE_DOMAINS))
def test_a_request_without_a_domain_is_byte_for_byte_what_it_was(namespace: str | None) -> None:
    request = with_digest(make_request().model_copy(update={"namespace": namespace}))
    assert request.ros_domain_id is None
    payload = request.payload()
    assert b"ros_domain_id" not in payload
    found = (request.digest, request.restart_digest, hashlib.sha256(payload).hexdigest())
    assert found == BEFORE_DOMAINS[namespace]


def test_a_domain_is_content_and_restart_content_only_when_set() -> None:
    plain = make_request()
    placed = with_digest(plain.model_copy(update={"ros_domain_id": 0}))
    # Set, even to ROS's default 0: published, digested, and a restart, never a reload (a
    # process joins its DDS domain when it starts).
    assert json.loads(placed.payload())["ros_domain_id"] == 0
    assert placed.digest != plain.digest and placed.restart_digest != plain.restart_digest
    moved = with_digest(placed.model_copy(update={"ros_domain_id": 1}))
    assert moved.digest != placed.digest and moved.restart_digest != placed.restart_digest
    # Beside a namespace: each part of the restart content.
    named = with_digest(plain.model_copy(update={"namespace": "/tb3_01"}))
    both = with_digest(named.model_copy(update={"ros_domain_id": 1}))
    assert len({named.restart_digest, both.restart_digest, moved.restart_digest}) == 3
    back = LaunchRequest.model_validate_json(both.payload())
    assert back == both and back.digest_matches()
    data = json.loads(both.payload())
    data["ros_domain_id"] = 2  # tampered with on the way
    assert not LaunchRequest.model_validate(data).digest_matches()


@pytest.mark.parametrize("domain", [-1, 233, "1", True, 1.0])
def test_a_domain_is_an_integer_from_0_to_232(domain: Any) -> None:
    data = json.loads(with_digest(make_request()).payload())
    data["ros_domain_id"] = domain
    with pytest.raises(ValidationError, match="ros_domain_id"):
        LaunchRequest.model_validate(data)
