"""The reconciler's builder keeps one cache across commits of a real git repository and gives
the verdict of a fresh build at every commit; `robotconf plan` builds its head from its base
(issue 14, item 1)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robotconf.reconciler.desired import Desired, DesiredBuilder, load_desired
from tests.support.fleet import GitLab

SCENARIO = "configs/scenarios/delivery-gazebo.yaml"
FLEET = "configs/fleet.yaml"


@pytest.fixture
def lab(tmp_path: Path) -> GitLab:
    return GitLab(tmp_path / "lab")


def same(got: Desired, expected: Desired) -> None:
    assert (got.revision, got.problems, got.omitted) == (
        expected.revision,
        expected.problems,
        expected.omitted,
    )
    assert (got.fleet is None) == (expected.fleet is None)
    if got.fleet is not None and expected.fleet is not None:
        assert list(got.fleet.requests) == list(expected.fleet.requests)
        for robot_id, request in expected.fleet.requests.items():
            assert got.fleet.requests[robot_id].payload() == request.payload()
        assert got.fleet.scenario_of == expected.fleet.scenario_of
        assert got.fleet.suspended == expected.fleet.suspended


def test_a_cached_build_of_each_commit_is_a_fresh_build(lab: GitLab) -> None:
    builder = DesiredBuilder()
    steps = [
        (SCENARIO, "move_speed: 0.1", "move_speed: 0.12"),  # one number: one scenario
        (SCENARIO, "move_speed: 0.12", "move_speed: 9"),  # out of range: refused
        (SCENARIO, "move_speed: 9", "move_speed: 0.1"),  # back: applicable again
        (FLEET, "robots:\n", "robots:\n  tb3-09: {scenario: guide-gazebo, namespace: tb3_09}\n"),
        ("configs/capabilities/turtlebot3-camera.yaml", "follow_with_poses", "no_such_logic"),
        ("configs/capabilities/turtlebot3-camera.yaml", "no_such_logic", "follow_with_poses"),
        ("models/platforms/ROS2/mapping-schemes/gazebo.yaml", "name: cmd_vel", "name: /cmd_vel"),
    ]
    builds = [builder(lab.root, lab.first)]
    same(builds[0], load_desired(lab.root, lab.first))
    for path, old, new in steps:
        lab.replace(path, old, new)
        revision = lab.commit(f"{path}: {old} -> {new}")
        built = builder(lab.root, revision)
        same(built, load_desired(lab.root, revision))
        builds.append(built)
    assert [b.ok for b in builds] == [True, True, False, True, True, False, True, False]
    # An older commit again (a rollback): still the verdict of a fresh build.
    same(builder(lab.root, lab.first), load_desired(lab.root, lab.first))
    assert builder.cache.stats.files_parsed > 0


def test_an_unreadable_revision_leaves_the_cache_usable(lab: GitLab) -> None:
    builder = DesiredBuilder()
    assert builder(lab.root, lab.first).ok
    missing = builder(lab.root, "0" * 40)
    assert not missing.ok and missing.problems[0].message.startswith(f"cannot read {'0' * 40}")
    lab.replace(SCENARIO, "move_speed: 0.1", "move_speed: 0.11")
    revision = lab.commit("one number")
    same(builder(lab.root, revision), load_desired(lab.root, revision))


def test_plan_builds_its_head_from_its_base(lab: GitLab) -> None:
    lab.replace(SCENARIO, "move_speed: 0.1", "move_speed: 0.12")
    lab.replace(
        FLEET, "robots:\n", "robots:\n  tb3-09: {scenario: guide-gazebo, namespace: tb3_09}\n"
    )
    head = lab.commit("one number, one robot")
    done = lab.run("plan", "--base", lab.first, "--head", head, "--format", "json")
    assert done.returncode == 1, done.stderr
    plan = json.loads(done.stdout)
    changes = {c["robot_id"]: c for c in plan["changes"]}
    delivering = {r for r, s in lab_scenarios(lab).items() if s == "delivery-gazebo"}
    assert set(changes) == delivering | {"tb3-09"}
    assert changes["tb3-09"]["change"] == "added"
    for robot_id in delivering:
        assert changes[robot_id]["fields"] == [
            "scenario.logic_settings.follow_with_poses.move_speed"
        ]
    # The work tree as head, the same change: the same plan.
    again = lab.run("plan", "--base", lab.first, "--format", "json")
    assert json.loads(again.stdout)["changes"] == plan["changes"]


def lab_scenarios(lab: GitLab) -> dict[str, str]:
    requests = lab.requests(lab.first)
    return {robot_id: request.scenario_name for robot_id, request in requests.items()}


TWIN = "  tb3-06: {scenario: patrol-real, name: Twin}\n"  # tb3-04's names: RC505


def test_a_rule_the_lab_turns_off_no_longer_refuses_a_commit(lab: GitLab) -> None:
    """Issue 21, item 6: the reconciler's cached build judges each commit with that commit's
    `.robotconf.yaml`; a change of that file alone re-judges, a rule a lab cannot tune still
    refuses."""
    builder = DesiredBuilder()
    assert builder(lab.root, lab.first).ok
    lab.replace(FLEET, "  tb3-05:", TWIN + "  tb3-05:")
    clash = lab.commit("a second real-world robot on tb3-04's names")
    refused = builder(lab.root, clash)
    assert not refused.ok and [p.code for p in refused.problems] == ["RC505"]
    lab.write(".robotconf.yaml", "rules:\n  RC505: off  # the two are on two ROS domains\n")
    lab.git("add", ".robotconf.yaml")
    tuned = lab.commit("RC505 off")  # nothing else changed: no rule needs to run again
    built = builder(lab.root, tuned)
    assert built.fleet is not None and "tb3-06" in built.fleet.requests
    assert builder.cache.stats.units_run == [] and builder.cache.stats.files_parsed == 1
    same(built, load_desired(lab.root, tuned))
    lab.replace(
        FLEET, "  tb3-05:", "  tb3/07: {scenario: guide-gazebo, namespace: tb3_07}\n  tb3-05:"
    )
    lab.write(".robotconf.yaml", "rules: {RC505: off, RC501: off}\n")
    lab.git("add", ".robotconf.yaml")
    bad_id = lab.commit("an id that is no topic level, and RC501 turned off")
    still = builder(lab.root, bad_id)
    assert not still.ok
    assert sorted((p.path, p.code) for p in still.problems) == [
        (".robotconf.yaml", "RC801"),
        (FLEET, "RC501"),
    ]
    same(still, load_desired(lab.root, bad_id))
    same(builder(lab.root, clash), load_desired(lab.root, clash))  # back: refused again
