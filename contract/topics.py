"""Every MQTT topic of the project, declared once: pattern, direction, payload, who reads and writes
it, retained or not. Topic names, the Mosquitto ACL, subscriptions, the checks of `up`'s broker and
docs/reference/topics.md (written by `python -m robotconf.workstation.docs`) derive from it.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from enum import Enum


class Role(str, Enum):
    """Who a client is: a robot (its agent, on its own topics only) or a service user."""

    ROBOT = "robot"
    RECONCILER = "reconciler"
    VIEWER = "viewer"
    OPERATOR = "operator"


SERVICES = (Role.RECONCILER, Role.VIEWER, Role.OPERATOR)
EVERYONE = frozenset(Role)
# The placeholders of a pattern: a robot's id (a robot may use only its own) and a client's id (a
# client may use only its own).
ROBOT = "{robot}"
CLIENT = "{client}"


@dataclass(frozen=True)
class Topic:
    """One topic (or a family of them, one per robot or per client) under the prefix."""

    key: str  # the name `Topics` gives it (contract/wire.py)
    pattern: str  # under `<prefix>/`, with ROBOT or CLIENT where an id goes
    direction: str  # who publishes to whom
    payload: str  # the model of its payload, by name
    read: frozenset[Role]
    write: frozenset[Role]
    retained: bool
    qos: int | None  # fixed QoS of its publishes; None when the publisher chooses
    about: str
    by_name: bool = False  # a stream: subscribed to only where asked for by its key

    def access(self, role: Role) -> str | None:
        """Mosquitto's word for what `role` may do here: read, write, readwrite, or None."""
        read, write = role in self.read, role in self.write
        return "readwrite" if read and write else "read" if read else "write" if write else None

    @property
    def per_robot(self) -> bool:
        return ROBOT in self.pattern

    @property
    def per_client(self) -> bool:
        return CLIENT in self.pattern

    def name(self, prefix: str, robot_id: str = "+", client_id: str = "+") -> str:
        """The topic of one robot (or client), or with `+` the filter of all of them."""
        return f"{prefix}/" + self.pattern.replace(ROBOT, robot_id).replace(CLIENT, client_id)


def _roles(*roles: Role) -> frozenset[Role]:
    return frozenset(roles)


SERVICE_READERS = frozenset(SERVICES)

# The order of the rows is the order of the ACL's lines and of the docs' table.
TOPICS: tuple[Topic, ...] = (
    Topic(
        "launch", f"robots/{ROBOT}/launch", "reconciler → agent",
        "LaunchRequest or StopRequest (contract/launch.py)",
        SERVICE_READERS | {Role.ROBOT}, _roles(Role.RECONCILER), True, 1,
        "the robot's Launch Request, signed when the lab signs; the reconciler reads them back "
        "(what is published is its only memory)",
    ),
    Topic(
        "status", f"robots/{ROBOT}/status", "agent → everyone", "AgentStatus (contract/wire.py)",
        SERVICE_READERS | {Role.ROBOT}, _roles(Role.ROBOT), True, 1,
        "the agent's state and its brain's; also its Last Will (offline). The robot reads its "
        "own back, to overwrite a late Last Will of an older connection",
    ),
    Topic(
        "description", f"robots/{ROBOT}/description", "agent → everyone",
        "RobotDescription (contract/wire.py)", SERVICE_READERS, _roles(Role.ROBOT), True, 1,
        "what the robot says about itself when it connects",
    ),
    Topic(
        "interfaces", f"robots/{ROBOT}/interfaces", "agent → everyone",
        "RobotInterfaces (contract/interfaces.py)", SERVICE_READERS, _roles(Role.ROBOT), True, 1,
        "the ROS interfaces the robot really has (agent.yaml `interfaces`), for drift and drafts",
    ),
    Topic(
        "goals", f"robots/{ROBOT}/goals", "agent → everyone", "GoalsSummary (contract/goals.py)",
        SERVICE_READERS, _roles(Role.ROBOT), True, 1,
        "what the robot's brain achieved since the current request: goals ended per task, the "
        "goal underway with its progress, the last outcome, vitals and recent events",
    ),
    Topic(
        "goal_outcomes", f"robots/{ROBOT}/goals/outcomes", "agent → reconciler",
        "OutcomeRecord (contract/goals.py)", SERVICE_READERS, _roles(Role.ROBOT), False, 1,
        "each goal's end (succeeded, failed, canceled, stale) with the revision and digest it "
        "ran under: the reconciler keeps them in its outcome ledger",
        by_name=True,
    ),
    Topic(
        "reconciler_status", "reconciler/status", "reconciler → everyone",
        "ReconcilerStatus (contract/wire.py)", SERVICE_READERS, _roles(Role.RECONCILER), True, 1,
        "ready or stalled and why, with a heartbeat; its Last Will says offline",
    ),
    Topic(
        "reconciler_rollout", "reconciler/rollout", "reconciler → itself",
        "WaveRecord (reconciler/wave_memory.py)", _roles(Role.RECONCILER), _roles(Role.RECONCILER),
        True, 1, "what the current wave of a rollout established: a restarted reconciler resumes",
    ),
    Topic(
        "rollout_request", "reconciler/requests", "operator → reconciler",
        "RolloutAction (contract/launch.py)", _roles(Role.RECONCILER), _roles(Role.OPERATOR),
        False, 1, "resume or abort a rollout's wave (`robotconf rollout`); signed when the lab "
        "signs, answered in the reconciler's status",
        by_name=True,
    ),
    Topic(
        "restart", f"robots/{ROBOT}/restart", "operator or reconciler → agent",
        "RestartRequest (contract/launch.py)", _roles(Role.ROBOT),
        _roles(Role.RECONCILER, Role.OPERATOR),
        False, 1, "start the brain again (`robotconf restart`); no robot may ask another",
    ),
    Topic(
        "logs_request", f"robots/{ROBOT}/logs/request", "operator → agent",
        "LogsRequest (contract/wire.py)", _roles(Role.ROBOT), _roles(Role.OPERATOR), False, 1,
        "ask for the brain's log (`robotconf logs`); a retained one is ignored",
    ),
    Topic(
        "logs", f"robots/{ROBOT}/logs", "agent → operators", "LogsChunk (contract/wire.py)",
        _roles(Role.OPERATOR), _roles(Role.ROBOT), False, 1,
        "the log's tail for a session, or the followed stream: only while someone asks",
    ),
    Topic(
        "sync", f"sync/{CLIENT}", "a client → itself", "any (a marker)", EVERYONE, EVERYONE,
        False, 1,
        "a client's private marker: a snapshot of the retained topics is complete when it returns",
    ),
)  # fmt: skip

