"""Rollouts verified by goal outcomes, pure: a healthy wave waits for its evidence, passes on
it, fails and rolls back on it, pauses when it is inconclusive, and an operator's resume or
abort of that very wave run (a git note) decides it."""

from __future__ import annotations

import pytest

from robotconf.configurator.render import FleetRender, render_fleet
from robotconf.contract.notes import VerdictNote
from robotconf.reconciler.evidence import EvidenceKey
from robotconf.reconciler.rollout import VERIFY_POLL, RolloutStep
from tests.support.lab import Lab
from tests.support.rollout_run import T0, RolloutRun

ROBOTS = ["tb3-01", "tb3-02", "tb3-03", "tb3-04"]
POLICY = """\
rollout:
  waves: [{name: canary, selector: {ring: canary}}, {name: all}]
  healthy_after: 10
  wave_timeout: 100
  verify: {%s}
"""


def fleet(lab: Lab, version: str, verify: str) -> FleetRender:
    robots = "".join(
        f"  {robot}: {{scenario: delivery-gazebo, name: bot {version}, "
        f"namespace: {robot.replace('-', '_')}"
        + (", labels: {ring: canary}" if robot == "tb3-01" else "")
        + "}\n"
        for robot in ROBOTS
    )
    lab.write("configs/fleet.yaml", "robots:\n" + robots + POLICY % verify)
    checked = lab.check()
    assert checked.ok, checked.errors
    rendered = render_fleet(checked.repo)
    rendered.revision = version * 40
    return rendered


class Run(RolloutRun):
    """One rollout of `head` over `stable` (the policy's `verify` fields given)."""

    def __init__(self, lab: Lab, verify: str) -> None:
        super().__init__(fleet(lab, "a", verify), fleet(lab, "b", verify))

    def report(  # type: ignore[override]
        self, robot: str, outcome: str, n: int = 1, code: str | None = None
    ) -> None:
        super().report([robot], outcome, n, code)


def wave_of(result: RolloutStep) -> tuple[str, int]:
    assert result.status is not None
    return result.status.state, result.status.wave


def test_a_healthy_wave_waits_for_its_evidence_then_passes_on_it(lab: Lab) -> None:
    run = Run(lab, "min_goals: 3, success_rate: 0.6")
    run.step(T0)
    waiting = run.step(T0 + 20)  # healthy (10 s), no goals yet
    assert wave_of(waiting) == ("Progressing", 0)
    assert waiting.status is not None and waiting.status.verification is not None
    assert waiting.status.verification.verdict is None
    assert "verifying: 0 of 3 goals" in waiting.status.message
    assert waiting.recheck_at == T0 + 20 + VERIFY_POLL
    run.report("tb3-01", "succeeded", 2)
    run.report("tb3-01", "failed", 1)
    passed = run.step(T0 + 30)
    assert wave_of(passed) == ("Progressing", 1)  # the next wave: its own evidence to gather
    assert [(n.wave_name, n.verdict) for n in passed.verdicts] == [("canary", "Successful")]
    assert passed.verdicts[0].goals == 3 and passed.verdicts[0].rate == pytest.approx(2 / 3)


def test_a_wave_whose_robots_fail_their_goals_rolls_back(lab: Lab) -> None:
    run = Run(lab, "min_goals: 10, success_rate: 0.9")
    run.step(T0)
    run.report("tb3-01", "failed", 1)
    run.report("tb3-01", "succeeded", 2)
    assert wave_of(run.step(T0 + 5)) == ("Progressing", 0)  # 9 of 10 would still make 90%...
    run.report("tb3-01", "failed", 1)  # ...8 of 10 would not: out of reach
    failed = run.step(T0 + 6)  # before it is even healthy
    assert wave_of(failed) == ("RolledBack", 0)
    assert failed.serve_stable
    assert failed.status is not None and "verification of wave 'canary' failed" in (
        failed.status.message
    )
    assert [n.verdict for n in failed.verdicts] == ["Failed"]


