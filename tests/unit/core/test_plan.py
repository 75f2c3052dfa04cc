"""`plan` with a rollout policy: which wave each changed robot falls in, in every format."""

from __future__ import annotations

import pytest

from robotconf.configurator.plan import (
    FleetRead,
    Plan,
    choose_base,
    format_plan_markdown,
    format_plan_text,
    make_plan,
    plan_as_json,
    verify_text,
)
from robotconf.configurator.render import FleetRender, render_fleet
from robotconf.configurator.types import RolloutPolicy, Verify
from tests.support.lab import Lab

FLEET = "configs/fleet.yaml"
DELIVERY = "configs/scenarios/delivery-gazebo.yaml"
GUIDE = "configs/scenarios/guide-gazebo.yaml"


def fleet(lab: Lab) -> tuple[FleetRender, RolloutPolicy | None]:
    checked = lab.check()
    assert checked.ok, checked.errors
    assert checked.repo.fleet is not None
    return render_fleet(checked.repo), checked.repo.fleet.model.rollout


def enable_example_rollout(lab: Lab) -> None:
    text = lab.read(FLEET)
    lab.write(FLEET, text.replace("\n# rollout:\n", "\nrollout:\n").replace("\n#   ", "\n  "))


def edit(lab: Lab) -> None:
    """Four robots change, one is added, one removed: every kind of change, every wave."""
    lab.replace(DELIVERY, "move_speed: 0.1", "move_speed: 0.12")  # tb3-01
    lab.replace(GUIDE, "max_linear_speed: 0.18", "max_linear_speed: 0.19")  # tb3-02
    lab.replace(FLEET, "name: Noetic patrol", "name: Old patrol")  # tb3-05
    lab.replace(FLEET, "  tb3-05:", "  tb3-09: {scenario: guide-gazebo}\n  tb3-05:")
    lab.replace(FLEET, "  tb3-03:", "  # tb3-03:")


@pytest.fixture
def plan(lab: Lab) -> Plan:
    base, _ = fleet(lab)
    enable_example_rollout(lab)
    edit(lab)
    head, rollout = fleet(lab)
    return make_plan(base, head, rollout)


def test_changes_come_in_wave_order_with_their_wave(plan: Plan) -> None:
    # canary: tb3-01 (tb3-03, the other canary, is removed); half of the six robots is three,
    # so half takes tb3-02 and tb3-04 (unchanged); all takes the rest; the removed are in none.
    assert plan.waves == ["canary", "half", "all"]
    assert [(c.robot_id, c.kind, c.wave) for c in plan.changes] == [
        ("tb3-01", "changed", "canary"),
        ("tb3-02", "changed", "half"),
        ("tb3-05", "changed", "all"),
        ("tb3-09", "added", "all"),
        ("tb3-03", "removed", None),
    ]


def test_text_groups_the_changes_under_their_waves(plan: Plan) -> None:
    lines = format_plan_text(plan).splitlines()
    assert lines[0].endswith(": 3 changed, 1 added, 1 removed, 2 unchanged")
    assert lines[1:] == [
        "rollout in waves: canary, half, all; robots that are off are skipped, and get it when"
        " they reconnect",
        "wave canary (1 of 3):",
        "  ~ tb3-01  delivery-gazebo: scenario.logic_settings.follow_with_poses.move_speed"
        " [reload]",
        "wave half (2 of 3):",
        "  ~ tb3-02  guide-gazebo: scenario.robot_settings.max_linear_speed [reload]",
        "wave all (3 of 3):",
        "  ~ tb3-05  patrol-noetic-gazebo: robot_name [reload]",
        "  + tb3-09  guide-gazebo",
        "in no wave (removed):",
        "  - tb3-03  (was delivery-bluetooth-gazebo; its brain will be stopped)",
    ]