BY_KEY: dict[str, Topic] = {topic.key: topic for topic in TOPICS}
ACCESS_ORDER = ("readwrite", "read", "write")  # a service user's lines, grouped in this order


def role_lines(role: Role) -> list[tuple[str, Topic]]:
    """(access, topic) of a service user's ACL lines: grouped by access, then in table order."""
    found = [(topic.access(role), topic) for topic in TOPICS if not topic.per_client]
    return [
        (access, topic) for wanted in ACCESS_ORDER for access, topic in found if access == wanted
    ]


def pattern_lines() -> list[tuple[str, Topic]]:
    """(access, topic) of the rules every client gets for its own ids, in table order: a robot's
    on its own topics (ROBOT is its user name), then everyone's on its own client id."""
    own = [(t.access(Role.ROBOT), t) for t in TOPICS if t.per_robot]
    mine = [(t.access(Role.ROBOT), t) for t in TOPICS if t.per_client]
    return [(access, topic) for access, topic in own + mine if access is not None]


def subscriptions(role: Role, prefix: str, *keys: str, robot_id: str = "+") -> list[str]:
    """The filters of rows `keys` (every row `role` reads, sync aside, when none), of one robot or
    (`+`) all of them. A row `role` may not read is refused here: a subscription the ACL would
    leave without messages fails where it is written, not silently on a production broker."""
    for key in keys:
        if role not in BY_KEY[key].read:
            raise ValueError(f"{role.value} may not read the {key} topics (contract/topics.py)")
    # Without keys: every row but the streams, which are asked for by name (a fleet's outcomes
    # are a thousand messages a second that a status reader has no use for).
    every = [t for t in TOPICS if role in t.read and not t.per_client and not t.by_name]
    rows = [BY_KEY[k] for k in keys] or every
    return [topic.name(prefix, robot_id) for topic in rows]


# ---------------------------------------------------------------- one client's rules


def _level_safe(text: str) -> bool:
    """An id a pattern may put in a topic level: Mosquitto does not substitute one that holds a
    wildcard or a separator (a robot named `+` would read every robot's topics)."""
    return bool(text) and not any(c in text for c in "/+#")


class Grants:
    """What one client may do, as the generated ACL says: compiled once per client, so that a
    check on a publish or a delivery is one regular-expression match."""

    __slots__ = ("_read", "_write", "read", "write")

    def __init__(self, read: tuple[str, ...], write: tuple[str, ...]) -> None:
        self.read, self.write = read, write  # topic filters
        self._read, self._write = _compile(read), _compile(write)

    def may_write(self, topic: str) -> bool:
        return self._write.fullmatch(topic) is not None

    def may_read(self, topic: str) -> bool:
        return self._read.fullmatch(topic) is not None

    def may_subscribe(self, topic_filter: str) -> bool:
        """True when every topic the filter matches may be read: a filter no read rule covers
        (a `+` where the rule has an id) is refused whole."""
        return any(_covers(rule, topic_filter) for rule in self.read)


def _compile(filters: Iterable[str]) -> re.Pattern[str]:
    parts = ["/".join(_level(level) for level in f.split("/")) for f in filters]
    return re.compile("|".join(f"(?:{p})" for p in parts) or r"(?!)")


def _level(level: str) -> str:
    if level == "+":
        return "[^/]*"
    if level == "#":  # only as the last level (not used by the table): the rest, if any
        return ".*"
    return re.escape(level)


def _covers(rule: str, topic_filter: str) -> bool:
    ours, theirs = rule.split("/"), topic_filter.split("/")
    for index, level in enumerate(theirs):
        if index >= len(ours):
            return False
        if ours[index] == "#":
            return True
        if level == "#" or (level == "+" and ours[index] != "+"):
            return False
        if ours[index] not in ("+", level):
            return False
    return len(ours) == len(theirs) or ours[len(theirs) :] == ["#"]


def grants(
    prefix: str, username: str | None, client_id: str, services: Mapping[str, Role]
) -> Grants:
    """The rules of the ACL `render_acl` writes, for one client: the pattern rules with its user
    name and client id (for everyone: a service user's name is never a robot's id), and a service
    user's own lines."""
    read: list[str] = []
    write: list[str] = []
    for access, topic in pattern_lines():
        own = username if topic.per_robot else client_id
        if own is None or not _level_safe(own):
            continue
        _grant(access, topic.name(prefix, robot_id=own, client_id=own), read, write)
    role = services.get(username or "")
    for access, topic in role_lines(role) if role is not None else []:
        _grant(access, topic.name(prefix), read, write)
    return Grants(tuple(read), tuple(write))


def _grant(access: str, name: str, read: list[str], write: list[str]) -> None:
    if access in ("read", "readwrite"):
        read.append(name)
    if access in ("write", "readwrite"):
        write.append(name)
