"""Operators' rollout actions (`robotconf rollout resume|abort`), judged: a payload from the
requests topic against the rollout as it stands -> the git note that carries it out, or why not.

Pure but for the signature check (the key is given). Nothing of a payload is trusted before it
is bounded, parsed, signed (when the lab signs) and recent; it is then carried out only when it
names the wave run that stands now. Carrying one out twice is harmless (the note is the same
decision), so a replay inside the recency window changes nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from pydantic import ValidationError

from robotconf.contract.launch import RolloutAction
from robotconf.contract.notes import VerdictNote
from robotconf.contract.safejson import PayloadError, parse_object
from robotconf.contract.textsafe import printable
from robotconf.contract.typing_errors import error_line
from robotconf.contract.wire import OperatorAnswer, RolloutStatus, short_rev

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

MAX_ACTION_BYTES = 4096
RECENT = 300.0  # seconds an action may be old (or ahead, a desk's clock) and still be taken


@dataclass(frozen=True)
class Taken:
    note: VerdictNote
    answer: OperatorAnswer


@dataclass(frozen=True)
class Refused:
    why: str
    answer: OperatorAnswer | None  # None: not readable enough to answer whom


def judge_action(
    payload: bytes,
    rollout: RolloutStatus | None,
    now: float,
    key: Ed25519PublicKey | None,
) -> Taken | Refused:
    """Whether the action in `payload` is carried out on `rollout` (the one in the reconciler's
    status now), and the note that does it."""
    read = _read(payload)
    if isinstance(read, Refused):
        return read
    data, action = read
    why: str | None = None
    if key is not None:
        from robotconf.contract.signing import verify_object

        problem = verify_object(data, key)
        why = problem.replace("this agent", "this reconciler") if problem else None
    if why is None and abs(now - action.issued_at) > RECENT:
        why = (
            f"issued {abs(now - action.issued_at):.0f} s from the reconciler's clock: only "
            f"actions within {RECENT:.0f} s are taken (clocks apart, or a replay)"
        )
    if why is None:
        why = _why_not(action, rollout)
    if why is not None or rollout is None:
        why = why or "no rollout"
        return Refused(why, _answer(action, False, why))
    note = _note(action, rollout, now)
    return Taken(note, _answer(action, True, note.message))


def _read(payload: bytes) -> tuple[dict[str, Any], RolloutAction] | Refused:
    """The payload bounded, parsed and typed; refused unanswered when it is not an action."""
    if len(payload) > MAX_ACTION_BYTES:
        return Refused(f"larger than {MAX_ACTION_BYTES} bytes", None)
    try:
        data = parse_object(payload, max_bytes=MAX_ACTION_BYTES)
    except PayloadError as exc:
        return Refused(str(exc), None)
    try:
        return data, RolloutAction.model_validate(data)
    except ValidationError as exc:
        return Refused(f"not a rollout action: {printable(error_line(exc.errors()[0]))}", None)


def _answer(action: RolloutAction, accepted: bool, message: str) -> OperatorAnswer:
    return OperatorAnswer(
        action=action.action,
        requested_by=action.requested_by,
        issued_at=action.issued_at,
        accepted=accepted,
        message=message,
    )


def _note(action: RolloutAction, rollout: RolloutStatus, now: float) -> VerdictNote:
    """The git note that carries out an action taken: a promotion is about the revision; a
    resume or an abort, about the wave run that stands."""
    if action.action == "promote":
        return VerdictNote(
            kind="promote",
            revision=action.revision,
            at=now,
            stage=action.stage,
            by=action.requested_by,
            message=f"{short_rev(action.revision)} promoted to stage '{action.stage}' "
            f"by {action.requested_by}",
        )
    verb = "resumed" if action.action == "resume" else "aborted"
    return VerdictNote(
        kind=action.action,
        revision=action.revision,
        at=now,
        wave=action.wave,
        wave_name=rollout.wave_name,
        started_at=action.wave_started_at,
        by=action.requested_by,
        message=f"wave '{rollout.wave_name}' {verb} by {action.requested_by}",
    )


def _why_not(action: RolloutAction, rollout: RolloutStatus | None) -> str | None:
    if rollout is None:
        return "no rollout: fleet.yaml has no rollout policy, or nothing was rolled out yet"
    if rollout.revision != action.revision:
        return f"the rollout is of {short_rev(rollout.revision)}, not {short_rev(action.revision)}"
    if action.action == "promote":
        return _why_not_promoted(action, rollout)
    if rollout.state not in ("Progressing", "Paused"):
        what = f"the rollout of {short_rev(rollout.revision)} is {rollout.state}"
        return f"{what}: nothing to {action.action}"
    if rollout.wave != action.wave or rollout.wave_started_at != action.wave_started_at:
        return (
            f"the rollout has moved on: it is in wave '{printable(rollout.wave_name)}' "
            f"({rollout.wave + 1} of {rollout.waves}) now; look again"
        )
    if action.action == "resume":
        if rollout.state != "Paused":
            return "the rollout is not paused: nothing to resume"
        if rollout.verification is None or rollout.verification.verdict != "Inconclusive":
            return "paused by fleet.yaml (rollout.paused): a commit setting it false resumes it"
    return None


def _why_not_promoted(action: RolloutAction, rollout: RolloutStatus) -> str | None:
    """A promotion names a stage of the rollout under way that its revision has not reached."""
    if rollout.state not in ("Progressing", "Paused"):
        what = f"the rollout of {short_rev(rollout.revision)} is {rollout.state}"
        return f"{what}: only a revision being rolled out is promoted (commit it again)"
    names = [stage.name for stage in rollout.stages]
    if action.stage not in names:
        known = ", ".join(names) if names else "none: fleet.yaml has no stages"
        return f"no stage {printable(action.stage or '')!r} (stages: {known})"
    standing = next(stage for stage in rollout.stages if stage.name == action.stage)
    if standing.state != "waiting":
        where = f"stage '{standing.name}' ({standing.state})"
        return f"{short_rev(rollout.revision)} is already on {where}"
    return None
