"""The shapes the robot and the server share below the documents: robot ids, ROS domains, the
strict model base, and how a mapping is bound (the Launch Request carries bindings).

Pure pydantic; the robot-side agent imports it, so nothing heavier than pydantic here.
"""

from __future__ import annotations

import re
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from robotconf.contract.errors import CliError
from robotconf.contract.textsafe import printable, shorten

# A goal's failure code, as brains report them and rollout.verify's `critical` names them:
# NAV2_TIMEOUT, nav2:104, E_BLOCKED. Here, beside the documents' models: validate reads
# fleet.yaml without the wire's models.
CODE_PATTERN = r"^[A-Za-z0-9_.:-]{1,64}$"

# `$` ends the text in pydantic's and JSON Schema's regexes; Python's `re` also lets it match
# before a final newline, so Python code matches robot ids in full with `is_robot_id`.
ROBOT_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"
_ROBOT_ID = re.compile(ROBOT_ID_PATTERN)
# The broker users of the service side (broker-config): no robot may log in as one of them.
SERVICE_USERS = ("reconciler", "viewer", "operator")
# DDS derives its UDP ports from the ROS domain id; beyond 232 they pass 65535 and a node fails
# at start (ROS 2 docs, "The ROS_DOMAIN_ID"). One bound for fleet.yaml, the Launch Request and
# agent.yaml's `env:`.
MAX_ROS_DOMAIN_ID = 232
ROS_DOMAIN_DESCRIPTION = (
    f"the ROS 2 domain (ROS_DOMAIN_ID, 0 to {MAX_ROS_DOMAIN_ID}) the robot's brain runs "
    "in: robots on different domains share no ROS graph"
)


def is_robot_id(text: str) -> bool:
    return _ROBOT_ID.fullmatch(text) is not None


# What may become a file or folder name: a robot id's shape. No `/`, no leading `.` (so no `..`),
# no space, control character, escape or line break: nothing that leaves its folder, hides, or
# misleads a terminal listing it.
FILE_NAME_RULE = "letters, digits, '_', '.', '-' (1 to 64), starting with a letter or digit"


def file_name_problem(name: str) -> str | None:
    """Why `name` may not become a file or folder name, else None. The one rule for every name
    a command writes a file from: robot ids, robot templates, mapping schemes, platforms,
    scenarios, capability configurations and broker users."""
    if is_robot_id(name):
        return None
    return f"cannot name a file: {FILE_NAME_RULE}"


def file_name(what: str, name: str) -> str:
    """`name`, once it may become a file name; else a CliError (exit 2) saying `what` it was
    (an option, e.g. `--template`) and the rule, the name shown escaped."""
    problem = file_name_problem(name)
    if problem is not None:
        raise CliError(f"{what} '{shorten(printable(name), 80)}' {problem}")
    return name


def reserved_robot_id(text: str) -> str | None:
    """The service user a robot id would collide with (in any letter case), else None."""
    for user in SERVICE_USERS:
        if text.lower() == user:
            return user
    return None


JsonScalar = bool | int | float | str
JsonObject = dict[str, Any]


class StrictModel(BaseModel):
    """The base of every typed document, agent.yaml and the Launch Request: unknown fields are
    refused (a typo must never pass silently) and values are taken only of their own type:
    `suspended: "yes"`, `minimum: true` or `speed: "0.2"` are mistakes, not conversions."""

    model_config = ConfigDict(extra="forbid", strict=True)


MappingKind = Literal["topic", "service", "action_client"]


class MappingBinding(StrictModel):
    """How one mapping is bound on a platform (a ROS topic, service or action client)."""

    kind: MappingKind = Field(description="a topic, a service, or an action the brain calls")
    name: str = Field(description="e.g. the topic name /cmd_vel")
    type: str = Field(description="e.g. geometry_msgs/msg/Twist")
