"""The Launch Request: what a robot's brain service receives, its canonical JSON and digest.

Pure pydantic; the robot-side agent validates incoming requests with these same types.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Set
from typing import Any, Literal, TypeVar

from pydantic import Field

from robotconf.contract.models import (
    MAX_ROS_DOMAIN_ID,
    ROBOT_ID_PATTERN,
    JsonObject,
    MappingBinding,
    StrictModel,
)

API_VERSION = "robotconf/v1"
DIGEST_PATTERN = r"^sha256:[0-9a-f]{64}$"
# What the digest leaves out: where the request was rendered from (a new commit with the same
# content restarts no brain), the digest itself and the signing fields. Every other field of
# a request, including one added later, is content. `restart_digest` is left out too: it is
# derived from the capability, which the digest covers already, so it adds nothing; and left
# out, a request keeps the digest it had before the field existed (an older reconciler's
# request and a newer one's for the same content are the same: upgrading restarts no brain).
DIGEST_EXCLUDED = frozenset({"revision", "digest", "restart_digest", "issued_at", "signature"})
# Content a request carries only when set: unset, it is neither published nor digested, so a
# robot that uses none has the request (and digests) it had before the field existed, and an
# agent that predates the field (its models refuse unknown fields) still accepts it.
CONTENT_WHEN_SET = ("namespace", "ros_domain_id")
# A well-formed placeholder while a request is built; `with_digest` replaces it.
_PENDING_DIGEST = "sha256:" + "0" * 64


# Strict as every document type: the agent validates the JSON object it received with these
# models, and JSON gives every field its own type (strings, numbers, lists, objects) already.
class LaunchCapability(StrictModel):
    """The capability configuration, resolved: what only a restart of the brain applies."""

    name: str = Field(description="the capability configuration's name")
    platform: str = Field(description="the robot's software platform")
    robot_template: str | None = Field(description="the template it fits, if it names one")
    mapping_scheme: str = Field(description="the scheme that bound the mappings")
    tasks: list[str] = Field(description="tasks the selected actions achieve")
    actions: list[str] = Field(description="the selected actions")
    # One logic is its name (every request before multi-logic actions, byte for byte), several
    # a list in the order the capability writes them.
    logics: dict[str, str | list[str]] = Field(
        description="action -> logic module, or a list of the logic modules it selects"
    )
    mappings: dict[str, MappingBinding] = Field(description="mappings the logics need, bound")


class LaunchGoal(StrictModel):
    """An initial task for the robot's planner."""

    task: str = Field(description="the task to achieve")
    location: JsonObject | None = Field(None, description="the environment object, expanded")


class LaunchScenario(StrictModel):
    """The scenario the robot runs, with every default filled and every name resolved."""

    name: str = Field(description="the scenario configuration's name")
    capability: LaunchCapability
    environment_name: str | None = Field(description="the environment, if the scenario has one")
    environment_type: str | None = Field(description="its type, e.g. Gazebo or Real")
    robot_settings: JsonObject = Field(description="every robot setting, defaults filled")
    logic_settings: dict[str, JsonObject] = Field(
        description="selected logic -> its settings, defaults filled"
    )
    environment_knowledge: JsonObject = Field(
        description="the knowledge sets deep-merged in order, the scenario's knowledge over them"
    )
    goals: list[LaunchGoal] = Field(description="the initial tasks, locations expanded")


class _Published(StrictModel):
    """What the reconciler publishes on a launch topic, signed or not."""

    issued_at: float | None = Field(None, description="unix time the request was signed")
    signature: str | None = Field(None, description="base64 Ed25519 over the signed fields")

    def wire(self, *, signature: bool = True, without: Set[str] = frozenset()) -> dict[str, Any]:
        """The JSON object published (signing fields and `restart_digest` only when set);
        `without`: fields left out (a caller that writes those itself)."""
        # A Stop has no `restart_digest`: only fields this model has and that are None.
        optional = ("issued_at", "signature", "restart_digest", *CONTENT_WHEN_SET)
        unset = {k for k in optional if k in type(self).model_fields and getattr(self, k) is None}
        if not signature:
            unset.add("signature")
        return self.model_dump(mode="json", exclude=unset | without)

    def payload(self) -> bytes:
        """The canonical bytes published on the launch topic."""
        return canonical_json(self.wire())


