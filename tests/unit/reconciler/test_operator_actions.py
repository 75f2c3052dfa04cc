"""Operators' rollout actions, judged: bounded, parsed, signed when the lab signs, recent, and
about the wave run that stands; anything else refused, with an answer when the asker is known."""

from __future__ import annotations

from pathlib import Path

import pytest

from robotconf.contract.launch import RolloutAction
from robotconf.contract.signing import generate_keys, load_private_key, sign
from robotconf.contract.wire import RolloutStatus, StageState, WaveVerification
from robotconf.reconciler.operator_actions import (
    MAX_ACTION_BYTES,
    RECENT,
    Refused,
    Taken,
    judge_action,
)

REV = "b" * 40
T0 = 1_000_000.0
PAUSED = RolloutStatus(
    revision=REV,
    state="Paused",
    wave=1,
    waves=3,
    wave_name="half",
    wave_started_at=T0 - 100,
    verification=WaveVerification(verdict="Inconclusive", min_goals=20, goals=3),
)


def action(kind: str = "resume", **changes: object) -> RolloutAction:
    fields: dict[str, object] = {
        "action": kind,
        "revision": REV,
        "wave": 1,
        "wave_started_at": T0 - 100,
        "requested_by": "ada",
        "issued_at": T0,
        **changes,
    }
    return RolloutAction.model_validate(fields)


def test_a_resume_of_the_paused_run_is_taken_as_a_note_naming_who() -> None:
    found = judge_action(action().payload(), PAUSED, T0 + 1, None)
    assert isinstance(found, Taken)
    assert (found.note.kind, found.note.wave, found.note.started_at, found.note.by) == (
        "resume",
        1,
        T0 - 100,
        "ada",
    )
    assert found.answer.accepted and found.answer.message == "wave 'half' resumed by ada"


@pytest.mark.parametrize(
    ("rollout", "given", "why"),
    [
        (None, {}, "no rollout"),
        (PAUSED.model_copy(update={"revision": "c" * 40}), {}, "not bbbbbbbbbbbb"),
        (PAUSED.model_copy(update={"state": "RolledBack"}), {}, "is RolledBack"),
        (PAUSED, {"wave": 0}, "has moved on"),
        (PAUSED, {"wave_started_at": T0 - 5000}, "has moved on"),
        (PAUSED.model_copy(update={"state": "Progressing"}), {}, "not paused"),
        (PAUSED.model_copy(update={"verification": None}), {}, "rollout.paused"),
        (PAUSED, {"issued_at": T0 - RECENT - 1}, "only actions within"),
    ],
)
def test_an_action_about_anything_but_the_run_that_stands_is_refused(
    rollout: RolloutStatus | None, given: dict[str, object], why: str
) -> None:
    found = judge_action(action(**given).payload(), rollout, T0, None)
    assert isinstance(found, Refused) and why in found.why
    assert found.answer is not None and not found.answer.accepted


def test_an_abort_is_taken_while_the_wave_progresses() -> None:
    running = PAUSED.model_copy(update={"state": "Progressing", "verification": None})
    found = judge_action(action("abort").payload(), running, T0, None)
    assert isinstance(found, Taken) and found.note.kind == "abort"


@pytest.mark.parametrize(
    "payload",
    [
        b"",
        b"{not json",
        b"[]",
        b'{"kind": "RolloutAction", "action": "explode"}',
        b"x" * (MAX_ACTION_BYTES + 1),
        b'{"action": "resume", "revision": "../../etc", "wave": 1, "wave_started_at": 1,'
        b' "requested_by": "ada", "issued_at": 1}',
    ],
)
def test_what_is_not_an_action_is_refused_unanswered(payload: bytes) -> None:
    found = judge_action(payload, PAUSED, T0, None)
    assert isinstance(found, Refused) and found.answer is None


def test_where_the_lab_signs_only_a_signed_unaltered_action_is_taken(tmp_path: Path) -> None:
    pair = generate_keys(tmp_path / "keys")
    other = generate_keys(tmp_path / "other")
    key = load_private_key(pair.private)
    public = key.public_key()
    signed = sign(action(), key, T0)
    assert isinstance(judge_action(signed.payload(), PAUSED, T0, public), Taken)
    unsigned = judge_action(action().payload(), PAUSED, T0, public)
    assert isinstance(unsigned, Refused) and "not signed" in unsigned.why
    assert "this reconciler requires" in unsigned.why
    forged = sign(action(), load_private_key(other.private), T0)
    assert isinstance(judge_action(forged.payload(), PAUSED, T0, public), Refused)
    altered = signed.model_copy(update={"action": "abort"})
    found = judge_action(altered.payload(), PAUSED, T0, public)
    assert isinstance(found, Refused) and "altered" in found.why


STAGED = PAUSED.model_copy(
    update={
        "state": "Progressing",
        "verification": None,
        "stage": "sim",
        "stages": [
            StageState(name="sim", state="rolling", verified_revision="a" * 40),
            StageState(name="real", state="waiting", verified_revision="a" * 40),
        ],
    }
)


@pytest.mark.parametrize(
    ("stage", "rollout", "why"),
    [
        ("real", STAGED, None),
        ("sim", STAGED, "already on stage 'sim' (rolling)"),
        ("moon", STAGED, "no stage 'moon' (stages: sim, real)"),
        ("real", STAGED.model_copy(update={"stages": []}), "fleet.yaml has no stages"),
        ("real", STAGED.model_copy(update={"state": "Complete"}), "is Complete"),
        ("real", STAGED.model_copy(update={"revision": "c" * 40}), "not bbbbbbbbbbbb"),
    ],
)
def test_a_promotion_names_a_stage_the_revision_under_way_has_not_reached(
    stage: str, rollout: RolloutStatus, why: str | None
) -> None:
    found = judge_action(action("promote", stage=stage).payload(), rollout, T0, None)
    if why is None:
        assert isinstance(found, Taken)
        assert (found.note.kind, found.note.stage, found.note.by) == ("promote", "real", "ada")
        assert found.answer.message == "bbbbbbbbbbbb promoted to stage 'real' by ada"
    else:
        assert isinstance(found, Refused) and why in found.why
