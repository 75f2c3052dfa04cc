"""The retained topics read into models: what the broker says each robot holds, runs and is.

Pure and shared: the reconciler's observe step and the fleet status parse payloads here, and
only here. Unreadable payloads (size, depth, JSON, schema) are skipped and counted, never fatal.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from pydantic import BaseModel, ConfigDict, ValidationError

from robotconf.contract.goals import GoalsSummary
from robotconf.contract.interfaces import (
    MAX_INTERFACES,
    MAX_INTERFACES_BYTES,
    KeptInterfaces,
    RobotInterfaces,
)
from robotconf.contract.launch import LaunchRequest, StopRequest, canonical_json
from robotconf.contract.safejson import MAX_PAYLOAD_BYTES, PayloadError
from robotconf.contract.wire import (
    ACTIVE_STATES,
    AgentStatus,
    ReconcilerStatus,
    RobotDescription,
    Topics,
    is_online,
)
from robotconf.readmodel.retained import Ignored, read_object
from robotconf.readmodel.robot_goals import bounded

RECONCILER_STATUS = "reconciler-status"
WAVE_RECORD = "rollout-record"  # reconciler.wave_memory, read by the reconciler alone
INTERFACES = "interfaces"
GOALS = "goals"
_ROBOT_LEAVES = ("launch", "status", "description", INTERFACES, GOALS)


@dataclass
class RobotSeen:
    """One robot as the retained topics show it."""

    launch: LaunchRequest | None = None  # only when read in full (`requests=True`)
    launch_digest: str | None = None  # the digest a launch payload carries, valid or not
    launch_retained: bool = False  # the launch topic holds a request (readable or not)
    launch_signed: bool = False  # that request carries a signature (good or not)
    stopped: bool = False  # the launch topic holds a Stop for this robot: nothing assigned
    status: AgentStatus | None = None
    description: RobotDescription | None = None
    interfaces: KeptInterfaces | None = None  # what it reports of its ROS graph
    interfaces_error: str | None = None  # why its interfaces payload cannot be read
    goals: GoalsSummary | None = None  # what its brain achieved since its request (bounded)
    goals_error: str | None = None  # why its goals summary cannot be read

    @property
    def online(self) -> bool:
        """Its agent has reported, and its last status is not `offline` (its Last Will)."""
        return is_online(self.status)

    @property
    def brain_active(self) -> bool:
        """Its agent says a brain is up or about to be."""
        return self.status is not None and self.status.state in ACTIVE_STATES


@dataclass
class Retained:
    robots: dict[str, RobotSeen] = field(default_factory=dict)
    reconciler: ReconcilerStatus | None = None
    ignored: dict[str, int] = field(default_factory=dict)  # unreadable payloads, by kind

    def launch_digests(self) -> dict[str, str | None]:
        """robot -> digest of its retained request; None when that request is unreadable.
        Robots with nothing retained, or a Stop, are absent: they are cleared."""
        return {
            robot_id: robot.launch_digest
            for robot_id, robot in self.robots.items()
            if robot.launch_retained
        }

    def active(self) -> set[str]:
        """Robots whose agent says a brain is up or about to be."""
        return {robot_id for robot_id, robot in self.robots.items() if robot.brain_active}


def _kind(topic: str, topics: Topics) -> tuple[str | None, str] | None:
    """(robot id or None, kind) of a topic whose retained message we read, else None."""
    if topic == topics.reconciler_status:
        return None, RECONCILER_STATUS
    where = topics.robot_of(topic)
    if where is not None and where[1] in _ROBOT_LEAVES:
        return where
    return None


class LaunchHeader(BaseModel):
    """What the reconciler reads of a launch payload: which request it is, not all of it."""

    model_config = ConfigDict(extra="ignore")

    kind: str | None = None
    digest: str | None = None
    signature: str | None = None  # a whole request's
    signed: bool = False  # a `launch_summary`'s

    @property
    def carries_signature(self) -> bool:
        """The request, or the summary kept of it, is signed (good or not: the agent judges)."""
        return self.signed or self.signature is not None


# A request as the reconciler writes it (canonical JSON: sorted keys, no blanks) opens with its
# header. Read there, 10,000 requests of a few kB cost one match each, not one parse each (the
# parse is 95% of reading a 10,000-robot fleet's retained topics). The agent still validates
# every request in full; any other form is parsed in full here too.
_CANONICAL_HEADER = re.compile(
    rb'\{"apiVersion":"[A-Za-z0-9./-]{1,64}","digest":"(sha256:[0-9a-f]{64})","kind":"LaunchRequest",'
)


def canonical_digest(payload: bytes) -> str | None:
    """The digest of a launch request in canonical form, read from its opening bytes; None when
    the payload is not one (too large, another form, or a Stop)."""
    if len(payload) > MAX_PAYLOAD_BYTES or not payload.endswith(b"}"):
        return None
    found = _CANONICAL_HEADER.match(payload)
    return found.group(1).decode("ascii") if found else None


# A signed request in canonical form ends with its signature: "signature" is the last of its
# sorted top-level keys, and an unsigned one ends with its scenario's closing brace instead.
_CANONICAL_SIGNATURE = re.compile(rb',"signature":"[A-Za-z0-9+/=]{1,128}"\}\Z')


def canonical_signed(payload: bytes) -> bool:
    """Whether a launch request in canonical form carries a signature (not whether it is a
    good one: the agent judges that)."""
    return _CANONICAL_SIGNATURE.search(payload, max(0, len(payload) - 160)) is not None


def launch_summary(kind: str | None, digest: str | None, signed: bool = False) -> bytes:
    """What the reconciler keeps of a launch request it holds or publishes: its kind, digest
    and whether it is signed, which `parse_retained(requests=False)` reads as it reads the
    whole request."""
    if signed:
        return canonical_json({"digest": digest, "kind": kind, "signed": True})
    return canonical_json({"digest": digest, "kind": kind})


def summarise_launches(topics: Topics) -> Callable[[str, bytes], bytes]:
    """For a RetainedView's `keep`: each launch payload as its `launch_summary`; a Stop, an
    unreadable payload and any other topic's kept whole (they read the same only so)."""

    def keep(topic: str, payload: bytes) -> bytes:
        where = topics.robot_of(topic)
        if where is None or where[1] != "launch":
            return payload
        digest = canonical_digest(payload)
        if digest is not None:
            return launch_summary("LaunchRequest", digest, canonical_signed(payload))
        try:
            header = LaunchHeader.model_validate(read_object(payload))
        except Exception:  # on the network thread: whatever it is, it is kept whole
            return payload
        if header.kind == "Stop":
            return payload
        return launch_summary(header.kind, header.digest, header.carries_signature)

    return keep


