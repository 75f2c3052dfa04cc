"""Rendering keeps each robot's request as its own values over its scenario's bytes: the
payload and digests must be exactly those of the whole request serialised (what the agent
checks), whatever the text of the scenario or of the robot."""

from __future__ import annotations

import json
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robotconf.configurator.render import FleetRender, RenderError, render_fleet, request_for
from robotconf.configurator.rendered import _SLOT_NAMES, FleetRequests, ScenarioRequests, _prefix
from robotconf.configurator.rosnames import UnresolvableName, resolve_name
from robotconf.configurator.types import MappingBinding
from robotconf.configurator.workspace import check
from robotconf.contract.launch import (
    LaunchRequest,
    LaunchScenario,
    make_launch_request,
    restart_digest_of,
    with_digest,
)
from tests.support.lab import ROOT


def _example_fleet() -> FleetRender:
    checked = check(ROOT)
    assert checked.ok, checked.errors
    return render_fleet(checked.repo)


def _shared() -> LaunchScenario:
    """A scenario of the example lab, as its robots share it (names unresolved)."""
    request = next(iter(_example_fleet().requests.values()))
    return request.scenario_requests.scenario


Robot = tuple[str, str, str, str | None] | tuple[str, str, str, str | None, int | None]


def _whole(scenario: LaunchScenario, robot: Robot) -> LaunchRequest:
    """The request made the plain way: resolved, built as a model, serialised whole."""
    robot_id, name, revision, namespace, *domain = robot
    capability = scenario.capability
    mappings = {
        key: b.model_copy(update={"name": resolve_name(b.name, namespace)})
        for key, b in capability.mappings.items()
    }
    resolved = scenario.model_copy(
        update={"capability": capability.model_copy(update={"mappings": mappings})}
    )
    return make_launch_request(robot_id, name, revision, resolved, namespace, *domain)


def _assert_same(scenario: LaunchScenario, robot: Robot) -> None:
    robot_id, name, revision, namespace, *domain = robot
    made = ScenarioRequests(scenario).request(robot_id, name, revision, namespace, *domain)
    whole = _whole(scenario, robot)
    assert made.payload() == whole.payload()
    assert (made.digest, made.restart_digest) == (whole.digest, whole.restart_digest)
    model = made.model()
    assert model == whole and model.payload() == whole.payload()
    received = LaunchRequest.model_validate_json(made.payload())  # as the agent reads it
    assert received.digest_matches() and received.restart_digest == restart_digest_of(received)


def test_every_request_of_the_example_fleet_is_the_whole_request() -> None:
    """With a namespace and without, with a ROS domain and without; payload, digests and
    model."""
    rendered = _example_fleet()
    assert {r.namespace is None for r in rendered.requests.values()} == {True, False}
    assert {r.ros_domain_id is None for r in rendered.requests.values()} == {True, False}
    for request in rendered.requests.values():
        model = request.model()
        assert model == with_digest(model) and model.digest_matches()
        assert request.payload() == model.payload()
        received = LaunchRequest.model_validate_json(request.payload())
        assert received == model and received.digest_matches()


@pytest.mark.parametrize(
    ("robot_name", "namespace", "knowledge"),
    [
        ('quotes " \\ and é 漢字 \u2028', None, {}),
        ("tab\tnewline\n", "/lab/bots", {"text": "\x00robotconf0:robot_id\x00"}),
        ("\x00robotconf0:robot_name\x00", "/x", {"a": ["\x00robotconf0:mappings\x00"]}),
        ("plain", "/ns", {"k": '"\\u0000robotconf0:robot_id\\u0000"'}),
        ("plain", None, {"\x00robotconf0:namespace\x00": 1, "\x00robotconf1:": 2}),
        ("\x00robotconf0:", "/robotconf0", {"\x00": "\x00\x00robotconf0:scenario\x00"}),
    ],
)
def test_values_that_look_like_slots_or_need_escaping(
    robot_name: str, namespace: str | None, knowledge: dict[str, Any]
) -> None:
    """Text of the scenario that holds a slot's mark moves the slots to another mark; text of
    the robot's goes in escaped as the whole request's serialisation escapes it."""
    # Written with this process's own marks: "\x00robotconf0:" stands for the first one.
    knowledge, robot_name = _marked(knowledge), _marked(robot_name)
    shared = _shared().model_copy(update={"environment_knowledge": knowledge})
    _assert_same(shared, ("tb3-09", robot_name, "r", namespace))


