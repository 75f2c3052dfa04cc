"""The pure diff: desired requests vs retained launch digests."""

from __future__ import annotations

from dataclasses import dataclass

from robotconf.reconciler.diff import diff


@dataclass(frozen=True)
class Req:
    digest: str


NONE: dict[str, Req] = {}


def test_publishes_only_what_differs_and_clears_what_is_gone() -> None:
    desired = {"a": Req("d1"), "b": Req("d2"), "c": Req("d3")}
    observed = {"a": "d1", "b": "old", "x": "dx"}
    actions = diff(desired, observed)
    assert sorted(actions.publish) == ["b", "c"]
    assert actions.clear == ["x"]
    assert actions.unchanged == 1
    assert actions.held == []
    assert actions.refused is None


def test_nothing_to_do_when_the_broker_already_holds_everything() -> None:
    desired = {"a": Req("d1"), "b": Req("d2")}
    actions = diff(desired, {"a": "d1", "b": "d2"})
    assert actions.empty and actions.unchanged == 2


def test_an_unreadable_retained_request_is_replaced() -> None:
    actions = diff({"a": Req("d1")}, {"a": None})
    assert list(actions.publish) == ["a"]


def test_suspended_robots_are_left_as_they_are() -> None:
    desired = {"a": Req("new"), "b": Req("d2")}
    actions = diff(desired, {"a": "old"}, suspended={"a", "b"})
    assert actions.publish == {} and actions.clear == []
    assert actions.held == ["a", "b"]  # b has nothing published: still left alone


def test_a_suspended_robot_already_in_sync_is_just_unchanged() -> None:
    actions = diff({"a": Req("d1")}, {"a": "d1"}, suspended={"a"})
    assert actions.held == [] and actions.unchanged == 1


def test_an_empty_fleet_that_would_stop_every_robot_is_refused() -> None:
    actions = diff(NONE, {"a": "d1", "b": "d2"})
    assert actions.refused is not None and "allow_empty" in actions.refused
    assert actions.empty


def test_an_empty_fleet_is_applied_when_allowed() -> None:
    actions = diff(NONE, {"a": "d1", "b": "d2"}, allow_empty=True)
    assert actions.refused is None
    assert actions.clear == ["a", "b"]


def test_an_empty_fleet_with_nothing_published_is_not_a_refusal() -> None:
    actions = diff(NONE, {})
    assert actions.refused is None and actions.empty


def test_removing_some_robots_is_not_an_empty_fleet() -> None:
    actions = diff({"a": Req("d1")}, {"a": "d1", "b": "d2"})
    assert actions.refused is None and actions.clear == ["b"]


def test_a_robot_still_running_without_an_assignment_is_cleared_again() -> None:
    """A clear is not retained: an agent that was away when it was sent still runs its brain."""
    desired = {"a": Req("d1")}
    actions = diff(desired, {"a": "d1"}, running={"a", "gone"})
    assert actions.clear == ["gone"] and actions.publish == {}
    # A suspended or assigned robot that runs is not touched.
    assert diff(desired, {"a": "d1"}, running={"a"}).empty


def test_a_request_held_unsigned_is_published_again_while_the_reconciler_signs() -> None:
    desired = {"a": Req("d1"), "b": Req("d2"), "c": Req("d3")}
    observed = {"a": "d1", "b": "d2", "c": "old"}
    actions = diff(desired, observed, unsigned={"a", "c"})
    assert sorted(actions.publish) == ["a", "c"] and actions.unchanged == 1
    held = diff(desired, observed, suspended={"a"}, unsigned={"a"})
    assert held.held == ["a"] and "a" not in held.publish  # a held robot stays as it is