@dataclass(frozen=True)
class _Reading:
    """What one payload was read as: the robot's fields it sets, the reconciler status, or
    why it cannot be read."""

    fields: dict[str, Any] = field(default_factory=dict)
    reconciler: ReconcilerStatus | None = None
    error: str | None = None


_Found = tuple[str | None, str]  # (robot id or None, kind) of a topic: `_kind`


class ReadMemo:
    """The reading of each topic's payload, kept while the payload stays the same: a step
    reads only what changed since the step before (10,000 unchanged requests cost one bytes
    comparison each, not a JSON parse, nor even working out whose topic it is). One memo per
    caller, for one `requests` setting and one topic prefix."""

    def __init__(self) -> None:
        self._readings: dict[str, tuple[bytes, _Found, _Reading]] = {}

    def get(self, topic: str, payload: bytes) -> tuple[_Found, _Reading] | None:
        kept = self._readings.get(topic)
        if kept is None or not (kept[0] is payload or kept[0] == payload):
            return None
        return kept[1], kept[2]

    def put(self, topic: str, payload: bytes, found: _Found, reading: _Reading) -> None:
        self._readings[topic] = (payload, found, reading)

    def keep_only(self, topics: Mapping[str, bytes]) -> None:
        """Forget the topics that are gone: the memo is never larger than the broker's view."""
        if len(self._readings) > len(topics):
            self._readings = {t: r for t, r in self._readings.items() if t in topics}


def parse_retained(
    messages: Mapping[str, bytes],
    topics: Topics,
    *,
    requests: bool = True,
    ignored: Ignored | None = None,
    memo: ReadMemo | None = None,
) -> Retained:
    """Sorts retained messages by robot and reads each with its model.

    `requests=False` reads only the kind, robot and digest of launch payloads (the reconciler
    needs no more, and a full validation of 10,000 requests would cost it at every step);
    `memo` keeps what was read of each payload for the next call."""
    out = Retained()
    robots = out.robots
    for topic, payload in messages.items():
        if not payload:
            continue
        kept = memo.get(topic, payload) if memo is not None else None
        if kept is None:
            found = _kind(topic, topics)
            if found is None:
                continue
            reading = _read(found[1], found[0], payload, requests)
            if memo is not None:
                memo.put(topic, payload, found, reading)
        else:
            found, reading = kept
        robot_id, kind = found
        if robot_id is None:
            out.reconciler = reading.reconciler
        else:
            # A robot is known to the broker even when what it published cannot be read.
            robot = robots.get(robot_id)
            if robot is None:
                robot = robots[robot_id] = RobotSeen()
            for name, value in reading.fields.items():
                setattr(robot, name, value)
        if reading.error is not None:
            out.ignored[kind] = out.ignored.get(kind, 0) + 1
            if ignored is not None:
                ignored.note(kind, topic, payload, reading.error)
    if memo is not None:
        memo.keep_only(messages)
    return out