class LaunchRequest(_Published):
    """One robot's complete start-up configuration."""

    apiVersion: Literal["robotconf/v1"] = "robotconf/v1"
    kind: Literal["LaunchRequest"] = "LaunchRequest"
    robot_id: str = Field(pattern=ROBOT_ID_PATTERN, description="the robot it is for")
    robot_name: str = Field(description="its display name")
    revision: str = Field(description="the git commit it was rendered from")
    digest: str = Field(pattern=DIGEST_PATTERN, description="sha256 of the content")
    # Optional: an older reconciler does not send it, and its requests always restart.
    restart_digest: str | None = Field(
        None,
        pattern=DIGEST_PATTERN,
        description="sha256 of what only a restart applies (scenario.capability); when only "
        "the rest changes, an agent configured to may reload the running brain instead",
    )
    namespace: str | None = Field(
        None,
        description="the robot's ROS 2 namespace, absolute (/tb3_01); the names in "
        "scenario.capability.mappings are resolved in it already (fully qualified)",
    )
    ros_domain_id: int | None = Field(
        None,
        ge=0,
        le=MAX_ROS_DOMAIN_ID,
        description="the ROS 2 domain the brain runs in: the agent sets ROS_DOMAIN_ID to it "
        "(agent.yaml's env may override it, reported as a conflict); none: the robot's own",
    )
    scenario: LaunchScenario

    def content(self) -> dict[str, Any]:
        """What the digest covers (see `digest_content`)."""
        return digest_content(self)

    def digest_matches(self) -> bool:
        """The agent's check: the digests are the ones `with_digest` gives this content (a
        request without `restart_digest` passes on its digest alone)."""
        if self.restart_digest is not None and self.restart_digest != restart_digest_of(self):
            return False
        return self.digest == content_digest(digest_content(self))


class StopRequest(_Published):
    """A signed "stop": what the launch topic holds for a robot no longer assigned, when the
    reconciler signs. An empty payload cannot carry a signature, so an agent that verifies
    requests stops its brain only for one of these (empty means stop, unsigned:
    docs/architecture.md#the-mqtt-contract)."""

    apiVersion: Literal["robotconf/v1"] = "robotconf/v1"
    kind: Literal["Stop"] = "Stop"
    robot_id: str = Field(pattern=ROBOT_ID_PATTERN)
    revision: str = Field(description="the git commit that unassigned the robot")


# Who asked, as a restart request names it: a user name or an address, never free text.
REQUESTER_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.@+-]{0,63}$"


class RestartRequest(_Published):
    """A request from the desk (`robotconf restart`) to start a robot's brain again without a
    commit. Signed with the launch requests' key when the robot's agent verifies them; its
    `issued_at` is required either way: the agent carries out each restart once, and only a
    recent one (replay protection)."""

    apiVersion: Literal["robotconf/v1"] = "robotconf/v1"
    kind: Literal["Restart"] = "Restart"
    robot_id: str = Field(pattern=ROBOT_ID_PATTERN)
    requested_by: str = Field(pattern=REQUESTER_PATTERN, description="who asked")
    issued_at: float = Field(description="unix time the restart was asked for")


class RolloutAction(_Published):
    """An operator's decision about a rollout, from the desk (`robotconf rollout resume`,
    `robotconf rollout abort`, `robotconf promote`) or the browser view, to the reconciler. A
    resume or abort names the wave run it is about (revision, wave, wave_started_at): one about
    a run that has moved on is refused, never applied to the next. Signed with the launch
    requests' key when the lab signs; the reconciler keeps each one it carries out as a git
    note on the revision (who, when)."""

    apiVersion: Literal["robotconf/v1"] = "robotconf/v1"
    kind: Literal["RolloutAction"] = "RolloutAction"
    action: Literal["resume", "abort", "promote"]
    revision: str = Field(pattern=r"^[0-9a-f]{40}$", description="the commit rolled out")
    stage: str | None = Field(
        None, max_length=64, description="promote: the stage (fleet.yaml stages) it goes to"
    )
    wave: int = Field(ge=0, le=10_000, description="the wave it is about (0-based)")
    wave_started_at: float = Field(description="when that wave was published")
    requested_by: str = Field(pattern=REQUESTER_PATTERN, description="who asked")
    issued_at: float = Field(description="unix time it was asked for")