def _marked(value: Any) -> Any:
    if isinstance(value, str):
        return value.replace("\x00robotconf0:", _prefix(0)).replace("\x00robotconf1:", _prefix(1))
    if isinstance(value, dict):
        return {_marked(k): _marked(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_marked(v) for v in value]
    return value


def test_marks_a_commit_can_write_cost_no_retries(monkeypatch: pytest.MonkeyPatch) -> None:
    """A commit cannot know the marks this process uses: text full of would-be marks is
    serialised once, not once per mark it holds."""
    base = _shared()
    made: list[int] = []
    real = ScenarioRequests._make

    def counted(self: ScenarioRequests, with_namespace: bool, domain: bool, mark: int) -> Any:
        made.append(mark)
        return real(self, with_namespace, domain, mark)

    monkeypatch.setattr(ScenarioRequests, "_make", counted)
    guesses = {f"\x00robotconf{i}:": f"\x00robotconf{i}:scenario\x00" for i in range(500)}
    shared = base.model_copy(update={"environment_knowledge": guesses})
    _assert_same(shared, ("tb3-09", "bot", "r", "/tb3_09", 7))
    assert made == [0]
    made.clear()
    held = {_prefix(i): i for i in range(3)}  # this process's own: the next mark is tried
    _assert_same(base.model_copy(update={"environment_knowledge": held}), ("a", "b", "r", None))
    assert made == [0, 1, 2, 3]


def test_a_scenario_without_mappings() -> None:
    shared = _shared()
    capability = shared.capability.model_copy(update={"mappings": {}})
    scenario = shared.model_copy(update={"capability": capability})
    _assert_same(scenario, ("tb3-09", "x", "r", None))
    _assert_same(scenario, ("tb3-09", "x", "r", "/tb3_09"))
    _assert_same(scenario, ("tb3-09", "x", "r", None, 0))
    _assert_same(scenario, ("tb3-09", "x", "r", "/tb3_09", 232))


def _with_logics(logics: dict[str, str | list[str]]) -> LaunchScenario:
    shared = _shared()
    capability = shared.capability.model_copy(update={"logics": logics})
    return shared.model_copy(update={"capability": capability})


@pytest.mark.parametrize(
    "logics",
    [
        {"Follow": ["follow_with_poses", "follow_with_bluetooth"]},
        {"Follow": ["follow_with_bluetooth", "follow_with_poses"], "AskHelp": "ask_help"},
        {"Follow": ["\x00robotconf0:namespace\x00", 'é"\\'], "Z": ["z"]},
    ],
)
def test_actions_with_several_logics(logics: dict[str, str | list[str]]) -> None:
    """A list of logics is serialised in its order, with and without a namespace, and the
    agent reads it back as it was."""
    scenario = _with_logics(_marked(logics))
    for namespace in (None, "/tb3_09"):
        _assert_same(scenario, ("tb3-09", "bot", "r", namespace))
        made = ScenarioRequests(scenario).request("tb3-09", "bot", "r", namespace)
        received = LaunchRequest.model_validate_json(made.payload())
        assert received.scenario.capability.logics == _marked(logics)


def test_several_logics_and_their_order_are_restart_content() -> None:
    one = ScenarioRequests(_with_logics({"Follow": "a"})).request("r", "b", "r", None)
    both = ScenarioRequests(_with_logics({"Follow": ["a", "b"]})).request("r", "b", "r", None)
    turned = ScenarioRequests(_with_logics({"Follow": ["b", "a"]})).request("r", "b", "r", None)
    assert len({one.restart_digest, both.restart_digest, turned.restart_digest}) == 3


def _with_names(names: list[str]) -> LaunchScenario:
    shared = _shared()
    mappings = {
        f"m{i}": MappingBinding(kind="topic", name=name, type="std_msgs/msg/String")
        for i, name in enumerate(names)
    }
    capability = shared.capability.model_copy(update={"mappings": mappings})
    return shared.model_copy(update={"capability": capability})


def test_names_absolute_relative_and_per_robot() -> None:
    scenario = _with_names(["/abs/odom", "cmd_vel", "{namespace}", "{namespace}/scan", "a/b"])
    for namespace in ("/tb3_01", "/lab/bots/tb3_02"):
        _assert_same(scenario, ("tb3-01", "bot", "r", namespace))
        resolved = ScenarioRequests(scenario).request("tb3-01", "b", "r", namespace).model()
        names = [b.name for b in resolved.scenario.capability.mappings.values()]
        assert names == [
            "/abs/odom",
            f"{namespace}/cmd_vel",
            namespace,
            f"{namespace}/scan",
            f"{namespace}/a/b",
        ]


def test_a_per_robot_name_without_a_namespace_is_a_render_error() -> None:
    scenario = _with_names(["{namespace}/cmd_vel"])
    with pytest.raises(UnresolvableName, match="needs the robot's namespace"):
        ScenarioRequests(scenario).request("tb3-01", "b", "r", None)
    relative = ScenarioRequests(_with_names(["cmd_vel"])).request("tb3-01", "b", "r", None)
    assert relative.model().scenario.capability.mappings["m0"].name == "/cmd_vel"


def test_render_error_names_the_robot() -> None:
    checked = check(ROOT)
    repo = checked.repo
    assert repo.fleet is not None
    robot_id, assignment = next(iter(repo.fleet.model.robots.items()))
    scenario = ScenarioRequests(_with_names(["{namespace}/cmd_vel"]))
    bare = assignment.model_copy(update={"namespace": None})
    with pytest.raises(RenderError, match=f"robot '{robot_id}'.*needs the robot's namespace"):
        request_for(repo, robot_id, bare, scenario)


def test_a_new_revision_keeps_the_digests_and_changes_only_the_revision() -> None:
    request = next(iter(_example_fleet().requests.values()))
    moved = request.with_revision("f" * 40)
    assert (moved.digest, moved.restart_digest) == (request.digest, request.restart_digest)
    assert json.loads(moved.payload()) == {**json.loads(request.payload()), "revision": "f" * 40}
    assert moved != request and request.with_revision(request.revision) == request


def test_a_fleets_requests_are_stamped_with_its_revision_as_they_are_read() -> None:
    # A request kept from an earlier commit is read with the fleet's revision, whichever way
    # it is read; only digests (which do not cover it) are given without stamping.
    fleet = _example_fleet()
    old = "e" * 40
    kept = {robot_id: request.with_revision(old) for robot_id, request in fleet.requests.items()}
    requests = FleetRequests("f" * 40, kept)
    assert all(request.revision == old for _, request in requests.as_kept())
    assert requests.digests() == {r: q.digest for r, q in kept.items()}
    assert all(request.revision == old for _, request in requests.as_kept())
    robot_id = next(iter(kept))
    assert requests[robot_id] == kept[robot_id].with_revision("f" * 40)
    assert requests.get(robot_id) == requests[robot_id]
    assert all(request.revision == "f" * 40 for request in requests.values())
    assert requests == {r: q.with_revision("f" * 40) for r, q in kept.items()}
    assert requests != kept and list(requests) == list(kept) and len(requests) == len(kept)
    requests[robot_id] = kept[robot_id]
    assert requests[robot_id].revision == "f" * 40 and robot_id in requests


def test_a_field_added_to_the_request_must_be_taught_to_rendering() -> None:
    """Rendering writes each field of the request: one it does not know would be left out
    of every payload. A new field fails here until rendered.py writes it."""
    known = {*_SLOT_NAMES, "scenario", "apiVersion", "kind", "issued_at", "signature"}
    assert set(LaunchRequest.model_fields) == known


_text = st.text(st.characters(codec="utf-8"), max_size=12)
_json = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | _text,
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(_text, inner, max_size=3),
    max_leaves=12,
)


