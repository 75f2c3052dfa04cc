"""Admission: whether a payload for this robot is admitted — a launch request (clear, accept
with warnings, or reject) or a restart asked for from the desk (carry out, or reject).

Pure: validated with the shared request types, checked against the robot's description.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

from pydantic import ValidationError

from robotconf.contract.launch import (
    API_VERSION,
    LaunchRequest,
    RestartRequest,
    StopRequest,
    canonical_json,
    template_mismatch,
)
from robotconf.contract.safejson import PayloadError, parse_object
from robotconf.contract.typing_errors import error_line
from robotconf.contract.wire import LogsRequest, RobotDescription


@dataclass(frozen=True)
class Clear:
    """No assignment: the empty payload, or a Stop (signed, when this agent verifies)."""

    issued_at: float | None = None  # of a signed Stop: it advances the replay watermark


@dataclass(frozen=True)
class Accept:
    request: LaunchRequest
    warnings: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Reject:
    reason: str
    # For a signed request dated too far ahead of this robot's clock: the wall time from which
    # the same request is no longer too far ahead (the agent looks at it again then).
    retry_at: float | None = None


Admission = Clear | Accept | Reject
# Checks the signature of the parsed JSON object; None when it is good.
Verifier = Callable[[dict[str, Any]], "str | None"]

# A launch request is a few kB; the broker's own limit may be higher.
MAX_REQUEST_BYTES = 1024 * 1024
# A restart or a logs request is a few hundred bytes.
MAX_COMMAND_BYTES = 4 * 1024
# A restart is carried out only this close (either way, seconds) to when it was issued: a
# captured one cannot be held back and replayed later.
RESTART_MAX_AGE = 300.0
# Restarts dated ahead of this robot's clock remembered at once (each for RESTART_MAX_AGE):
# beyond, another one dated ahead is refused until the oldest is forgotten.
MAX_RESTARTS_AHEAD = 32


@dataclass(frozen=True)
class Restart:
    """A restart to carry out: who asked, and when it was issued."""

    requested_by: str
    issued_at: float


@dataclass(frozen=True)
class RestartMemory:
    """What an agent remembers of the restarts it carried out, so that each is carried out
    once (persisted in its work directory).

    `watermark`: restarts issued at or before it are refused. It is the issue time of the last
    one carried out, but never later than this robot's clock was then: a desk whose clock runs
    fast must not lock out the restarts of correct clocks that follow. `ahead`: the restarts
    carried out that were dated after the robot's clock (and so after the watermark), refused
    again as themselves (who asked, and when: both signed) while within RESTART_MAX_AGE."""

    watermark: float | None = None
    ahead: frozenset[Restart] = frozenset()

    @classmethod
    def of(cls, watermark: float | None, ahead: Iterable[tuple[float, str]]) -> RestartMemory:
        """From what the work directory keeps (RestartLedger): `(issued_at, requested_by)`."""
        return cls(watermark, frozenset(Restart(by, issued) for issued, by in ahead))

    def ahead_entries(self) -> frozenset[tuple[float, str]]:
        """`ahead` as the work directory keeps it."""
        return frozenset((r.issued_at, r.requested_by) for r in self.ahead)

    def refusal(self, restart: Restart) -> str | None:
        """Why `restart` counts as carried out already; None if it does not."""
        issued = restart.issued_at
        if self.watermark is not None and issued <= self.watermark:
            return (
                f"restart issued at {_iso(issued)} is not newer than the last one carried "
                f"out ({_iso(self.watermark)}): a duplicate or a replay"
            )
        if restart in self.ahead:
            return (
                f"restart issued at {_iso(issued)} by {restart.requested_by} was carried out "
                "already: a duplicate or a replay"
            )
        return None

    def carried_out(self, restart: Restart, now: float) -> RestartMemory:
        """The memory once `restart` is carried out at `now` (wall time)."""
        watermark = min(restart.issued_at, now)
        if self.watermark is not None:
            watermark = max(watermark, self.watermark)
        ahead = set(self.ahead)
        if restart.issued_at > watermark:
            ahead.add(restart)
        return RestartMemory(watermark, frozenset(ahead)).pruned(now)

    def pruned(self, now: float) -> RestartMemory:
        """Without what the watermark or the age limit refuses anyway."""
        floor = now - RESTART_MAX_AGE
        kept = frozenset(
            r
            for r in self.ahead
            if r.issued_at >= floor and (self.watermark is None or r.issued_at > self.watermark)
        )
        return self if kept == self.ahead else RestartMemory(self.watermark, kept)


# Seconds a signed request may be dated ahead of this robot's clock. The replay watermark is
# the newest issue time accepted, so it can never run further ahead of the robot's clock than
# this: a reconciler whose clock ran fast locks the requests of a correct clock out for this
# long at most (instead of until real time catches up), and the watermark is never lowered,
# so no replay is let in. Far beyond NTP's error, far below a lock-out that matters.
MAX_ISSUED_AHEAD = 30.0
# Seconds between looks at a request refused as dated ahead, at most: NTP may set this
# robot's clock right at any moment, long before real time catches up with a fast reconciler.
AHEAD_LOOK = 30.0


def look_again_in(outcome: Admission, now: float) -> float | None:
    """Seconds (from wall time `now`) until a request refused as dated ahead is looked at
    again: when this clock reaches it, or AHEAD_LOOK at most; None for any other outcome."""
    if not isinstance(outcome, Reject) or outcome.retry_at is None:
        return None
    return min(max(outcome.retry_at - now, 0.0), AHEAD_LOOK) + 0.05


@dataclass(frozen=True)
class Freshness:
    """What a signed request must not be older than: no rollback by replaying an old one; and
    how far ahead of this robot's clock it may be dated (`now`: wall time; None: unchecked)."""

    newest_issued_at: float | None  # of the newest signed request this robot accepted
    running_digest: str | None  # the request it runs now: re-sending that one is harmless
    now: float | None = None