class LaunchDigests:
    """What the reconciler reads of its launch view at each step, robot -> the digest of its
    retained request (None: unreadable), as `parse_retained(requests=False).launch_digests()`
    gives it; unreadable payloads noted in `ignored` at each step as it notes them. Kept from
    one step to the next and updated by the payloads that differ: with 10,000 unchanged
    requests, a step costs one set difference (in C), not 10,000 readings of the memo."""

    def __init__(self, topics: Topics) -> None:
        self._topics = topics
        self._read: dict[str, bytes] = {}  # topic -> the payload last read there
        self._digests: dict[str, str | None] = {}  # robot -> digest: what a step is given
        self._robot_of: dict[str, str] = {}  # launch topic -> the robot it gives a digest
        self._errors: dict[str, tuple[str, bytes, str]] = {}  # topic -> kind, payload, why
        self._unsigned: set[str] = set()  # robots whose retained request carries no signature

    @property
    def unsigned(self) -> frozenset[str]:
        """Robots whose retained request, as the last `update` read it, is not signed."""
        return frozenset(self._unsigned)

    def update(
        self, messages: Mapping[str, bytes], ignored: Ignored | None = None
    ) -> dict[str, str | None]:
        for topic in self._read.keys() - messages.keys():
            self._forget(topic)
            del self._read[topic]
        for topic, payload in messages.items() - self._read.items():
            self._forget(topic)
            self._read[topic] = payload
            if payload:
                self._learn(topic, payload)
        if ignored is not None:
            for topic, (kind, payload, reason) in self._errors.items():
                ignored.note(kind, topic, payload, reason)
        return dict(self._digests)

    def _forget(self, topic: str) -> None:
        self._errors.pop(topic, None)
        robot_id = self._robot_of.pop(topic, None)
        if robot_id is not None:
            del self._digests[robot_id]
            self._unsigned.discard(robot_id)

    def _learn(self, topic: str, payload: bytes) -> None:
        found = _kind(topic, self._topics)
        if found is None:
            return
        robot_id, kind = found
        reading = _read(kind, robot_id, payload, False)
        if reading.error is not None:
            self._errors[topic] = (kind, payload, reading.error)
        if robot_id is not None and reading.fields.get("launch_retained"):
            self._digests[robot_id] = reading.fields.get("launch_digest")
            self._robot_of[topic] = robot_id
            if not reading.fields.get("launch_signed"):
                self._unsigned.add(robot_id)


def _read(kind: str, robot_id: str | None, payload: bytes, requests: bool) -> _Reading:
    # Unreadable is still retained: it is replaced (or cleared), never trusted.
    fields: dict[str, Any] = {"launch_retained": True} if kind == "launch" else {}
    if kind == "launch" and not requests and robot_id is not None:
        digest = canonical_digest(payload)
        if digest is not None:
            fields.update(launch_digest=digest, launch_signed=canonical_signed(payload))
            return _Reading(fields)
    try:
        # An interfaces report is bounded tighter than other payloads, before it is parsed.
        raw = read_object(
            payload, MAX_INTERFACES_BYTES if kind == INTERFACES else MAX_PAYLOAD_BYTES
        )
        if robot_id is None:
            return _Reading(reconciler=ReconcilerStatus.model_validate(raw))
        if kind == "launch":
            _read_launch(robot_id, raw, requests, fields)
        elif kind == "status":
            fields["status"] = AgentStatus.model_validate(raw)
        elif kind == INTERFACES:
            fields["interfaces"] = _interfaces(raw, payload)
        elif kind == GOALS:
            fields["goals"] = _goals(robot_id, raw)
        else:
            fields["description"] = RobotDescription.model_validate(raw)
    except (PayloadError, ValidationError, ValueError) as exc:
        reason = " ".join(str(exc).split())[:300]
        if kind == INTERFACES:  # the robot reported, unreadably: `error`, never `unknown`
            fields["interfaces_error"] = reason
        elif kind == GOALS:
            fields["goals_error"] = reason
        return _Reading(fields, error=reason)
    return _Reading(fields)


def _interfaces(raw: dict[str, Any], payload: bytes) -> KeptInterfaces:
    """Validated whole, kept as its bytes (see KeptInterfaces)."""
    found = KeptInterfaces(payload, RobotInterfaces.model_validate(raw))
    if found.count > MAX_INTERFACES:
        raise ValueError(f"{found.count:,} interfaces, over the limit of {MAX_INTERFACES:,}")
    return found


def _goals(robot_id: str, raw: dict[str, Any]) -> GoalsSummary:
    """A goals summary, trusted only on its own robot's topic, kept bounded (robot_goals)."""
    found = GoalsSummary.model_validate(raw)
    if found.robot_id != robot_id:
        raise ValueError(f"a goals summary of robot {found.robot_id!r} on the topic of {robot_id}")
    return bounded(found)


def _read_launch(robot_id: str, raw: dict[str, Any], full: bool, fields: dict[str, Any]) -> None:
    """A launch payload into `fields`: a Stop for this robot clears it; anything else is a
    request, whose digest counts even when the rest is invalid (what differs is republished
    anyway): it is in `fields` before the full request is validated."""
    header = LaunchHeader.model_validate(raw)
    if header.kind == "Stop":
        if StopRequest.model_validate(raw).robot_id != robot_id:
            raise ValueError(f"a Stop for another robot on the launch topic of {robot_id}")
        fields.update(launch_retained=False, stopped=True)
        return
    fields["launch_digest"] = header.digest
    fields["launch_signed"] = header.carries_signature
    if full:
        fields["launch"] = LaunchRequest.model_validate(raw)
