"""Alert events of rollout verification, pure: a paused rollout, its resumption, a wave's failed
verification; each told once per transition, never again at a resync, with bounded memory."""

from __future__ import annotations

from dataclasses import replace

from robotconf.contract.notes import VerdictNote
from robotconf.contract.wire import (
    ReconcilerStatus,
    RolloutState,
    RolloutStatus,
    StageState,
    Verdict,
    WaveVerification,
)
from robotconf.readmodel.events import (
    REMEMBERED,
    RESUMERS,
    Event,
    Kind,
    Seen,
    Told,
    resumed,
    resumers,
    transitions,
)

REV, NEXT = "b" * 40, "c" * 40
INCONCLUSIVE = (
    "wave 'canary' inconclusive (3 of 10 goals): robotconf rollout resume passes it, "
    "robotconf rollout abort rolls back"
)


def verification(
    verdict: Verdict | None, *, dry_run: bool = False, by: str | None = None
) -> WaveVerification:
    return WaveVerification(
        verdict=verdict,
        dry_run=dry_run,
        goals=10,
        min_goals=10,
        rate=0.5,
        success_rate=0.9,
        decided_by=by,
        message="rate 0.50 < success_rate 0.90 over 10 goals",
    )


def status(
    state: RolloutState,
    *,
    revision: str = REV,
    wave: int = 0,
    started: float | None = 100.0,
    found: WaveVerification | None = None,
    message: str = "",
) -> Seen:
    rollout = RolloutStatus(
        revision=revision,
        state=state,
        wave=wave,
        waves=3,
        wave_name=("canary", "half", "rest")[wave],
        wave_started_at=started,
        verification=found,
        message=message,
    )
    reconciler = ReconcilerStatus(
        state="Progressing",
        ready=False,
        reason="Progressing",
        branch="main",
        last_applied_revision=revision,
        rollout=rollout,
    )
    return Seen(reconciler)


def run(seens: list[Seen], told: Told | None = None) -> tuple[Told, list[list[Event]]]:
    """The events of each observation in turn, the memory carried along."""
    told, out = told or Told(), []
    for seen in seens:
        told, events = transitions(told, seen, 1.0)
        out.append(events)
    return told, out


def kinds(steps: list[list[Event]]) -> list[list[Kind]]:
    return [[e.kind for e in step] for step in steps]


def test_an_inconclusive_pause_is_told_once_and_its_resume_once_naming_who() -> None:
    paused = status("Paused", found=verification("Inconclusive"), message=INCONCLUSIVE)
    # The operator's resume: the status shows it on the resumed wave when it is still there.
    resumed = status("Progressing", found=verification("Inconclusive", by="ada"))
    _, steps = run([status("Progressing"), paused, paused, resumed, resumed])
    assert kinds(steps) == [[], [Kind.ROLLOUT_PAUSED], [], [Kind.ROLLOUT_RESUMED], []]
    told_paused, told_resumed = steps[1][0], steps[3][0]
    assert told_paused.reason == "Paused" and told_paused.revision == REV
    assert "paused at wave 'canary' (1 of 3)" in told_paused.message
    assert "robotconf rollout resume" in told_paused.message
    assert "robotconf rollout abort" in told_paused.message
    assert "resumed by ada after wave 'canary'" in told_resumed.message
    assert told_resumed.reason == "Progressing"


def test_a_pause_by_fleet_yaml_is_told_and_its_resume_without_a_name() -> None:
    paused = status("Paused", message="paused (rollout.paused): a commit setting it false resumes")
    _, steps = run([paused, paused, status("Progressing", wave=1, started=200.0)])
    assert kinds(steps) == [[Kind.ROLLOUT_PAUSED], [], [Kind.ROLLOUT_RESUMED]]
    assert "paused (rollout.paused)" in steps[0][0].message
    assert "resumed after wave 'canary'" in steps[2][0].message
    assert " by " not in steps[2][0].message


