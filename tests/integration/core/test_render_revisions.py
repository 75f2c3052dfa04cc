"""Rendering from commits and through the CLI: the digest ignores the revision, --rev reads
the commit."""

from __future__ import annotations

import json

from robotconf.configurator.render import render_fleet
from robotconf.contract.launch import LaunchRequest
from tests.support.lab import Lab

DELIVERY = "configs/scenarios/delivery-gazebo.yaml"


def test_digest_covers_content_not_revision(lab: Lab) -> None:
    first = lab.commit("lab")
    before = render_fleet(lab.check(first).repo)
    assert all(r.revision == first and r.model().digest_matches() for r in before.requests.values())
    # An unrelated commit: a description and a new, unused scenario.
    lab.replace("models/actions/OpenDoor.yaml", "platforms:", "name: OpenDoor\nplatforms:")
    lab.write("configs/scenarios/spare.yaml", "capability: turtlebot3-guide\n")
    second = lab.commit("unrelated")
    after = render_fleet(lab.check(second).repo)
    assert {i: r.digest for i, r in before.requests.items()} == {
        i: r.digest for i, r in after.requests.items()
    }
    assert all(r.revision == second for r in after.requests.values())
    # A relevant change alters exactly the robots running that scenario.
    lab.replace(DELIVERY, "move_speed: 0.1", "move_speed: 0.12")
    third = lab.commit("slower")
    changed = render_fleet(lab.check(third).repo)
    differ = {i for i in after.requests if after.requests[i].digest != changed.requests[i].digest}
    assert differ == {i for i, s in changed.scenario_of.items() if s == "delivery-gazebo"}


def test_rev_reads_the_commit_not_the_work_tree(lab: Lab) -> None:
    sha = lab.commit("lab")
    lab.replace(DELIVERY, "move_speed: 0.1", "move_speed: 0.2")
    lab.write("configs/capabilities/broken.yaml", "platform: [")
    committed = lab.render(rev=sha)
    assert committed.revision == sha
    assert committed.scenario.logic_settings["follow_with_poses"]["move_speed"] == 0.1
    assert not lab.check().ok  # the work tree is broken, the commit is not


def test_work_tree_revision_is_marked_dirty(lab: Lab) -> None:
    sha = lab.commit("lab")
    assert lab.render().revision == sha
    lab.replace(DELIVERY, "move_speed: 0.1", "move_speed: 0.2")
    assert lab.render().revision == f"{sha}+dirty"


def test_cli_render_prints_the_request(lab: Lab) -> None:
    sha = lab.commit("lab")
    done = lab.run("render", "tb3-02", "--rev", "HEAD")
    assert done.returncode == 0, done.stderr
    request = LaunchRequest.model_validate(json.loads(done.stdout))
    assert request.robot_id == "tb3-02" and request.revision == sha and request.digest_matches()


def test_cli_render_unknown_robot_and_invalid_repo(lab: Lab) -> None:
    done = lab.run("render", "tb3-1")
    assert done.returncode == 1 and "not in configs/fleet.yaml" in done.stderr
    assert "Traceback" not in done.stderr
    lab.replace(DELIVERY, "move_speed: 0.1", "move_speed: 9")
    done = lab.run("render", "tb3-01")
    assert done.returncode == 1 and "RC403" in done.stderr and done.stdout == ""
