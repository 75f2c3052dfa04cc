"""Staged rollouts, pure: the promotion ladder (fleet.yaml `stages`) runs each stage's robots
through the waves, then the stage's gate (its soak, counted in goals); the next stage's robots
keep the stable revision until the gate passes, or until an operator promotes the revision."""

from __future__ import annotations

import yaml

from robotconf.configurator.render import FleetRender, render_fleet
from robotconf.configurator.stages import plan_waves
from robotconf.contract.notes import VerdictNote
from robotconf.contract.wire import AgentState, RolloutStatus, StageState
from robotconf.reconciler.rollout import RolloutStep, stage_bases
from tests.support.lab import Lab
from tests.support.rollout_run import T0, RolloutRun

FLEET = "configs/fleet.yaml"
SIM = ["tb3-01", "tb3-02", "tb3-03", "tb3-05"]  # Gazebo
REAL = ["tb3-04", "tb3-07"]  # the robotics lab
POLICY = """\
rollout:
  waves: [{name: canary, selector: {ring: canary}}, {name: all}]
  healthy_after: 10
  wave_timeout: 100
  verify: {min_goals: 1, timeout: 600}
stages:
  - {name: sim, environments: [Gazebo], soak: {goals: 5}}
  - {name: real, environments: [Real]}
"""


def build(lab: Lab, version: str, policy: str = POLICY) -> FleetRender:
    robots = yaml.safe_load(lab.read(FLEET))["robots"]
    for assignment in robots.values():
        assignment["name"] = f"{assignment['name']} {version}"
    lab.write(FLEET, yaml.safe_dump({"robots": robots}, sort_keys=True) + policy)
    checked = lab.check()
    assert checked.ok, checked.errors
    rendered = render_fleet(checked.repo)
    rendered.revision = version * 40
    return rendered


class Run(RolloutRun):
    def __init__(self, lab: Lab, policy: str = POLICY) -> None:
        super().__init__(build(lab, "a", policy), build(lab, "b", policy))


def test_each_stage_goes_through_the_waves_then_its_gate(lab: Lab) -> None:
    plan = plan_waves(build(lab, "b"))
    assert [s.name for s in plan.specs] == [
        "sim/canary",
        "sim/all",
        "sim",
        "real/canary",
        "real/all",
        "real",
    ]
    assert [s.gate for s in plan.specs] == [False, False, True, False, False, True]
    assert {r: plan.of[r] for r in SIM + REAL} == {
        "tb3-01": 0,
        "tb3-03": 0,
        "tb3-02": 1,
        "tb3-05": 1,
        "tb3-04": 4,  # no real robot is a canary: real/canary takes none
        "tb3-07": 4,
    }


def test_the_real_robots_keep_the_stable_revision_until_sim_is_soaked(lab: Lab) -> None:
    run = Run(lab)
    run.step(T0)
    run.report(["tb3-01"], "succeeded")
    run.step(T0 + 20)  # sim/canary verified: on to sim/all
    run.report(["tb3-02"], "succeeded")
    gate = run.step(T0 + 40)  # sim/all verified: the gate soaks 5 goals of the whole stage
    assert gate.status is not None and gate.status.wave_name == "sim"
    assert gate.status.stage == "sim" and gate.status.state == "Progressing"
    assert [(s.name, s.state, s.verified_revision) for s in gate.status.stages] == [
        ("sim", "verifying", "a" * 40),
        ("real", "waiting", "a" * 40),
    ]
    assert run.moved() == SIM  # the real robots are not touched
    run.report(SIM, "succeeded")  # 4 of 5
    assert run.step(T0 + 50).status.wave_name == "sim"  # type: ignore[union-attr]
    run.report(["tb3-05"], "succeeded")
    promoted = run.step(T0 + 60)
    assert promoted.status is not None and promoted.status.stage == "real"
    assert [(s.name, s.state) for s in promoted.status.stages] == [
        ("sim", "verified"),
        ("real", "rolling"),
    ]
    assert run.moved() == sorted(SIM + REAL)
    gates = [(n.wave_name, n.stage, n.verdict, n.goals) for n in promoted.verdicts]
    assert ("sim", "sim", "Successful", 5) in gates


