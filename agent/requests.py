"""What a payload on the launch topic means for this robot: clear, accept (with warnings), reject.

Pure: validated with the shared LaunchRequest type, checked against the robot's description.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime, timezone

from pydantic import ValidationError

from configurator.launch import API_VERSION, LaunchRequest
from configurator.wire import RobotDescription


@dataclass(frozen=True)
class Clear:
    """The empty retained payload: no assignment."""


@dataclass(frozen=True)
class Accept:
    request: LaunchRequest
    warnings: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Reject:
    reason: str


Verdict = Clear | Accept | Reject
Verifier = Callable[[LaunchRequest], "str | None"]  # None when the signature is good


@dataclass(frozen=True)
class Freshness:
    """What a signed request must not be older than: no rollback by replaying an old one."""

    newest_issued_at: float | None  # of the newest signed request this robot accepted
    running_digest: str | None  # the request it runs now: re-sending that one is harmless


def _stale(request: LaunchRequest, freshness: Freshness | None) -> str | None:
    if freshness is None or freshness.newest_issued_at is None or request.issued_at is None:
        return None
    if request.issued_at >= freshness.newest_issued_at:
        return None
    if request.digest == freshness.running_digest:
        return None
    return (
        f"replayed request: issued at {_iso(request.issued_at)}, before the newest one this "
        f"robot accepted ({_iso(freshness.newest_issued_at)}); a rollback must come as a new "
        "commit"
    )


def _iso(stamp: float) -> str:
    return datetime.fromtimestamp(stamp, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def _validation_summary(exc: ValidationError, limit: int = 3) -> str:
    parts = []
    for error in exc.errors()[:limit]:
        where = ".".join(str(p) for p in error["loc"]) or "(top level)"
        parts.append(f"{where}: {error['msg']}")
    more = exc.error_count() - limit
    return "; ".join(parts) + (f"; and {more} more" if more > 0 else "")


def interpret(
    payload: bytes,
    robot: RobotDescription,
    verify: Verifier | None = None,
    freshness: Freshness | None = None,
) -> Verdict:
    if not payload.strip():
        return Clear()
    try:
        data = json.loads(payload)
    except (UnicodeDecodeError, ValueError) as exc:
        return Reject(f"malformed JSON: {exc}")
    if not isinstance(data, dict):
        return Reject(f"a launch request must be a JSON object, got {type(data).__name__}")
    # Checked before the full validation so that a newer format gets a reason people understand.
    version = data.get("apiVersion")
    if version != API_VERSION:
        return Reject(f"unknown apiVersion {version!r}; this agent understands {API_VERSION!r}")
    try:
        request = LaunchRequest.model_validate(data)
    except ValidationError as exc:
        return Reject(f"not a valid launch request: {_validation_summary(exc)}")
    if request.robot_id != robot.id:
        return Reject(f"the request is for robot {request.robot_id!r}, this is {robot.id!r}")
    if verify is not None:
        problem = verify(request) or _stale(request, freshness)
        if problem is not None:
            return Reject(problem)
    if not request.digest_matches():
        return Reject(f"digest {request.digest} does not match the request's content")
    capability = request.scenario.capability
    if robot.platform is not None and capability.platform != robot.platform:
        return Reject(
            f"the request needs platform {capability.platform!r}, "
            f"this robot runs {robot.platform!r}"
        )
    warnings = []
    template = capability.robot_template
    recommended = robot.recommended_template
    if recommended is not None and template != recommended:
        target = f"targets template {template!r}" if template else "names no robot template"
        warnings.append(
            f"capability {capability.name!r} {target}; this robot recommends {recommended!r}"
        )
    return Accept(request, warnings)