def _stale(
    issued_at: float | None, digest: str | None, freshness: Freshness | None
) -> Reject | None:
    if freshness is None or issued_at is None:
        return None
    if digest is not None and digest == freshness.running_digest:
        return None
    now = freshness.now
    if now is not None and issued_at > now + MAX_ISSUED_AHEAD:
        return Reject(
            f"request issued at {_iso(issued_at)}, ahead of this robot's clock ({_iso(now)}) "
            f"by more than {MAX_ISSUED_AHEAD:g} s: the reconciler's clock or this robot's is "
            "wrong (check NTP); accepting it would lock out the requests that follow",
            retry_at=issued_at - MAX_ISSUED_AHEAD,
        )
    if freshness.newest_issued_at is None or issued_at >= freshness.newest_issued_at:
        return None
    return Reject(
        f"replayed request: issued at {_iso(issued_at)}, before the newest one this "
        f"robot accepted ({_iso(freshness.newest_issued_at)}); a rollback must come as a new "
        "commit"
    )


def _iso(stamp: float) -> str:
    try:
        return datetime.fromtimestamp(stamp, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    except (OverflowError, OSError, ValueError):
        return f"{stamp!r} (not a time)"


def _validation_summary(exc: ValidationError, limit: int = 3) -> str:
    parts = [error_line(error) for error in exc.errors(include_url=False)[:limit]]
    more = exc.error_count() - limit
    summary = "; ".join(parts) + (f"; and {more} more" if more > 0 else "")
    return summary if len(summary) <= 400 else summary[:397] + "..."  # keys come from the payload


def interpret(
    payload: bytes,
    robot: RobotDescription,
    verify: Verifier | None = None,
    freshness: Freshness | None = None,
) -> Admission:
    """The admission of one launch-topic payload. Nothing is trusted before it is verified: the
    payload is parsed under bounds, addressed and (when `verify` is set) its signature checked
    on the plain JSON object; only then is it validated as a request."""
    if not payload.strip():
        if verify is not None:
            return Reject(
                "unsigned stop refused: this agent requires signed requests, and an empty "
                "message cannot be signed; the brain keeps running"
            )
        return Clear()
    try:
        data = parse_object(payload, max_bytes=MAX_REQUEST_BYTES)
    except PayloadError as exc:
        return Reject(f"malformed launch request: {exc}")
    # Checked before the full validation so that a newer format gets a reason people understand.
    version = data.get("apiVersion")
    if version != API_VERSION:
        return Reject(
            f"unknown apiVersion {_short(version)}; this agent understands {API_VERSION!r}"
        )
    addressed = data.get("robot_id")
    if addressed != robot.id:
        return Reject(f"the request is for robot {_short(addressed)}, this is {robot.id!r}")
    if verify is not None:
        if payload != canonical_json(data):
            # The brain gets these very bytes: nothing may ride along that the signature's
            # canonical form does not cover (white space, escapes, key order).
            return Reject("a signed request must be in canonical JSON form, as signed")
        problem = verify(data)
        if problem is not None:
            return Reject(problem)
    if data.get("kind") == "Stop":
        return _stop(data, verify is not None, freshness)
    try:
        request = LaunchRequest.model_validate(data)
    except ValidationError as exc:
        return Reject(f"not a valid launch request: {_validation_summary(exc)}")
    if verify is not None:
        stale = _stale(request.issued_at, request.digest, freshness)
        if stale is not None:
            return stale
    if not request.digest_matches():
        return Reject(f"digest {request.digest} does not match the request's content")
    capability = request.scenario.capability
    if robot.platform is not None and capability.platform != robot.platform:
        return Reject(
            f"the request needs platform {capability.platform!r}, "
            f"this robot runs {robot.platform!r}"
        )
    warning = template_mismatch(capability.robot_template, robot.recommended_template)
    return Accept(request, [warning] if warning else [])


def _stop(data: dict[str, Any], signed: bool, freshness: Freshness | None) -> Admission:
    try:
        stop = StopRequest.model_validate(data)
    except ValidationError as exc:
        return Reject(f"not a valid stop: {_validation_summary(exc)}")
    if signed:
        stale = _stale(stop.issued_at, None, freshness)
        if stale is not None:
            return stale
    return Clear(stop.issued_at if signed else None)


def _short(value: Any) -> str:
    """A value from the payload as a message may quote it: bounded."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def interpret_restart(
    payload: bytes,
    robot_id: str,
    verify: Verifier | None,
    memory: RestartMemory,
    now: float,
) -> Restart | Reject:
    """The admission of one restart-topic payload, in the order of `interpret`: bounded parse,
    address, signature (when this agent verifies), then the model; then freshness: issued
    within RESTART_MAX_AGE of `now` (wall time) and not carried out before (`memory`), so
    that each restart happens once, a duplicate delivery included."""
    try:
        data = parse_object(payload, max_bytes=MAX_COMMAND_BYTES)
    except PayloadError as exc:
        return Reject(f"malformed restart request: {exc}")
    if data.get("apiVersion") != API_VERSION or data.get("kind") != "Restart":
        return Reject(
            f"not a restart request (apiVersion {_short(data.get('apiVersion'))}, kind "
            f"{_short(data.get('kind'))}); expected {API_VERSION!r} and 'Restart'"
        )
    addressed = data.get("robot_id")
    if addressed != robot_id:
        return Reject(f"the restart is for robot {_short(addressed)}, this is {robot_id!r}")
    if verify is not None:
        if payload != canonical_json(data):
            return Reject("a signed restart must be in canonical JSON form, as signed")
        problem = verify(data)
        if problem is not None:
            return Reject(problem)
    try:
        request = RestartRequest.model_validate(data)
    except ValidationError as exc:
        return Reject(f"not a valid restart request: {_validation_summary(exc)}")
    issued = request.issued_at
    if abs(now - issued) > RESTART_MAX_AGE:
        return Reject(
            f"restart issued at {_iso(issued)}, and this robot's clock says {_iso(now)}: more "
            f"than {RESTART_MAX_AGE:g} s apart (an old restart replayed, or a clock is wrong: "
            "check NTP)"
        )
    restart = Restart(request.requested_by, issued)
    problem = memory.refusal(restart)
    if problem is not None:
        return Reject(problem)
    if issued > now and len(memory.pruned(now).ahead) >= MAX_RESTARTS_AHEAD:
        return Reject(
            f"restart issued at {_iso(issued)}, ahead of this robot's clock ({_iso(now)}), "
            f"and {MAX_RESTARTS_AHEAD} such restarts were carried out in the last "
            f"{RESTART_MAX_AGE:g} s: a desk's clock is wrong (check NTP)"
        )
    return restart


def interpret_logs_request(payload: bytes) -> LogsRequest | Reject:
    """The admission of one logs-request payload: bounded parse, then the strict model (it
    changes nothing on the robot, and what it asks for leaves redacted: no signature)."""
    try:
        return LogsRequest.model_validate(parse_object(payload, max_bytes=MAX_COMMAND_BYTES))
    except PayloadError as exc:
        return Reject(f"malformed logs request: {exc}")
    except ValidationError as exc:
        return Reject(f"not a valid logs request: {_validation_summary(exc)}")
