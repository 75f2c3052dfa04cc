"""The promotion ladder in fleet.yaml (`stages`): which robots each stage takes, validated:
code, place and words per rule."""

from __future__ import annotations

import pytest

from robotconf.configurator.render import render_fleet
from robotconf.configurator.stages import SelectorError, fleet_stages, parse_selector
from tests.support.lab import Lab

FLEET = "configs/fleet.yaml"
POLICY = "rollout:\n  waves: [{name: all}]\n"
LADDER = (
    "stages:\n  - {name: sim, environments: [Gazebo]}\n  - {name: real, environments: [Real]}\n"
)


def with_stages(lab: Lab, stages: str, policy: str = POLICY) -> None:
    lab.write(FLEET, lab.read(FLEET) + policy + stages)


def test_robots_are_placed_by_their_environments_name_or_type(lab: Lab) -> None:
    with_stages(
        lab,
        "stages:\n  - {name: sim, environments: [GazeboDemo1]}\n"
        "  - {name: real, environments: [Real]}\n",
    )
    checked = lab.check()
    assert checked.diagnostics == []
    stages = fleet_stages(render_fleet(checked.repo))
    assert {r for r, s in stages.items() if s == 1} == {"tb3-04", "tb3-07"}  # RoboticsLab: Real
    assert stages["tb3-01"] == 0 and len(stages) == 6


def test_a_selector_places_robots_by_their_labels_first_stage_first(lab: Lab) -> None:
    with_stages(
        lab,
        'stages:\n  - {name: canaries, selector: "ring=canary"}\n'
        "  - {name: rest, environments: [Gazebo, Real]}\n",
    )
    checked = lab.check()
    assert checked.diagnostics == []
    stages = fleet_stages(render_fleet(checked.repo))
    assert sorted(r for r, s in stages.items() if s == 0) == ["tb3-01", "tb3-03"]


def test_a_robot_no_stage_takes_is_an_error_naming_it(lab: Lab) -> None:
    with_stages(lab, "stages:\n  - {name: sim, environments: [Gazebo]}\n")
    d = lab.only("RC708")
    assert "no stage takes robot(s) tb3-04, tb3-07" in d.message
    lines = lab.read(FLEET).splitlines()
    assert d.line == next(n for n, line in enumerate(lines, 1) if line.startswith("stages:"))


@pytest.mark.parametrize(
    ("stages", "words"),
    [
        ("  - {name: sim}\n", "needs environments (names or types) or a selector"),
        (
            '  - {name: sim, environments: [Gazebo], selector: "a=b"}\n',
            "one of the two",
        ),
        ('  - {name: sim, selector: "ring"}\n', 'write "key=value"'),
        ("  - {name: sim, environments: [Gazbo]}\n", "did you mean 'Gazebo'"),
        ("  - {name: 'a b', environments: [Gazebo]}\n", "stage name 'a b'"),
        (
            "  - {name: sim, environments: [Gazebo]}\n  - {name: sim, environments: [Real]}\n",
            "stage 'sim' is named twice",
        ),
    ],
)
def test_a_stage_that_cannot_place_robots_is_refused(lab: Lab, stages: str, words: str) -> None:
    with_stages(lab, "stages:\n" + stages + "  - {name: rest, environments: [Gazebo, Real]}\n")
    found = [d for d in lab.check().diagnostics if d.code == "RC707"]
    assert found and any(words in d.message for d in found), [d.message for d in found]


def test_stages_need_a_rollout_to_verify_on(lab: Lab) -> None:
    with_stages(lab, LADDER, policy="")
    d = lab.only("RC707")
    assert "add a rollout: policy" in d.message


@pytest.mark.parametrize("text", ["site", "=real", "site=", "a=b,a=c", "a=b,,c=d"])
def test_a_selector_is_key_value_pairs(text: str) -> None:
    with pytest.raises(SelectorError):
        parse_selector(text)
