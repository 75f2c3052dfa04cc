"""What a launch-topic payload means for this robot, decided without a broker."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from robotconf.agent.admission import (
    AHEAD_LOOK,
    MAX_ISSUED_AHEAD,
    Accept,
    Admission,
    Clear,
    Freshness,
    Reject,
    Verifier,
    interpret,
    look_again_in,
)
from robotconf.agent.workdir import IssuedStore
from robotconf.contract.launch import LaunchRequest, StopRequest, canonical_json
from robotconf.contract.signing import (
    generate_keys,
    load_private_key,
    load_public_key,
    sign,
    verify_object,
)
from robotconf.contract.wire import RobotDescription
from tests.support.agents import make_request

ROBOT = RobotDescription(
    id="tb3-01", name="Delivery bot", recommended_template="turtlebot3-camera", platform="ROS2"
)


@pytest.mark.parametrize("payload", [b"", b"  \n"])
def test_empty_payload_clears(payload: bytes) -> None:
    assert interpret(payload, ROBOT) == Clear()


def test_valid_request_is_accepted_without_warnings() -> None:
    request = make_request()
    outcome = interpret(request.payload(), ROBOT)
    assert outcome == Accept(request, [])


def test_a_request_whose_action_selects_several_logics_is_accepted() -> None:
    """Multi-logic actions arrive as a list of logic names; the agent's models take both forms."""
    request = make_request(logic=["follow_with_poses", "follow_with_bluetooth"])
    outcome = interpret(request.payload(), ROBOT)
    assert outcome == Accept(request, [])
    assert isinstance(outcome, Accept)
    assert outcome.request.scenario.capability.logics["Follow"] == [
        "follow_with_poses",
        "follow_with_bluetooth",
    ]


def reason(payload: bytes, robot: RobotDescription = ROBOT) -> str:
    outcome = interpret(payload, robot)
    assert isinstance(outcome, Reject), outcome
    return outcome.reason


def test_another_robots_request_is_rejected() -> None:
    assert "'tb3-02'" in reason(make_request(robot_id="tb3-02").payload())


@pytest.mark.parametrize("payload", [b"{", b"\xff\xfe", b"[1, 2"])
def test_malformed_json_is_rejected(payload: bytes) -> None:
    assert reason(payload).startswith("malformed launch request")


def test_non_object_is_rejected() -> None:
    assert "JSON object" in reason(b"[1, 2]")


@pytest.mark.parametrize("version", ["robotconf/v2", None])
def test_unknown_api_version_is_rejected(version: str | None) -> None:
    data = json.loads(make_request().payload())
    data["apiVersion"] = version
    assert "unknown apiVersion" in reason(json.dumps(data).encode())


def test_schema_violations_are_rejected_with_the_field() -> None:
    data = json.loads(make_request().payload())
    del data["scenario"]["capability"]["platform"]
    data["surprise"] = 1
    text = reason(json.dumps(data).encode())
    assert "scenario.capability.platform" in text and "surprise" in text


def test_a_rejection_names_the_field_as_agent_yaml_and_validate_do() -> None:
    data = json.loads(make_request().payload())
    data["scenario"]["capability"]["tasks"] = ["Delivery", 7]
    assert "scenario.capability.tasks[1] must be text, got 7 (a whole number)" in reason(
        json.dumps(data).encode()
    )


def test_tampered_content_is_rejected_by_its_digest() -> None:
    data = json.loads(make_request().payload())
    data["scenario"]["robot_settings"]["max_linear_speed"] = 9.9
    assert "does not match" in reason(json.dumps(data).encode())


def test_other_platform_is_rejected_only_when_the_robot_declares_one() -> None:
    ros1 = make_request(platform="ROS1").payload()
    assert "platform 'ROS1'" in reason(ros1)
    anything = ROBOT.model_copy(update={"platform": None})
    assert isinstance(interpret(ros1, anything), Accept)


def test_other_template_is_a_warning() -> None:
    outcome = interpret(make_request(template="turtlebot3-burger").payload(), ROBOT)
    assert isinstance(outcome, Accept)
    assert len(outcome.warnings) == 1 and "turtlebot3-burger" in outcome.warnings[0]
    outcome = interpret(make_request(template=None).payload(), ROBOT)
    assert isinstance(outcome, Accept) and "names no robot template" in outcome.warnings[0]
    no_preference = ROBOT.model_copy(update={"recommended_template": None})
    outcome = interpret(make_request(template="turtlebot3-burger").payload(), no_preference)
    assert outcome == Accept(make_request(template="turtlebot3-burger"), [])