def test_each_wave_run_paused_is_told_and_a_later_pause_implies_a_resume() -> None:
    first = status("Paused", message="inconclusive")
    second = status("Paused", wave=1, started=200.0, message="inconclusive")
    _, steps = run([first, second, second, status("Complete", wave=2, started=None)])
    assert kinds(steps) == [
        [Kind.ROLLOUT_PAUSED],
        [Kind.ROLLOUT_RESUMED, Kind.ROLLOUT_PAUSED],
        [],
        [Kind.ROLLOUT_RESUMED],
    ]


def test_a_paused_rollout_aborted_or_replaced_is_not_told_resumed() -> None:
    paused = status("Paused", message="inconclusive")
    aborted = status("RolledBack", message="aborted by ada in wave 'canary'")
    _, steps = run([paused, aborted, status("Progressing")])
    assert kinds(steps) == [[Kind.ROLLOUT_PAUSED], [Kind.ROLLOUT_ROLLED_BACK], []]
    _, steps = run([paused, status("Progressing", revision=NEXT), status("Progressing")])
    assert kinds(steps) == [[Kind.ROLLOUT_PAUSED], [], []]


def test_a_pause_is_remembered_while_the_status_names_no_rollout() -> None:
    paused = status("Paused", message="inconclusive")
    no_rollout = Seen(ReconcilerStatus(state="Stalled", ready=False, branch="main"))
    _, steps = run([paused, no_rollout, Seen(None), paused, status("Progressing", wave=1)])
    assert kinds(steps) == [[Kind.ROLLOUT_PAUSED], [], [], [], [Kind.ROLLOUT_RESUMED]]


def test_a_failed_verification_is_told_once_per_wave_with_the_rollback() -> None:
    failed = verification("Failed")
    gathering = status("Progressing", found=verification(None))
    rolled_back = status("RolledBack", found=failed, message="verification of wave failed")
    _, steps = run([gathering, rolled_back, rolled_back])
    assert kinds(steps) == [[], [Kind.VERIFICATION_FAILED, Kind.ROLLOUT_ROLLED_BACK], []]
    told = steps[1][0]
    assert told.reason == "Failed" and told.revision == REV
    assert "failed at wave 'canary' (1 of 3): rate 0.50 < success_rate 0.90" in told.message
    assert "dry run" not in told.message


def test_a_dry_run_failure_is_told_once_as_not_gating() -> None:
    shadow = status("Progressing", found=verification("Failed", dry_run=True))
    next_wave = status("Progressing", wave=1, started=200.0, found=verification(None))
    _, steps = run([shadow, shadow, next_wave, shadow])
    assert kinds(steps) == [[Kind.VERIFICATION_FAILED], [], [], []]
    assert steps[0][0].reason == "DryRun"
    assert "(dry run: not gating)" in steps[0][0].message


def test_other_verdicts_are_not_told() -> None:
    verdicts: tuple[Verdict | None, ...] = ("Successful", "Inconclusive", None)
    for verdict in verdicts:
        found = verification(verdict)
        _, steps = run([status("Progressing", found=found)])
        assert steps == [[]]


def test_the_memory_of_pauses_and_verifications_is_bounded() -> None:
    told = Told()
    for n in range(REMEMBERED + 10):
        revision = f"{n:040x}"
        told, _ = transitions(
            told, status("Paused", revision=revision, found=verification("Failed")), 1.0
        )
    assert len(told.paused) == REMEMBERED and len(told.verifications) == REMEMBERED
    assert told.pausing is not None and told.pausing.run[0] == f"{REMEMBERED + 9:040x}"
    # The newest are still remembered: a resync tells nothing.
    _, events = transitions(
        told, status("Paused", revision=told.pausing.run[0], found=verification("Failed")), 1.0
    )
    assert events == []