def test_inconclusive_pauses_and_an_operators_resume_of_that_run_passes_it(lab: Lab) -> None:
    run = Run(lab, "min_goals: 5, timeout: 60")
    first = run.step(T0)
    paused = run.step(T0 + 60)
    assert wave_of(paused) == ("Paused", 0)
    assert paused.status is not None and "robotconf rollout resume" in paused.status.message
    assert [n.verdict for n in paused.verdicts] == ["Inconclusive"]
    assert wave_of(run.step(T0 + 500)) == ("Paused", 0)  # it stays so: a person decides
    assert first.status is not None
    # A resume of another run of this wave (an earlier rollout of the commit) is not this one's.
    run.notes = [resume(run, 0, T0 - 1000)]
    assert wave_of(run.step(T0 + 501)) == ("Paused", 0)
    run.notes = [resume(run, 0, T0)]
    resumed = run.step(T0 + 502)
    assert wave_of(resumed) == ("Progressing", 1)
    assert [(n.verdict, n.by) for n in resumed.verdicts] == [("Inconclusive", "ada")]


def test_a_restarted_reconciler_keeps_a_paused_wave_paused_until_it_can_judge(lab: Lab) -> None:
    run = Run(lab, "min_goals: 5, timeout: 60")
    run.step(T0)
    paused = run.step(T0 + 60)
    assert wave_of(paused) == ("Paused", 0) and paused.status is not None
    run.blind = True  # the robots' statuses not learned yet: nothing is judged
    blind = run.step(T0 + 70)
    assert wave_of(blind) == ("Paused", 0)  # not Progressing: that would read as a resume
    assert blind.status is not None and blind.status.message == paused.status.message
    run.blind = False
    assert wave_of(run.step(T0 + 80)) == ("Paused", 0)


def test_an_abort_rolls_the_wave_back_at_once(lab: Lab) -> None:
    run = Run(lab, "min_goals: 5")
    run.step(T0)
    run.notes = [resume(run, 0, T0).model_copy(update={"kind": "abort"})]
    aborted = run.step(T0 + 1)
    assert wave_of(aborted) == ("RolledBack", 0) and aborted.serve_stable
    assert aborted.status is not None and "aborted by ada" in aborted.status.message


@pytest.mark.parametrize(
    ("inconclusive", "state"), [("fail", "RolledBack"), ("pass", "Progressing")]
)
def test_the_policy_says_what_inconclusive_does(lab: Lab, inconclusive: str, state: str) -> None:
    run = Run(lab, f"min_goals: 5, timeout: 60, inconclusive: {inconclusive}")
    run.step(T0)
    assert run.step(T0 + 60).status.state == state  # type: ignore[union-attr]


def test_a_dry_run_judges_and_shows_but_gates_on_health_alone(lab: Lab) -> None:
    run = Run(lab, "min_goals: 1, success_rate: 1.0, dry_run: true")
    run.step(T0)
    run.report("tb3-01", "failed", 3)
    shadow = run.step(T0 + 20)
    assert wave_of(shadow) == ("Progressing", 1)  # healthy: on to the next wave
    assert [(n.verdict, n.dry_run) for n in shadow.verdicts] == [("Failed", True)]


def test_a_critical_code_fails_a_wave_that_otherwise_succeeds(lab: Lab) -> None:
    run = Run(lab, "min_goals: 10, critical: [COLLISION]")
    run.step(T0)
    run.report("tb3-01", "succeeded", 9)
    run.report("tb3-01", "failed", 1, code="COLLISION")
    failed = run.step(T0 + 20)
    assert wave_of(failed) == ("RolledBack", 0)
    assert failed.status is not None and "critical failure code COLLISION" in failed.status.message


def test_evidence_of_another_wave_is_no_evidence(lab: Lab) -> None:
    run = Run(lab, "min_goals: 1")
    run.step(T0)
    run.report("tb3-01", "succeeded", 5)
    assert run.evidence is not None
    run.evidence.key = EvidenceKey(run.head.revision, 0, T0 - 1)  # an earlier run's counts
    assert wave_of(run.step(T0 + 20)) == ("Progressing", 0)  # still gathering


def resume(run: Run, wave: int, started_at: float) -> VerdictNote:
    return VerdictNote(
        kind="resume",
        revision=run.head.revision,
        at=T0 + 400,
        wave=wave,
        started_at=started_at,
        by="ada",
    )