def test_signatures_are_checked_when_the_agent_has_a_key(tmp_path: Path) -> None:
    pair = generate_keys(tmp_path)
    public = load_public_key(pair.public)

    def check(data: dict[str, Any]) -> str | None:
        return verify_object(data, public)

    signed = sign(make_request(), load_private_key(pair.private))
    assert interpret(signed.payload(), ROBOT, check) == Accept(signed, [])
    assert "not signed" in reason_with(make_request().payload(), check)
    data = json.loads(signed.payload())
    data["revision"] = "another-commit"  # outside the digest, inside the signature
    assert "does not verify" in reason_with(canonical_json(data), check)
    # The very bytes that were signed, nothing else: no white space or escapes ride along.
    assert "canonical JSON form" in reason_with(
        json.dumps(json.loads(signed.payload())).encode(), check
    )


def reason_with(payload: bytes, check: Verifier) -> str:
    outcome = interpret(payload, ROBOT, check)
    assert isinstance(outcome, Reject), outcome
    return outcome.reason


def test_an_older_signed_request_is_a_replay_unless_it_is_the_running_one(tmp_path: Path) -> None:
    pair = generate_keys(tmp_path)
    public, private = load_public_key(pair.public), load_private_key(pair.private)

    def check(data: dict[str, Any]) -> str | None:
        return verify_object(data, public)

    old = sign(make_request(), private, issued_at=1000.0)
    new = sign(make_request(template="turtlebot3-burger"), private, issued_at=2000.0)
    assert old.digest != new.digest
    running_new = Freshness(newest_issued_at=2000.0, running_digest=new.digest)
    outcome = interpret(old.payload(), ROBOT, check, running_new)
    assert isinstance(outcome, Reject) and "replayed request" in outcome.reason
    # The request it runs, re-sent (a retained redelivery after a reconnect), is harmless.
    assert isinstance(interpret(new.payload(), ROBOT, check, running_new), Accept)
    # A newer one is accepted; so is anything when nothing was accepted yet.
    newer = sign(make_request(), private, issued_at=3000.0)
    assert isinstance(interpret(newer.payload(), ROBOT, check, running_new), Accept)
    assert isinstance(interpret(old.payload(), ROBOT, check, Freshness(None, None)), Accept)
    # Even after the robot was stopped, the old request cannot bring it back.
    stopped = Freshness(newest_issued_at=2000.0, running_digest=None)
    assert isinstance(interpret(old.payload(), ROBOT, check, stopped), Reject)


def test_a_fast_clock_cannot_lock_out_later_requests_and_replays_stay_refused(
    tmp_path: Path,
) -> None:
    """A request dated more than MAX_ISSUED_AHEAD ahead of the robot's clock is refused, so the
    watermark never runs far ahead: a correct clock's next request is accepted; a replay of
    what was accepted is refused as before."""
    pair = generate_keys(tmp_path)
    public, private = load_public_key(pair.public), load_private_key(pair.private)

    def check(data: dict[str, Any]) -> str | None:
        return verify_object(data, public)

    now = 1_700_000_000.0
    store = IssuedStore(tmp_path / "newest")

    def admit(request: LaunchRequest, at: float, running: str | None = None) -> Admission:
        outcome = interpret(request.payload(), ROBOT, check, Freshness(store.newest, running, at))
        if isinstance(outcome, Accept):
            store.accepted(outcome.request.issued_at)
        return outcome

    # A reconciler an hour fast: refused, and the watermark does not move.
    fast = sign(make_request(variant=1), private, issued_at=now + 3600)
    refused = admit(fast, now)
    assert isinstance(refused, Reject) and "ahead of this robot's clock" in refused.reason
    assert "check NTP" in refused.reason and store.newest is None
    assert refused.retry_at == now + 3600 - MAX_ISSUED_AHEAD  # when it is no longer too far ahead
    assert look_again_in(refused, now) == AHEAD_LOOK + 0.05  # NTP may fix the clock before
    assert look_again_in(refused, now + 3600 - MAX_ISSUED_AHEAD - 2) == 2 + 0.05
    # Its clock fixed, its next request is accepted at once.
    fixed = sign(make_request(variant=2), private, issued_at=now + 5)
    assert isinstance(admit(fixed, now + 4), Accept) and store.newest == now + 5
    # A little ahead (within the bound) is accepted, and locks out at most that long:
    # a correct clock's request MAX_ISSUED_AHEAD later is newer than the watermark.
    ahead = sign(make_request(variant=3), private, issued_at=now + 100 + 29)
    assert isinstance(admit(ahead, now + 100), Accept)
    after = sign(make_request(variant=4), private, issued_at=now + 100 + MAX_ISSUED_AHEAD)
    assert isinstance(admit(after, now + 100 + MAX_ISSUED_AHEAD - 0.5), Accept)
    # Replays of what was accepted stay refused, whenever they come.
    for old in (fixed, ahead):
        for at in (now + 200, now + 10**6):
            replayed = admit(old, at, running=after.digest)
            assert isinstance(replayed, Reject) and "replayed request" in replayed.reason
    # The running request re-sent (a retained redelivery) stays harmless.
    assert isinstance(admit(after, now + 10**6, running=after.digest), Accept)