def test_sim_failing_its_soak_never_reaches_the_real_robots(lab: Lab) -> None:
    run = Run(lab, POLICY.replace("min_goals: 1,", "min_goals: 1, success_rate: 0.8,"))
    run.step(T0)
    run.report(["tb3-01"], "succeeded")
    run.step(T0 + 20)
    run.report(["tb3-02"], "succeeded")
    assert run.step(T0 + 40).status.wave_name == "sim"  # type: ignore[union-attr]
    run.report(SIM[:2], "failed")  # 2 of the soak's 5 failed: 80% is out of reach
    stopped = run.step(T0 + 50)
    assert stopped.status is not None and stopped.status.state == "RolledBack"
    assert stopped.serve_stable
    assert [(s.name, s.state) for s in stopped.status.stages] == [
        ("sim", "failed"),
        ("real", "waiting"),
    ]
    assert [(n.stage, n.verdict) for n in stopped.verdicts] == [("sim", "Failed")]
    assert "verification of wave 'sim' failed" in stopped.status.message


def test_an_operator_promotes_the_revision_to_a_stage_by_hand(lab: Lab) -> None:
    run = Run(lab)
    run.step(T0)
    run.notes = [
        VerdictNote(kind="promote", revision=run.head.revision, at=T0 + 1, stage="real", by="ada")
    ]
    # Each healthy wave before real passes without evidence; health is still waited for.
    noted = []
    for at in range(20, 120, 20):
        jumped = run.step(T0 + at)
        noted += jumped.verdicts
        if jumped.status is not None and jumped.status.stage == "real":
            break
    assert jumped.status is not None and jumped.status.stage == "real"
    assert run.moved() == sorted(SIM + REAL)
    assert {n.wave_name for n in noted} == {"sim/canary", "sim/all", "sim"}
    assert all(n.by == "ada" for n in noted)


def test_status_and_the_browser_view_show_each_stage_and_its_verified_revision(lab: Lab) -> None:
    from robotconf.readmodel.verdicts import rollout_line
    from robotconf.workstation.ui.pages import stages_html

    run = Run(lab)
    status = run.step(T0).status
    assert status is not None
    assert "stages sim rolling (keeps aaaaaaaaaaaa) > real waiting (keeps aaaaaaaaaaaa)" in (
        rollout_line(status)
    )
    html = stages_html(status)
    assert '<li data-stage="rolling">sim: rolling (verified here: <a class="rev"' in html
    assert "<code>aaaaaaaaaaaa</code></a>)</li>" in html
    assert '<li data-stage="waiting">real: waiting' in html


def test_plan_lists_the_stages_and_each_robots_stage_wave(lab: Lab) -> None:
    from robotconf.configurator.plan import format_plan_text, make_plan

    base, head = build(lab, "a"), build(lab, "b")
    plan = make_plan(base, head, head.rollout)
    assert plan.stages == ["sim (Gazebo; soak 5 goals)", "real (Real)"]
    waves = {change.robot_id: change.wave for change in plan.changes}
    assert waves["tb3-01"] == "sim/canary" and waves["tb3-04"] == "real/all"
    text = format_plan_text(plan)
    assert (
        "stages (each verified before the next): sim (Gazebo; soak 5 goals) → real (Real)" in text
    )


# ------------------------------------------------------------------ a stage's own revision


def to_real(run: RolloutRun) -> None:
    """Steps `run` through sim (both waves, then the soak) to the real stage's first wave."""
    run.step(T0)
    run.report(["tb3-01"], "succeeded")
    run.step(T0 + 20)
    run.report(["tb3-02"], "succeeded")
    run.step(T0 + 40)
    run.report(SIM, "succeeded", each=2)
    rolling = run.step(T0 + 60)
    assert rolling.status is not None and rolling.status.stage == "real"


def digests(step: RolloutStep, robots: list[str]) -> dict[str, str]:
    """What `robots` hold after `step`: what it sends them, or what they held (kept)."""
    held = {robot: request.digest for robot, request in step.requests.items()}
    assert not step.keep & set(robots), "kept as they are: ask the run what they hold"
    return {robot: held[robot] for robot in robots}


def test_a_failure_on_the_real_robots_rolls_back_only_the_real_stage(lab: Lab) -> None:
    run = Run(lab)
    to_real(run)
    run.states["tb3-04"] = AgentState.BACKOFF  # a real robot's brain crashes on the head
    stopped = run.step(T0 + 70)
    assert stopped.status is not None and stopped.status.state == "RolledBack"
    assert not stopped.serve_stable  # sim keeps the head, verified there
    head, stable = run.head.requests, run.stable.requests
    assert digests(stopped, SIM) == {r: head[r].digest for r in SIM}
    assert digests(stopped, REAL) == {r: stable[r].digest for r in REAL}
    assert [(s.name, s.state, s.verified_revision) for s in stopped.status.stages] == [
        ("sim", "verified", "b" * 40),
        ("real", "failed", "a" * 40),
    ]
    assert "rolled back stage 'real' to aaaaaaaaaaaa" in stopped.status.message
    assert "stage 'sim' keeps bbbbbbbbbbbb, verified there" in stopped.status.message
    # Read back (the next step, a restarted reconciler): the same robots hold the same.
    again = run.step(T0 + 80)
    assert again.status is not None and again.status.state == "RolledBack"
    assert digests(again, SIM + REAL) == digests(stopped, SIM + REAL)