# One encoder for every call: json.dumps makes a new one whenever an option is not its default.
_CANONICAL = json.JSONEncoder(
    sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False
)


def canonical_json(value: Any) -> bytes:
    """Sorted keys, no insignificant white space, UTF-8: equal content, equal bytes."""
    return _CANONICAL.encode(value).encode("utf-8")


def content_digest(content: Any) -> str:
    return "sha256:" + hashlib.sha256(canonical_json(content)).hexdigest()


def digest_content(request: LaunchRequest, without: Set[str] = frozenset()) -> dict[str, Any]:
    """The one definition of what a request's digest covers: every field of the model (of a
    subclass too) but DIGEST_EXCLUDED. Rendering and the agent's check both come here.
    `without`: fields left out (a caller that writes those itself)."""
    unset = {name for name in CONTENT_WHEN_SET if getattr(request, name) is None}
    return request.model_dump(mode="json", exclude=set(DIGEST_EXCLUDED) | unset | without)


def restart_content(request: LaunchRequest) -> Any:
    """What only a restart applies, of this request (see `restart_content_of`)."""
    return restart_content_of(
        request.scenario.capability.model_dump(mode="json"),
        request.namespace,
        request.ros_domain_id,
    )


def restart_content_of(capability: Any, namespace: Any, ros_domain_id: Any = None) -> Any:
    """The one definition of what only a restart applies: the capability (platform, mapping
    scheme, template, actions, logics, mappings), as JSON. The rest (goals, knowledge,
    settings, the robot's name) a brain that supports it may reload in place. A namespace and
    a ROS domain are restart content too: a brain's nodes cannot move into another namespace
    in place, and a process joins its DDS domain once, when it starts."""
    if namespace is None and ros_domain_id is None:
        # Without either, the content it always had: such a robot's restart digest is unchanged.
        return capability
    content = {"capability": capability, "namespace": namespace, "ros_domain_id": ros_domain_id}
    # Each only when set: a robot with a namespace and no domain keeps its restart digest.
    return {key: value for key, value in content.items() if value is not None}


def restart_digest_of(request: LaunchRequest) -> str:
    return content_digest(restart_content(request))


Request = TypeVar("Request", bound=LaunchRequest)


def with_digest(request: Request) -> Request:
    """The request with the digests of its content: how rendering seals every request."""
    return request.model_copy(
        update={
            "digest": content_digest(digest_content(request)),
            "restart_digest": restart_digest_of(request),
        }
    )


def make_launch_request(
    robot_id: str,
    robot_name: str,
    revision: str,
    scenario: LaunchScenario,
    namespace: str | None = None,
    ros_domain_id: int | None = None,
) -> LaunchRequest:
    """Build a request whose digest covers everything but the revision, and whose
    restart_digest covers its capability (and namespace, and ROS domain). Rendering a fleet
    makes the same bytes without a model per robot (configurator/rendered.py)."""
    return with_digest(
        LaunchRequest(
            robot_id=robot_id,
            robot_name=robot_name,
            revision=revision,
            digest=_PENDING_DIGEST,
            namespace=namespace,
            ros_domain_id=ros_domain_id,
            scenario=scenario,
        )
    )


def template_mismatch(template: str | None, recommended: str | None) -> str | None:
    """The warning when a request's robot template is not the one the robot recommends; None
    when there is nothing to say. The agent's admission and the fleet status both word it so:
    the status shows it once, whichever of the two raised it."""
    if recommended is None or template == recommended:
        return None
    if template is None:
        return (
            f"the assigned capability names no robot template; the robot recommends {recommended!r}"
        )
    return (
        f"assigned robot template {template!r} differs from the robot's recommended {recommended!r}"
    )