def test_the_newest_issue_time_survives_an_agent_restart(tmp_path: Path) -> None:
    store = IssuedStore(tmp_path / "newest")
    assert store.newest is None
    store.accepted(2000.5)
    store.accepted(1000.0)  # never goes back
    assert IssuedStore(tmp_path / "newest").newest == 2000.5
    assert (tmp_path / "newest").stat().st_mode & 0o777 == 0o600


@pytest.fixture
def keyed(tmp_path: Path) -> tuple[Any, Verifier]:
    pair = generate_keys(tmp_path)
    public = load_public_key(pair.public)
    return load_private_key(pair.private), lambda data: verify_object(data, public)


def test_with_a_key_only_a_signed_stop_stops(keyed: tuple[Any, Verifier]) -> None:
    private, check = keyed
    assert "unsigned stop refused" in reason_with(b"", check)
    assert "not signed" in reason_with(
        StopRequest(robot_id="tb3-01", revision="r").payload(), check
    )
    stop = sign(StopRequest(robot_id="tb3-01", revision="r"), private, issued_at=5000.0)
    assert interpret(stop.payload(), ROBOT, check) == Clear(5000.0)
    other = sign(StopRequest(robot_id="tb3-02", revision="r"), private)
    assert "for robot 'tb3-02'" in reason_with(other.payload(), check)
    # An old stop cannot undo a newer request either.
    stale = interpret(stop.payload(), ROBOT, check, Freshness(6000.0, "sha256:running"))
    assert isinstance(stale, Reject) and "replayed request" in stale.reason


def test_without_a_key_an_unsigned_stop_stops() -> None:
    assert interpret(StopRequest(robot_id="tb3-01", revision="r").payload(), ROBOT) == Clear()


@pytest.mark.parametrize(
    "payload",
    [
        b"[" * 100_000 + b"]" * 100_000,
        b'{"apiVersion": "robotconf/v1", "issued_at": Infinity}',
        b'{"apiVersion": "robotconf/v1", "robot_id": "tb3-01", "issued_at": 1e999}',
        b'{"apiVersion": "robotconf/v1", "robot_id": "tb3-01", "y": "\\ud800"}',
        b'{"apiVersion": "robotconf/v1", "robot_id": "tb3-01", "n": ' + b"9" * 5000 + b"}",
        b'{"apiVersion": "robotconf/v1", "robot_id": null}',
        b'{"apiVersion": "robotconf/v1", "robot_id": "tb3-01", "robot_id": "tb3-01"}',
        b'{"apiVersion": "' + b"v" * 2_000_000 + b'"}',
        b'{"apiVersion": ["robotconf/v1"]}',
    ],
)
def test_hostile_payloads_are_rejected_with_a_short_reason(
    payload: bytes, keyed: tuple[Any, Verifier]
) -> None:
    for check in (None, keyed[1]):
        outcome = interpret(payload, ROBOT, check)
        assert isinstance(outcome, Reject), outcome
        assert len(outcome.reason) < 500


@pytest.mark.parametrize("issued_at", [1e308, -1e308, 0.0, 2**62])
def test_replay_checks_survive_any_signed_time(
    issued_at: float, keyed: tuple[Any, Verifier]
) -> None:
    private, check = keyed
    signed = sign(make_request(), private, issued_at=issued_at)
    outcome = interpret(signed.payload(), ROBOT, check, Freshness(1e300, None))
    assert isinstance(outcome, (Accept, Reject))
    outcome = interpret(signed.payload(), ROBOT, check, Freshness(-1e300, None))
    assert isinstance(outcome, (Accept, Reject))
