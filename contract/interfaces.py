"""What a robot reports of its ROS graph: the interfaces message and its bounds.

Pure pydantic, shared by the agent (which writes it), the reconciler and the CLI (which read
it to judge drift and draft templates). Topic: `<prefix>/robots/<id>/interfaces`, retained.
"""

from __future__ import annotations

import json
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

# Bounds the agent applies before publishing and every reader checks before trusting: what is
# cut is counted in `truncated`. A large real robot has a few hundred interfaces; 2,000 is a
# robot with many namespaced sensors, and still far below these.
MAX_INTERFACES = 4096  # entries across topics, services and actions
MAX_INTERFACE_NAME = 256  # characters of a name or a type; a longer entry is left out
MAX_INTERFACES_BYTES = 512 * 1024  # the published JSON

InterfaceKind = Literal["topic", "service", "action"]
# How a mapping kind of a mapping scheme is looked for among the interfaces.
KIND_OF_MAPPING: dict[str, InterfaceKind] = {
    "topic": "topic",
    "service": "service",
    "action_client": "action",
}
InterfacesVerdict = Literal["reported", "unknown", "error"]


class Interface(BaseModel):
    """One interface as the robot's tooling names it: `/scan`, `sensor_msgs/msg/LaserScan`."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    name: str = Field(max_length=MAX_INTERFACE_NAME)
    type: str = Field(max_length=MAX_INTERFACE_NAME)


class RobotInterfaces(BaseModel):
    """The retained interfaces message. `error` set: the source failed, and the lists are the
    last ones it gave (or empty) — never read as the robot lacking anything."""

    model_config = ConfigDict(extra="ignore")

    topics: list[Interface] = Field(default_factory=list)
    services: list[Interface] = Field(default_factory=list)
    actions: list[Interface] = Field(default_factory=list)
    source: str = Field("", description="ros2, or the agent.yaml command that gave them")
    at: float | None = Field(None, description="unix time they were read")
    truncated: int = Field(0, ge=0, description="entries left out by the bounds")
    error: str | None = Field(None, description="why the source failed, when it did")

    def of_kind(self, kind: InterfaceKind) -> list[Interface]:
        return {"topic": self.topics, "service": self.services, "action": self.actions}[kind]

    @property
    def verdict(self) -> InterfacesVerdict:
        return "error" if self.error is not None else "reported"


class KeptInterfaces:
    """A report as a reader keeps it (the reconciler, `robotconf status`): what it says of
    itself, and its entries left as the payload's bytes, already validated, until `index`
    asks. Parsed into models, a report of 300 interfaces takes nine times its payload: 10,000
    robots would hold gigabytes; the bytes are held by the reader's view of the broker anyway."""

    __slots__ = ("at", "count", "error", "payload", "source", "truncated")

    def __init__(self, payload: bytes, report: RobotInterfaces) -> None:
        self.payload = payload
        self.source = report.source
        self.at = report.at
        self.truncated = report.truncated
        self.error = report.error
        self.count = len(report.topics) + len(report.services) + len(report.actions)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, KeptInterfaces) and other.payload == self.payload

    def __hash__(self) -> int:
        return hash(self.payload)

    @property
    def verdict(self) -> InterfacesVerdict:
        return "error" if self.error is not None else "reported"

    def report(self) -> RobotInterfaces:
        """The whole report, parsed again."""
        return RobotInterfaces.model_validate_json(self.payload)


# A robot's interfaces as any reader has them: the message, or as a reader keeps it.
Reported = RobotInterfaces | KeptInterfaces


def interfaces_verdict(found: Reported | None) -> InterfacesVerdict:
    """`unknown` when the robot reported nothing (reporting off, a ROS 1 robot, an old agent)."""
    return "unknown" if found is None else found.verdict


def _short(type_name: str) -> str:
    """`pkg/msg/Type` -> `pkg/Type`: ROS 1 and older tools leave out the middle part."""
    parts = type_name.strip().split("/")
    return f"{parts[0]}/{parts[-1]}" if len(parts) == 3 else type_name.strip()


def same_type(expected: str, found: str) -> bool:
    """A scheme's type and a reported one name the same interface type (`geometry_msgs/Twist`
    is `geometry_msgs/msg/Twist`)."""
    return expected.strip() == found.strip() or _short(expected) == _short(found)


def index(found: Reported) -> dict[tuple[InterfaceKind, str], list[str]]:
    """(kind, name) -> the types the robot reports under it (a topic may carry several)."""
    if isinstance(found, KeptInterfaces):
        return _index_payload(found.payload)
    table: dict[tuple[InterfaceKind, str], list[str]] = {}
    kinds: tuple[InterfaceKind, ...] = ("topic", "service", "action")
    for kind in kinds:
        for entry in found.of_kind(kind):
            table.setdefault((kind, entry.name), []).append(entry.type)
    return table


_LISTS: tuple[tuple[str, InterfaceKind], ...] = (
    ("topics", "topic"),
    ("services", "service"),
    ("actions", "action"),
)


def _index_payload(payload: bytes) -> dict[tuple[InterfaceKind, str], list[str]]:
    """`index` of a payload that validated as a report when it was kept: read as plain JSON,
    without a model per entry. Entries are kept as the model reads them (text name and type
    within the bounds); anything else was refused when the payload was kept."""
    raw = json.loads(payload)
    table: dict[tuple[InterfaceKind, str], list[str]] = {}
    for field, kind in _LISTS:
        for entry in raw.get(field) or ():
            table.setdefault((kind, entry["name"]), []).append(entry["type"])
    return table
