"""The Launch Request: what a robot's brain service receives, its canonical JSON and digest.

Pure pydantic; the robot-side agent validates incoming requests with these same types.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from configurator.types import ROBOT_ID_PATTERN, JsonObject, MappingBinding

API_VERSION = "robotconf/v1"
DIGEST_PATTERN = r"^sha256:[0-9a-f]{64}$"
_NOT_CONTENT = {"revision", "digest", "issued_at", "signature"}


class _Wire(BaseModel):
    model_config = ConfigDict(extra="forbid")


class LaunchCapability(_Wire):
    name: str
    platform: str
    robot_template: str | None
    mapping_scheme: str
    tasks: list[str] = Field(description="tasks the selected actions achieve")
    actions: list[str]
    logics: dict[str, str] = Field(description="action -> logic module")
    mappings: dict[str, MappingBinding] = Field(description="mappings the logics need, bound")


class LaunchGoal(_Wire):
    task: str
    location: JsonObject | None = Field(None, description="the environment object, expanded")


class LaunchScenario(_Wire):
    name: str
    capability: LaunchCapability
    environment_name: str | None
    environment_type: str | None
    robot_settings: JsonObject
    logic_settings: dict[str, JsonObject]
    environment_knowledge: JsonObject
    goals: list[LaunchGoal]


class _Published(_Wire):
    """What the reconciler publishes on a launch topic, signed or not."""

    issued_at: float | None = Field(None, description="unix time the request was signed")
    signature: str | None = Field(None, description="base64 Ed25519 over the signed fields")

    def wire(self, *, signature: bool = True) -> dict[str, Any]:
        """The JSON object published (signing fields only when set)."""
        unset = {k for k in ("issued_at", "signature") if getattr(self, k) is None}
        if not signature:
            unset.add("signature")
        return self.model_dump(mode="json", exclude=unset)

    def payload(self) -> bytes:
        """The canonical bytes published on the launch topic."""
        return canonical_json(self.wire())


class LaunchRequest(_Published):
    """One robot's complete start-up configuration."""

    apiVersion: Literal["robotconf/v1"] = "robotconf/v1"
    kind: Literal["LaunchRequest"] = "LaunchRequest"
    robot_id: str = Field(pattern=ROBOT_ID_PATTERN)
    robot_name: str
    revision: str = Field(description="the git commit it was rendered from")
    digest: str = Field(pattern=DIGEST_PATTERN, description="sha256 of the content")
    scenario: LaunchScenario

    def content(self) -> dict[str, Any]:
        """What the digest covers: everything but revision, digest and the signature fields."""
        return self.model_dump(mode="json", exclude=_NOT_CONTENT)


    def digest_matches(self) -> bool:
        return self.digest == content_digest(self.content())


class StopRequest(_Published):
    """A signed "stop": what the launch topic holds for a robot no longer assigned, when the
    reconciler signs. An empty payload cannot carry a signature, so an agent that verifies
    requests stops its brain only for one of these (DESIGN §7: empty means stop, unsigned)."""

    apiVersion: Literal["robotconf/v1"] = "robotconf/v1"
    kind: Literal["Stop"] = "Stop"
    robot_id: str = Field(pattern=ROBOT_ID_PATTERN)
    revision: str = Field(description="the git commit that unassigned the robot")


def canonical_json(value: Any) -> bytes:
    """Sorted keys, no insignificant white space, UTF-8: equal content, equal bytes."""
    return json.dumps(
        value, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False
    ).encode("utf-8")


def content_digest(content: Any) -> str:
    return "sha256:" + hashlib.sha256(canonical_json(content)).hexdigest()


def make_launch_request(
    robot_id: str, robot_name: str, revision: str, scenario: LaunchScenario
) -> LaunchRequest:
    """Build a request whose digest covers everything but the revision."""
    content = {
        "apiVersion": API_VERSION,
        "kind": "LaunchRequest",
        "robot_id": robot_id,
        "robot_name": robot_name,
        "scenario": scenario.model_dump(mode="json"),
    }
    return LaunchRequest(
        robot_id=robot_id,
        robot_name=robot_name,
        revision=revision,
        digest=content_digest(content),
        scenario=scenario,
    )