@settings(max_examples=60, deadline=None)
@given(
    knowledge=st.dictionaries(_text, _json, max_size=4),
    robot_name=_text,
    namespace=st.none() | st.sampled_from(["/tb3_01", "/a/b", "/robotconf0"]),
    revision=_text,
    domain=st.none() | st.integers(0, 232),
)
def test_any_text_gives_the_whole_requests_bytes(
    knowledge: dict[str, Any],
    robot_name: str,
    namespace: str | None,
    revision: str,
    domain: int | None,
) -> None:
    shared = _shared().model_copy(update={"environment_knowledge": knowledge})
    _assert_same(shared, ("tb3-09", robot_name, revision, namespace, domain))


def test_scenarios_of_one_capability_share_its_templates_only_while_it_is_the_same() -> None:
    """A capability's bytes are made once for its scenarios; one of the same name whose
    content differs (the next commit's) gets bytes of its own."""
    first = _shared()
    second = first.model_copy(update={"name": "other", "environment_knowledge": {"k": 1}})
    changed = first.capability.model_copy(update={"platform": "elsewhere"})
    third = first.model_copy(update={"capability": changed})
    for scenario in (first, second, third, first):
        _assert_same(scenario, ("tb3-01", "bot", "r", "/tb3_01"))
    made = [ScenarioRequests(s).request("tb3-01", "b", "r", "/n") for s in (first, third)]
    assert made[0].restart_digest != made[1].restart_digest


def test_a_robots_domain_wins_over_its_scenarios_and_is_written_as_the_model_writes_it() -> None:
    shared = _shared()
    for default, own, domain in ((None, None, None), (4, None, 4), (4, 0, 0), (None, 232, 232)):
        made = ScenarioRequests(shared, default).request("tb3-01", "b", "r", "/tb3_01", own)
        assert made.ros_domain_id == domain
        whole = _whole(shared, ("tb3-01", "b", "r", "/tb3_01", domain))
        assert made.payload() == whole.payload() and made.model() == whole
        assert (made.digest, made.restart_digest) == (whole.digest, whole.restart_digest)
        assert json.loads(made.payload()).get("ros_domain_id", "unset") == (
            "unset" if domain is None else domain
        )
