"""The rollout line of `robotconf status` and `up` with `rollout.verify`: the wave's evidence
said once, a wave paused on it with why and the commands that decide it; `status --json`
carries the verification as the reconciler published it."""

from __future__ import annotations

from robotconf.contract.wire import ReconcilerStatus, RolloutStatus, WaveVerification
from robotconf.readmodel.verdicts import (
    FleetStatus,
    evidence_words,
    paused_for_evidence,
    rollout_line,
)
from robotconf.workstation.cli.fleet_view import fleet_status_text
from tests.support.lab import Lab
from tests.unit.reconciler.test_rollout_verify import T0, Run

HEAD, OLD = "b" * 40, "a" * 40
EVIDENCE = "14 of 20 goals, 92% ≥ 90%"


def verification(**update: object) -> WaveVerification:
    found = WaveVerification(
        goals=14, min_goals=20, succeeded=13, failed=1, robots=3, rate=0.92, success_rate=0.9
    )
    return found.model_copy(update={"message": EVIDENCE, **update})


def rollout(
    found: WaveVerification | None, state: str = "Progressing", message: str = ""
) -> RolloutStatus:
    return RolloutStatus.model_validate(
        {
            "revision": HEAD,
            "stable_revision": OLD,
            "state": state,
            "wave": 1,
            "waves": 3,
            "wave_name": "half",
            "counts": {"healthy": 3, "failed": 0, "pending": 0},
            "verification": found,
            "message": message,
        }
    )


def test_the_evidence_follows_the_wave_s_robots() -> None:
    line = rollout_line(rollout(verification()))
    assert line == (
        "rollout: bbbbbbbbbbbb Progressing, wave 2/3 (half): 3 healthy, 0 failed, 0 pending; "
        f"stable aaaaaaaaaaaa; evidence {EVIDENCE}"
    )


def test_without_verify_the_line_is_as_before() -> None:
    line = rollout_line(rollout(None, message="on its way"))
    assert "evidence" not in line and line.endswith("stable aaaaaaaaaaaa — on its way")


def test_evidence_the_message_quotes_is_said_once() -> None:
    why = f"wave 'half' verifying: {EVIDENCE}"
    line = rollout_line(rollout(verification(), message=why))
    assert line.count(EVIDENCE) == 1 and "; evidence" not in line
    assert line.endswith(f"stable aaaaaaaaaaaa — {why}")


def test_a_wave_paused_on_its_evidence_says_why_and_the_commands_once(lab: Lab) -> None:
    run = Run(lab, "min_goals: 5, timeout: 60")
    run.step(T0)
    paused = run.step(T0 + 60)
    assert paused.status is not None and paused.status.verification is not None
    assert paused_for_evidence(paused.status)
    line = rollout_line(paused.status)
    assert line.startswith("rollout: bbbbbbbbbbbb Paused, wave 1/2 (canary): 1 healthy")
    assert "inconclusive (0 of 5 goals: Inconclusive (too few goals ended by the deadline))" in (
        line
    )
    assert line.count("robotconf rollout resume") == 1
    assert line.count("robotconf rollout abort") == 1
    assert line.count("0 of 5 goals") == 1


def test_the_commands_are_named_when_the_message_does_not() -> None:
    found = verification(verdict="Inconclusive", message=f"{EVIDENCE}: Inconclusive")
    line = rollout_line(rollout(found, "Paused", message="held"))
    assert line.endswith(
        "— held — robotconf rollout resume passes it, robotconf rollout abort rolls back"
    )
    assert f"; evidence {EVIDENCE}: Inconclusive" in line


def test_no_commands_where_no_operator_decides() -> None:
    inconclusive = verification(verdict="Inconclusive")
    for status in (
        rollout(inconclusive, "Progressing"),  # inconclusive: pass or fail decided it
        rollout(inconclusive.model_copy(update={"dry_run": True}), "Paused"),  # rollout.paused
        rollout(inconclusive.model_copy(update={"decided_by": "ada"}), "Paused"),
        rollout(verification(verdict="Successful"), "Paused"),
    ):
        assert not paused_for_evidence(status)
        assert "robotconf rollout resume" not in rollout_line(status)


def test_who_decided_by_hand_and_a_dry_run_are_said() -> None:
    assert evidence_words(verification(verdict="Inconclusive", decided_by="ada")) == (
        f"{EVIDENCE}; resumed by ada"
    )
    assert evidence_words(verification(verdict="Failed", decided_by="bo")).endswith("aborted by bo")
    shadow = verification(dry_run=True, message=f"{EVIDENCE}: Failed [dry run: not gating]")
    assert rollout_line(rollout(shadow)).endswith("Failed [dry run: not gating]")
    # A status without the reconciler's words still says what was counted.
    assert evidence_words(verification(message="")) == "14 of 20 goals"


def test_evidence_from_the_broker_is_printed_safely() -> None:
    line = rollout_line(rollout(verification(message="1 of 2\x1b[2J", decided_by="e\nve")))
    assert "\x1b" not in line and "\n" not in line
    assert "\\x1b[2J" in line and "e\\nve" in line


def test_status_shows_the_line_and_its_json_the_verification() -> None:
    found = verification(verdict="Successful", deadline=T0 + 600, critical=["COLLISION"])
    reconciler = ReconcilerStatus(
        state="Progressing", ready=False, last_applied_revision=OLD, rollout=rollout(found)
    )
    fleet = FleetStatus([], reconciler, "t")
    assert f"; evidence {EVIDENCE}\n" in fleet_status_text(fleet)
    shown = fleet.as_json()["reconciler"]["rollout"]["verification"]
    assert shown == found.model_dump(mode="json")
    assert shown["verdict"] == "Successful" and shown["min_goals"] == 20
    assert shown["rate"] == 0.92 and shown["critical"] == ["COLLISION"]
    assert shown["message"] == EVIDENCE