def test_markdown_has_a_wave_column(plan: Plan) -> None:
    text = format_plan_markdown(plan)
    assert "Rollout in waves: canary → half → all; robots that are off are skipped" in text
    rows = [line for line in text.splitlines() if line.startswith("| ")]
    assert rows[0] == "| wave | robot | change | scenario | changed fields |"
    assert [row.split(" | ")[:2] for row in rows[2:]] == [
        ["| canary", "`tb3-01`"],
        ["| half", "`tb3-02`"],
        ["| all", "`tb3-05`"],
        ["| all", "`tb3-09`"],
        ["| —", "`tb3-03`"],
    ]


def test_json_names_the_waves_and_each_change_s_wave(plan: Plan) -> None:
    found = plan_as_json(plan)
    assert found["waves"] == ["canary", "half", "all"]
    assert [(c["robot_id"], c["wave"]) for c in found["changes"]] == [
        ("tb3-01", "canary"),
        ("tb3-02", "half"),
        ("tb3-05", "all"),
        ("tb3-09", "all"),
        ("tb3-03", None),
    ]


def test_without_a_policy_the_plan_is_as_before(lab: Lab) -> None:
    base, _ = fleet(lab)
    edit(lab)
    head, rollout = fleet(lab)
    assert rollout is None
    plan = make_plan(base, head, rollout)
    assert plan.waves is None and all(c.wave is None for c in plan.changes)
    assert [c.robot_id for c in plan.changes] == ["tb3-01", "tb3-02", "tb3-03", "tb3-05", "tb3-09"]
    text = format_plan_text(plan)
    assert "wave" not in text and "\n  ~ tb3-01  delivery-gazebo: " in text
    markdown = format_plan_markdown(plan)
    assert "wave" not in markdown.lower()
    assert "| robot | change | scenario | changed fields |" in markdown
    found = plan_as_json(plan)
    assert list(found) == ["base", "head", "unchanged", "changes"]
    assert list(found["changes"][0]) == [
        "robot_id",
        "change",
        "scenario_before",
        "scenario_after",
        "fields",
        "action",  # restart or reload: with or without a policy
    ]


def test_wave_names_from_the_file_are_printed_safely(lab: Lab) -> None:
    base, _ = fleet(lab)
    enable_example_rollout(lab)
    edit(lab)
    head, rollout = fleet(lab)
    assert rollout is not None
    # Validation refuses such a name (RC701); the formats must not trust that it did.
    rollout.waves[0].name = "can*ary\u202e|x"
    plan = make_plan(base, head, rollout)
    text = format_plan_text(plan)
    assert "wave can*ary\\u202e|x (1 of 3):" in text and "\u202e" not in text
    markdown = format_plan_markdown(plan)
    assert "| can\\*ary\\\\u202e\\|x | `tb3-01` |" in markdown and "\u202e" not in markdown


def test_a_domain_change_is_a_restart(lab: Lab) -> None:
    """A brain joins its ROS domain when it starts: a new domain is never reloaded."""
    base, _ = fleet(lab)
    lab.replace(FLEET, "ros_domain_id: 2}", "ros_domain_id: 3}")  # tb3-07
    lab.replace("models/environments/RoboticsLab.yaml", "ros_domain_id: 1", "")  # tb3-04's
    head, rollout = fleet(lab)
    lines = format_plan_text(make_plan(base, head, rollout)).splitlines()
    assert lines[1:] == [
        "  ~ tb3-04  patrol-real: ros_domain_id [restart]",
        "  ~ tb3-07  patrol-real: ros_domain_id [restart]",
    ]


def test_verify_says_what_each_wave_must_show() -> None:
    verify = Verify(
        min_goals=20, success_rate=0.9, compare="stable", max_drop=0.1, critical=["COLLISION"]
    )
    assert verify_text(verify) == (
        "at least 20 goals, success rate ≥ 90%, no worse than stable by more than 10%, "
        "critical: COLLISION; inconclusive after 10m: pause"
    )
    assert verify_text(Verify(timeout=90, inconclusive="fail", dry_run=True)) == (
        "at least 1 goal; inconclusive after 90s: fail (dry run: judged, not gating)"
    )
    assert verify_text(Verify(min_goals=0, timeout="2h", inconclusive="pass")) == (
        "no minimum of goals; inconclusive after 2h: pass"
    )