def test_a_verified_stage_failing_later_is_revoked_and_rolled_back(lab: Lab) -> None:
    run = Run(lab)
    to_real(run)
    run.states["tb3-03"] = AgentState.FAILED  # a sim robot fails while the real ones roll
    stopped = run.step(T0 + 70)
    assert stopped.status is not None and stopped.status.state == "RolledBack"
    assert stopped.serve_stable  # every stage goes back to what it kept: the stable revision
    assert [(s.name, s.state, s.verified_revision) for s in stopped.status.stages] == [
        ("sim", "revoked", "a" * 40),
        ("real", "waiting", "a" * 40),
    ]
    assert [(n.stage, n.wave_name, n.verdict) for n in stopped.verdicts] == [
        ("sim", "sim", "Failed")
    ]
    assert "verification of stage 'sim' revoked" in stopped.verdicts[0].message
    assert stopped.status.verification is not None
    assert stopped.status.verification.verdict == "Failed"  # told: verification_failed
    assert "tb3-03" in stopped.status.message


def test_a_crash_within_max_failures_revokes_nothing(lab: Lab) -> None:
    run = Run(lab, POLICY.replace("healthy_after: 10", "healthy_after: 10\n  max_failures: 1"))
    to_real(run)
    run.states["tb3-03"] = AgentState.FAILED
    going = run.step(T0 + 70)
    assert going.status is not None and going.status.state == "Progressing"
    assert [s.state for s in going.status.stages] == ["verified", "rolling"]


def test_the_next_revision_keeps_each_stage_on_what_was_verified_for_it(lab: Lab) -> None:
    first = Run(lab)
    to_real(first)
    first.states["tb3-04"] = AgentState.BACKOFF
    stopped = first.step(T0 + 70)  # sim keeps b (verified), real went back to a
    assert stopped.status is not None
    third = build(lab, "c")
    held = {r: q.digest for r, q in stopped.requests.items()}
    run = RolloutRun(first.stable, third, previous=stopped.status, held=held)
    run.builds = {first.head.revision: first.head}
    begun = run.step(T0 + 100)
    assert begun.status is not None and begun.status.stage == "sim"
    assert [(s.state, s.verified_revision) for s in begun.status.stages] == [
        ("rolling", "b" * 40),
        ("waiting", "a" * 40),
    ]
    assert {r: run.launches()[r] for r in REAL} == {
        r: first.stable.requests[r].digest for r in REAL
    }
    run.states["tb3-01"] = AgentState.FAILED  # the canary fails c in sim
    back = run.step(T0 + 110)
    assert back.status is not None and back.status.state == "RolledBack"
    assert not back.serve_stable
    # Sim goes back to b, verified there, not to the stable a; real keeps a.
    assert digests(back, SIM) == {r: first.head.requests[r].digest for r in SIM}
    assert digests(back, REAL) == {r: first.stable.requests[r].digest for r in REAL}
    assert "rolled back stage 'sim' to bbbbbbbbbbbb, 'real' to aaaaaaaaaaaa" in (
        back.status.message
    )


def test_each_stage_keeps_what_was_verified_for_it_across_a_restart(lab: Lab) -> None:
    head = build(lab, "c")
    rolling = StageState(
        name="real", state="rolling", verified_revision="a" * 40, rollback_revision="a" * 40
    )
    mine = RolloutStatus(
        revision=head.revision,
        state="Progressing",
        stages=[
            StageState(
                name="sim", state="verified", verified_revision="c" * 40, rollback_revision="b" * 40
            ),
            rolling,
        ],
    )
    # Restarted mid-rollout: what sim goes back to is what it kept when the rollout began.
    assert stage_bases(head, mine, "a" * 40) == ["b" * 40, "a" * 40]
    # A new head: what each stage verified last; a stage never named keeps the stable one.
    other = mine.model_copy(update={"revision": "d" * 40, "stages": mine.stages[:1]})
    assert stage_bases(head, other, "a" * 40) == ["c" * 40, "a" * 40]
    assert stage_bases(head, None, "a" * 40) == ["a" * 40, "a" * 40]