def resume_note(by: str, *, wave: int = 0, started: float = 100.0) -> VerdictNote:
    """The verdict a step notes when an operator's resume passes a wave run."""
    return VerdictNote(
        kind="verification",
        revision=REV,
        at=150.0,
        wave=wave,
        started_at=started,
        verdict="Inconclusive",
        by=by,
    )


def test_the_resumer_is_named_from_the_steps_verdicts_when_the_status_moved_on() -> None:
    paused = status("Paused", found=verification("Inconclusive"), message=INCONCLUSIVE)
    # The step that passed wave 0 published wave 1 at once: its status shows wave 1's evidence.
    moved_on = status("Progressing", wave=1, started=200.0, found=verification(None))
    known = resumers({}, [resume_note("grace")])
    told, _ = transitions(Told(), paused, 1.0)
    _, events = transitions(told, replace(moved_on, resumed_by=known), 2.0)
    assert [e.kind for e in events] == [Kind.ROLLOUT_RESUMED]
    assert "resumed by grace after wave 'canary' (1 of 3): now Progressing" in events[0].message


def test_resumers_keep_the_newest_few_and_skip_verdicts_no_one_decided() -> None:
    unnamed = resume_note("x").model_copy(update={"by": None})
    known = resumers({}, [unnamed])
    assert known == {}
    for n in range(RESUMERS + 3):
        known = resumers(known, [resume_note(f"op{n}", wave=n)])
    assert len(known) == RESUMERS
    assert known[(REV, RESUMERS + 2, 100.0)] == f"op{RESUMERS + 2}"
    assert (REV, 0, 100.0) not in known


def staged(stage: str, state: RolloutState = "Progressing", revision: str = REV) -> Seen:
    seen = status(state, revision=revision)
    assert seen.status is not None and seen.status.rollout is not None
    rollout = seen.status.rollout.model_copy(
        update={
            "stage": stage,
            "stages": [
                StageState(name="sim", state="verified"),
                StageState(name="real", state="rolling"),
            ],
        }
    )
    return replace(seen, status=seen.status.model_copy(update={"rollout": rollout}))


def test_a_revision_reaching_a_later_stage_is_told_promoted_once() -> None:
    _, steps = run(
        [
            staged("sim"),
            staged("real"),
            staged("real"),
            staged("real", "Complete"),
            staged("real", revision=NEXT),
            staged("real", "RolledBack", revision="d" * 40),
        ]
    )
    assert kinds(steps)[:5] == [[], [Kind.STAGE_PROMOTED], [], [], [Kind.STAGE_PROMOTED]]
    assert Kind.STAGE_PROMOTED not in kinds(steps)[5]
    told = steps[1][0]
    assert told.reason == "Promoted" and "promoted to stage 'real'" in told.message
    assert "verified on 'sim'" in told.message


def test_a_restarted_reconciler_knows_the_standing_it_finds_was_told() -> None:
    paused = status("Paused", message="inconclusive")
    assert paused.status is not None
    # The status the reconciler before left (its Last Will keeps the rollout): its pause was
    # told; going on is told as a resumption, and the pause is not told twice.
    told = resumed(Told(), paused.status)
    _, steps = run([paused, status("Progressing", wave=1, started=200.0)], told)
    assert kinds(steps) == [[], [Kind.ROLLOUT_RESUMED]]
    rolled_back = status("RolledBack", found=verification("Failed"), message="failed")
    assert rolled_back.status is not None
    _, steps = run([rolled_back], resumed(Told(), rolled_back.status))
    assert kinds(steps) == [[]]  # told by the one before: neither the failure nor the rollback


def test_a_paused_wave_run_still_unjudged_is_not_told_resumed() -> None:
    paused = status("Paused", message="inconclusive")
    unjudged = status("Progressing", message="")  # the same wave run, no decision on it
    _, steps = run([paused, unjudged, paused])
    assert kinds(steps) == [[Kind.ROLLOUT_PAUSED], [], []]
