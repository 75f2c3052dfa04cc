"""Groups that move together, pure: robots that cooperate (fleet.yaml `groups`, or every
scenario's robots with `rollout.groups: scenario`) are never split by a wave, and one member
failing fails the others; validated (RC709); `plan` names each robot's group."""

from __future__ import annotations

import pytest
import yaml

from robotconf.configurator.plan import format_plan_text, make_plan
from robotconf.configurator.render import FleetRender, render_fleet
from robotconf.configurator.stages import plan_waves
from robotconf.contract.wire import AgentState, AgentStatus
from robotconf.reconciler.rollout import RolloutInput, roll_out
from tests.support.lab import Lab

T0 = 1_000_000.0
FLEET = "configs/fleet.yaml"
POLICY = """\
rollout:
  waves: [{name: canary, selector: {ring: canary}}, {name: all}]
  healthy_after: 10
  max_failures: 1
  wave_timeout: 100
"""


def build(lab: Lab, version: str, extra: str, restart: bool = False) -> FleetRender:
    """The lab's fleet, renamed for `version` (reloaded in place); with `restart`, its
    namespaces moved too (a restart)."""
    robots = yaml.safe_load(lab.read(FLEET))["robots"]
    for assignment in robots.values():
        assignment["name"] = f"{assignment['name']} {version}"
        if restart and "namespace" in assignment:
            assignment["namespace"] = f"{assignment['namespace']}_{version}"
    lab.write(FLEET, yaml.safe_dump({"robots": robots}, sort_keys=True) + POLICY + extra)
    checked = lab.check()
    assert checked.ok, checked.errors
    rendered = render_fleet(checked.repo)
    rendered.revision = version * 40
    return rendered


def test_a_wave_never_splits_a_group(lab: Lab) -> None:
    head = build(lab, "b", "groups:\n  delivery: [tb3-01, tb3-02]\n")
    plan = plan_waves(head)
    assert plan.of["tb3-02"] == plan.of["tb3-01"] == 0  # the guide goes with its canary
    assert plan.of["tb3-05"] == 1
    assert plan.group_of == {"tb3-01": "delivery", "tb3-02": "delivery"}


def test_every_scenarios_robots_move_together_with_groups_scenario(lab: Lab) -> None:
    text = POLICY.replace("  wave_timeout: 100\n", "  wave_timeout: 100\n  groups: scenario\n")
    robots = yaml.safe_load(lab.read(FLEET))["robots"]
    robots["tb3-04"]["labels"] = {"ring": "canary"}
    lab.write(FLEET, yaml.safe_dump({"robots": robots}, sort_keys=True) + text)
    checked = lab.check()
    assert checked.ok, checked.errors
    plan = plan_waves(render_fleet(checked.repo))
    assert plan.of["tb3-07"] == plan.of["tb3-04"] == 0  # patrol-real's two robots, together
    assert plan.group_of["tb3-07"] == "scenario:patrol-real"


def test_one_member_failing_fails_its_group(lab: Lab) -> None:
    extra = "groups:\n  delivery: [tb3-01, tb3-03]\n"
    stable, head = build(lab, "a", extra), build(lab, "b", extra)
    launches: dict[str, str | None] = {r: q.digest for r, q in stable.requests.items()}
    statuses = {
        r: AgentStatus(robot_id=r, state=AgentState.RUNNING, digest=d, since=T0)
        for r, d in launches.items()
    }
    first = roll_out(RolloutInput(head, stable, None, launches, statuses, {}, T0))
    launches.update({r: head.requests[r].digest for r in ("tb3-01", "tb3-03")})
    statuses["tb3-01"] = AgentStatus(
        robot_id="tb3-01", state=AgentState.FAILED, digest=head.requests["tb3-01"].digest
    )
    statuses["tb3-03"] = AgentStatus(
        robot_id="tb3-03", state=AgentState.RUNNING, digest=head.requests["tb3-03"].digest
    )
    step = roll_out(
        RolloutInput(
            head, stable, first.status, launches, statuses, {"tb3-03": T0}, T0 + 5, first.record
        )
    )
    # One failure is within max_failures 1; its group makes it two: rolled back.
    assert step.status is not None and step.status.state == "RolledBack"
    assert step.status.failed == ["tb3-01", "tb3-03"]


