"""What a robot reports of its ROS graph: the interfaces message and its bounds.

Pure pydantic, shared by the agent (which writes it), the reconciler and the CLI (which read
it to judge drift and draft templates). Topic: `<prefix>/robots/<id>/interfaces`, retained.
"""

from __future__ import annotations

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


def interfaces_verdict(found: RobotInterfaces | None) -> InterfacesVerdict:
    """`unknown` when the robot reported nothing (reporting off, a ROS 1 robot, an old agent)."""
    return "unknown" if found is None else found.verdict
