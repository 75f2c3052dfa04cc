"""ROS 2 names: mapping names and namespaces by the ROS 2 rules, resolved per robot."""

from __future__ import annotations

import pytest

from robotconf.configurator.rosnames import (
    UnresolvableName,
    absolute_namespace,
    mapping_name_problem,
    namespace_problem,
    resolve_name,
    suggest_namespace,
)

VALID_NAMES = [
    "/cmd_vel",
    "cmd_vel",
    "camera/image_raw",
    "/sim/door_controller/open",
    "_hidden",
    "/_private/thing",
    "Foo/BAR/abc123",
    "{namespace}/cmd_vel",
    "{namespace}/a/b",
    "a" * 200,
]

INVALID_NAMES = [
    ("", "is empty"),
    ("/", "root namespace"),
    ("~/cmd_vel", "private"),
    ("~", "private"),
    ("123abc", "starting with a digit"),
    ("/a/1b", "token '1b' starting with a digit"),
    ("foo bar", "' '"),
    ("cmd-vel", "'-'"),
    ("/caméra", "'é'"),
    ("foo//bar", "empty token"),
    ("//foo", "empty token"),
    ("foo/", "empty token"),
    ("/foo/", "empty token"),
    ("foo_/bar", "ending with an underscore"),
    ("foo__bar", "repeated underscore"),
    ("{namespace}", "add a name"),
    ("{namespace}cmd_vel", "continue with '/'"),
    ("/a/{namespace}/b", "substitution"),
    ("{node}/cmd_vel", "substitution"),
    ("{ns}/x", "substitution"),
    ("/a}", "substitution"),
    ("a" * 250, "too long"),
]


@pytest.mark.parametrize("name", VALID_NAMES)
def test_valid_mapping_names(name: str) -> None:
    assert mapping_name_problem(name) is None


@pytest.mark.parametrize(("name", "why"), INVALID_NAMES)
def test_invalid_mapping_names(name: str, why: str) -> None:
    problem = mapping_name_problem(name)
    assert problem is not None and why in problem, problem


@pytest.mark.parametrize("namespace", ["tb3_01", "/tb3_01", "fleet/tb3_01", "/a/B/_c", "x"])
def test_valid_namespaces(namespace: str) -> None:
    assert namespace_problem(namespace) is None


@pytest.mark.parametrize(
    ("namespace", "why"),
    [
        ("", "empty"),
        ("/", "root namespace"),
        ("tb3-01", "'-'"),
        ("/tb3_01/", "empty token"),
        ("a//b", "empty token"),
        ("01", "starting with a digit"),
        ("~/x", "no '~'"),
        ("{namespace}", "no '~' and no '{...}'"),
        ("a__b", "repeated underscore"),
        ("a_", "ending with an underscore"),
        ("x" * 260, "too long"),
    ],
)
def test_invalid_namespaces(namespace: str, why: str) -> None:
    problem = namespace_problem(namespace)
    assert problem is not None and why in problem, problem


@pytest.mark.parametrize(
    ("text", "suggestion"),
    [("tb3-01", "tb3_01"), ("/fleet/01-x", "fleet/_01_x"), ("a--b_", "a_b"), ("---", "robot")],
)
def test_suggested_namespaces_are_valid(text: str, suggestion: str) -> None:
    assert suggest_namespace(text) == suggestion
    assert namespace_problem(suggestion) is None


def test_absolute_namespace() -> None:
    assert absolute_namespace("tb3_01") == "/tb3_01"
    assert absolute_namespace("/tb3_01") == "/tb3_01"


@pytest.mark.parametrize(
    ("name", "namespace", "resolved"),
    [
        ("/cmd_vel", None, "/cmd_vel"),
        ("/cmd_vel", "tb3_01", "/cmd_vel"),
        ("cmd_vel", None, "/cmd_vel"),
        ("cmd_vel", "tb3_01", "/tb3_01/cmd_vel"),
        ("cmd_vel", "/tb3_01", "/tb3_01/cmd_vel"),
        ("camera/image_raw", "fleet/tb3_01", "/fleet/tb3_01/camera/image_raw"),
        ("{namespace}/cmd_vel", "tb3_01", "/tb3_01/cmd_vel"),
        ("{namespace}/a/b", "/fleet/tb3_01", "/fleet/tb3_01/a/b"),
    ],
)
def test_resolution(name: str, namespace: str | None, resolved: str) -> None:
    assert resolve_name(name, namespace) == resolved
    # A resolved name is itself a valid absolute name that resolves to itself.
    assert mapping_name_problem(resolved) is None
    assert resolve_name(resolved, "other") == resolved


def test_namespace_substitution_needs_a_namespace() -> None:
    with pytest.raises(UnresolvableName, match="needs the robot's namespace"):
        resolve_name("{namespace}/cmd_vel", None)
