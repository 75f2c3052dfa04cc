"""Metrics of rollout verification: each wave verdict counted once, the pause gauge, and the
current wave's evidence shown only while there is some (no 0 before it, no NaN)."""

from __future__ import annotations

import pytest
from prometheus_client import generate_latest

from robotconf.contract.notes import VerdictNote
from robotconf.contract.wire import RolloutState, RolloutStatus, Verdict, WaveVerification
from robotconf.reconciler.metrics import COUNTED, Metrics, RolloutGauges, count_verdicts

REV = "b" * 40
VERIFICATIONS = "robotconf_rollout_verifications_total"


def note(
    verdict: Verdict | None,
    *,
    wave: int = 0,
    started: float = 100.0,
    dry_run: bool = False,
    by: str | None = None,
    revision: str = REV,
) -> VerdictNote:
    return VerdictNote(
        kind="verification",
        revision=revision,
        at=150.0,
        wave=wave,
        started_at=started,
        verdict=verdict,
        dry_run=dry_run,
        by=by,
    )


def rollout(
    state: RolloutState, goals: int | None = None, rate: float | None = None
) -> RolloutStatus:
    found = WaveVerification(goals=goals, rate=rate) if goals is not None else None
    return RolloutStatus(revision=REV, state=state, verification=found)


def counted(metrics: Metrics, verdict: str, dry_run: str = "false") -> float | None:
    return metrics.registry.get_sample_value(
        VERIFICATIONS, {"verdict": verdict, "dry_run": dry_run}
    )


def test_a_fresh_reconciler_shows_every_verdict_at_zero_and_no_evidence() -> None:
    metrics = Metrics()
    for verdict in ("Successful", "Failed", "Inconclusive"):
        assert counted(metrics, verdict) == 0.0 and counted(metrics, verdict, "true") == 0.0
    assert metrics.registry.get_sample_value("robotconf_rollout_paused") == 0.0
    text = generate_latest(metrics.registry).decode()
    assert "robotconf_rollout_wave_goals" not in text
    assert "robotconf_rollout_wave_success_rate" not in text


def test_each_wave_verdict_is_counted_once_however_often_it_is_noted() -> None:
    metrics = Metrics()
    paused = rollout("Paused", 3)
    metrics.rollout(paused, [note("Inconclusive")])
    metrics.rollout(paused, [note("Inconclusive")])  # noted again at each step of the pause
    metrics.rollout(rollout("Progressing"), [note("Inconclusive", by="ada")])  # resumed by hand
    metrics.rollout(rollout("Progressing"), [note("Successful", wave=1, started=200.0)])
    metrics.rollout(rollout("Progressing"), [note("Failed", wave=2, started=300.0, dry_run=True)])
    metrics.rollout(rollout("Progressing"), [note(None, wave=3, started=400.0, by="ada")])
    assert counted(metrics, "Inconclusive") == 1.0
    assert counted(metrics, "Successful") == 1.0
    assert counted(metrics, "Failed") == 0.0 and counted(metrics, "Failed", "true") == 1.0


def test_a_later_run_of_the_same_wave_is_another_verdict() -> None:
    memory, fresh = count_verdicts((), [note("Failed"), note("Failed")])
    assert len(fresh) == 1
    memory, fresh = count_verdicts(memory, [note("Failed", started=900.0)])
    assert len(fresh) == 1 and len(memory) == 2


def test_the_memory_of_counted_verdicts_is_bounded() -> None:
    notes = [note("Successful", revision=f"{n:040x}") for n in range(COUNTED + 10)]
    memory, fresh = count_verdicts((), notes)
    assert len(fresh) == COUNTED + 10 and len(memory) == COUNTED
    assert count_verdicts(memory, notes[-1:])[1] == []  # the newest are still remembered


def test_the_pause_gauge_and_the_current_waves_evidence() -> None:
    metrics = Metrics()
    value = metrics.registry.get_sample_value
    metrics.rollout(rollout("Progressing", 0), [])  # verifying, no decided goal yet: no rate
    assert value("robotconf_rollout_paused") == 0.0
    assert value("robotconf_rollout_wave_goals") == 0.0
    assert value("robotconf_rollout_wave_success_rate") is None
    assert "NaN" not in generate_latest(metrics.registry).decode()
    metrics.rollout(rollout("Paused", 12, 0.75), [])
    assert value("robotconf_rollout_paused") == 1.0
    assert value("robotconf_rollout_wave_goals") == 12.0
    assert value("robotconf_rollout_wave_success_rate") == pytest.approx(0.75)
    metrics.rollout(rollout("Complete"), [])  # no wave verified now: no evidence shown
    assert value("robotconf_rollout_paused") == 0.0
    assert value("robotconf_rollout_wave_goals") is None
    assert value("robotconf_rollout_wave_success_rate") is None
    metrics.rollout(None, [])
    assert RolloutGauges.of(None) == RolloutGauges()


def test_each_stage_says_whether_the_revision_is_verified_on_it() -> None:
    from robotconf.contract.wire import StageState

    metrics = Metrics()
    staged = RolloutStatus(
        revision=REV,
        state="Progressing",
        stage="real",
        stages=[
            StageState(name="sim", state="verified"),
            StageState(name="real", state="rolling"),
        ],
    )
    metrics.rollout(staged, [])
    text = generate_latest(metrics.registry).decode()
    assert 'robotconf_rollout_stage_verified{stage="sim"} 1.0' in text
    assert 'robotconf_rollout_stage_verified{stage="real"} 0.0' in text