def test_plan_names_each_robots_group(lab: Lab) -> None:
    extra = "groups:\n  delivery: [tb3-01, tb3-02]\n"
    base, head = build(lab, "a", extra), build(lab, "b", extra)
    text = format_plan_text(make_plan(base, head, head.rollout))
    assert "tb3-02" in text and "(group delivery)" in text


@pytest.mark.parametrize(
    ("groups", "words"),
    [
        ("  team: [tb3-01, tb3-99]\n", "names robot 'tb3-99', which is not assigned"),
        ("  team: [tb3-01]\n  other: [tb3-01, tb3-02]\n", "is in groups 'team' and 'other'"),
        ('  team: "ring"\n', 'write "key=value"'),
        ("  'a b': [tb3-01]\n", "group name 'a b'"),
    ],
)
def test_a_group_that_cannot_move_as_one_is_refused(lab: Lab, groups: str, words: str) -> None:
    lab.write(FLEET, lab.read(FLEET) + POLICY + "groups:\n" + groups)
    found = [d.message for d in lab.check().diagnostics if d.code == "RC709"]
    assert any(words in m for m in found), found


def test_a_group_across_stages_is_refused(lab: Lab) -> None:
    lab.write(
        FLEET,
        lab.read(FLEET)
        + POLICY
        + "groups:\n  mixed: [tb3-01, tb3-04]\n"
        + "stages:\n  - {name: sim, environments: [Gazebo]}\n"
        + "  - {name: real, environments: [Real]}\n",
    )
    found = [d.message for d in lab.check().diagnostics if d.code == "RC709"]
    assert any("group 'mixed' has robots on 2 stages" in m for m in found), found


def test_a_busy_member_holds_its_whole_groups_restart_up_to_its_max_defer(lab: Lab) -> None:
    extra = "groups:\n  delivery: [tb3-01, tb3-03]\n"
    stable, head = build(lab, "a", extra), build(lab, "b", extra, restart=True)
    launches: dict[str, str | None] = {r: q.digest for r, q in stable.requests.items()}

    def statuses(busy: bool) -> dict[str, AgentStatus]:
        found = {
            r: AgentStatus(robot_id=r, state=AgentState.RUNNING, digest=d, since=T0)
            for r, d in launches.items()
        }
        found["tb3-03"] = found["tb3-03"].model_copy(update={"busy": busy, "max_defer": 30.0})
        return found

    def sent(step_: object) -> list[str]:
        from robotconf.reconciler.rollout import RolloutStep

        assert isinstance(step_, RolloutStep)
        return sorted(
            r
            for r, q in step_.requests.items()
            if r not in step_.keep
            and q.digest == head.requests[r].digest
            and launches[r] != q.digest
        )

    held = roll_out(RolloutInput(head, stable, None, launches, statuses(True), {}, T0))
    assert sent(held) == []  # neither of the group: tb3-03's brain is busy
    assert held.status is not None and "group 'delivery' waits while tb3-03 is busy" in (
        held.status.message
    )
    assert held.recheck_at is not None and held.recheck_at <= T0 + 30
    still = roll_out(
        RolloutInput(head, stable, held.status, launches, statuses(True), {}, T0 + 10, held.record)
    )
    assert sent(still) == []
    free = roll_out(
        RolloutInput(
            head, stable, still.status, launches, statuses(False), {}, T0 + 12, still.record
        )
    )
    assert sent(free) == ["tb3-01", "tb3-03"]  # together, once nobody is busy
    late = roll_out(
        RolloutInput(
            head, stable, still.status, launches, statuses(True), {}, T0 + 31, still.record
        )
    )
    assert sent(late) == ["tb3-01", "tb3-03"]  # max_defer passed: sent, each agent defers


def test_a_change_reloaded_in_place_is_not_held_for_a_busy_member(lab: Lab) -> None:
    extra = "groups:\n  delivery: [tb3-01, tb3-03]\n"
    stable, head = build(lab, "a", extra), build(lab, "b", extra)  # names only: a reload
    launches: dict[str, str | None] = {r: q.digest for r, q in stable.requests.items()}
    statuses = {
        r: AgentStatus(
            robot_id=r, state=AgentState.RUNNING, digest=d, since=T0, busy=True, max_defer=30.0
        )
        for r, d in launches.items()
    }
    step = roll_out(RolloutInput(head, stable, None, launches, statuses, {}, T0))
    assert step.status is not None and "waits while" not in step.status.message
    moved = [r for r in ("tb3-01", "tb3-03") if r not in step.keep]
    assert moved == ["tb3-01", "tb3-03"]