def test_the_head_s_verify_is_printed_under_its_waves(lab: Lab) -> None:
    base, _ = fleet(lab)
    enable_example_rollout(lab)
    lab.replace(
        FLEET,
        "  offline: skip",
        "  offline: skip\n  verify: {min_goals: 20, success_rate: 0.9, critical: [COLLISION]}",
    )
    edit(lab)
    head, rollout = fleet(lab)
    plan = make_plan(base, head, rollout)
    words = (
        "at least 20 goals, success rate ≥ 90%, critical: COLLISION; inconclusive after 10m: pause"
    )
    lines = format_plan_text(plan).splitlines()
    assert lines[1].startswith("rollout in waves: canary, half, all;")
    assert lines[2:4] == [f"verified by: {words}", "wave canary (1 of 3):"]
    assert f"Each wave verified by: {words}." in format_plan_markdown(plan)
    found = plan_as_json(plan)["verify"]
    assert found["min_goals"] == 20 and found["critical"] == ["COLLISION"]
    assert found["success_rate"] == 0.9 and found["inconclusive"] == "pause"


def test_without_verify_nothing_is_said_of_it(plan: Plan) -> None:
    assert "verified" not in format_plan_text(plan) + format_plan_markdown(plan)
    assert plan_as_json(plan)["verify"] is None


# ------------------------------------------------------------------ the base without --base

URL = "mqtt://127.0.0.1:1883"
COMMIT = "0123456789abcdef0123456789abcdef01234567"


def test_the_base_is_what_the_fleet_runs_when_the_broker_says() -> None:
    chosen = choose_base(FleetRead(URL, applied=COMMIT))
    assert (chosen.revision, chosen.from_fleet) == (COMMIT, True)
    assert chosen.line(COMMIT) == (
        "against what the fleet runs: 0123456789ab (applied by the reconciler)"
    )


def test_the_base_is_head_when_no_broker_answers() -> None:
    chosen = choose_base(FleetRead(URL, unreached=f"no broker reachable at {URL}"))
    assert (chosen.revision, chosen.from_fleet) == ("HEAD", False)
    assert chosen.line("fedcba9876543210") == (
        f"against HEAD fedcba987654 (no broker reachable at {URL})"
    )


def test_the_base_is_head_when_no_reconciler_applied_anything() -> None:
    chosen = choose_base(FleetRead(URL))
    assert chosen.revision == "HEAD"
    assert chosen.why == f"the broker at {URL} holds no revision applied by a reconciler"


@pytest.mark.parametrize("named", ["--upload-pack=evil", "HEAD~1", "main", "abc", "A" * 40, ""])
def test_a_status_that_names_no_commit_never_reaches_git_as_a_revision(named: str) -> None:
    chosen = choose_base(FleetRead(URL, applied=named))
    assert chosen.revision == "HEAD" and not chosen.from_fleet
    assert "names no commit" in chosen.why


def test_each_side_s_commit_subject_is_said_when_known(lab: Lab) -> None:
    from dataclasses import replace

    base, head = "a" * 40, "b" * 40
    plan = replace(
        Plan(base=base, head=head, changes=[], unchanged=6),
        subjects={head: "Rename the lab robots\x1b[2J"},
    )
    text = format_plan_text(plan)
    assert text.splitlines()[1] == '  bbbbbbbbbbbb "Rename the lab robots\\x1b[2J"'
    assert 'aaaaaaaaaaaa "' not in text  # no subject known: no line
    assert "- bbbbbbbbbbbb" in format_plan_markdown(plan)
    assert plan_as_json(plan)["subjects"] == {head: "Rename the lab robots\\x1b[2J"}
