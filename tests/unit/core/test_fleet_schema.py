"""The fleet schema tells editors what validate checks of labels and the rollout policy."""

from __future__ import annotations

import copy
from typing import Any

import jsonschema
import pytest

from robotconf.configurator.schemas import generate
from tests.support.lab import Lab

GOOD: dict[str, Any] = {
    "robots": {
        "tb3-01": {"scenario": "delivery-gazebo", "labels": {"ring": "canary", "site": "hall-a"}},
        "tb3-02": {"scenario": "guide-gazebo"},
    },
    "rollout": {
        "waves": [
            {"name": "canary", "selector": {"ring": "canary"}},
            {"name": "half", "percent": 50},
            {"name": "all"},
        ],
        "healthy_after": 0,
        "max_failures": "10%",
        "wave_timeout": 0.5,
        "on_failure": "halt",
        "paused": True,
    },
}


@pytest.fixture
def schema(lab: Lab) -> dict[str, Any]:
    return generate(lab.check().repo)["fleet.schema.json"]


def _with(path: list[str | int], value: Any) -> dict[str, Any]:
    """GOOD with the value at `path` replaced (a copy)."""
    doc = copy.deepcopy(GOOD)
    node: Any = doc
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value
    return doc


def test_a_fleet_with_labels_and_a_policy_fits(schema: dict[str, Any]) -> None:
    jsonschema.validate(GOOD, schema)
    jsonschema.validate(_with(["rollout", "max_failures"], 2), schema)
    jsonschema.validate(_with(["rollout", "max_failures"], "100%"), schema)


@pytest.mark.parametrize(
    ("path", "value"),
    [
        (["robots", "tb3-01", "labels"], {"ring/x": "canary"}),
        (["robots", "tb3-01", "labels"], {"ring": "can ary"}),
        (["robots", "tb3-01", "labels"], {"ring": 1}),
        (["rollout", "waves", 0, "name"], "wave one"),
        (["rollout", "waves", 0, "selector"], {"ring": ""}),
        (["rollout", "waves", 1, "percent"], 0),
        (["rollout", "waves", 1, "percent"], 101),
        (["rollout", "healthy_after"], -1),
        (["rollout", "wave_timeout"], 0),
        (["rollout", "max_failures"], -1),
        (["rollout", "max_failures"], "101%"),
        (["rollout", "max_failures"], "ten"),
        (["rollout", "on_failure"], "retry"),
        (["rollout", "waves", 2], {"name": "all", "percent": 50, "extra": 1}),
    ],
)
def test_what_validate_refuses_the_schema_refuses(
    schema: dict[str, Any], path: list[str | int], value: Any
) -> None:
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(_with(path, value), schema)
