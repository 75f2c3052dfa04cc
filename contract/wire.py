"""The MQTT contract (docs/architecture.md#the-mqtt-contract): topic names, broker URLs and the
retained status messages.

Pure pydantic; shared by the agent, the reconciler and `robotconf status`.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Literal
from urllib.parse import unquote, urlsplit

from pydantic import BaseModel, ConfigDict, Field, field_validator

from robotconf.contract.clock import now
from robotconf.contract.diagnostics import Diagnostic
from robotconf.contract.models import ROBOT_ID_PATTERN
from robotconf.contract.textsafe import printable, shorten
from robotconf.contract.topics import BY_KEY

DEFAULT_PREFIX = "robotconf"
BROKER_ENV = "ROBOTCONF_BROKER"
DEFAULT_BROKER = "mqtt://127.0.0.1:1883"


def _one(key: str) -> Callable[[Topics, str], str]:
    """A method of `Topics` giving the name of table row `key` for one robot."""
    topic = BY_KEY[key]

    def name(self: Topics, robot_id: str) -> str:
        return topic.name(self.prefix, robot_id)

    name.__doc__ = f"{topic.about} ({topic.direction})."
    return name


def _fixed(key: str) -> property:
    """A property of `Topics`: the name of a table row without ids, or the filter of a per-robot
    row's topics of every robot (`+`)."""
    topic = BY_KEY[key]

    def name(self: Topics) -> str:
        return topic.name(self.prefix)

    name.__doc__ = f"{topic.about} ({topic.direction})."
    return property(name)


@dataclass(frozen=True)
class Topics:
    """Topic names under one prefix, made from the table of topics (contract/topics.py)."""

    prefix: str = DEFAULT_PREFIX

    launch = _one("launch")
    status = _one("status")
    description = _one("description")
    interfaces = _one("interfaces")
    goals = _one("goals")
    goal_outcomes = _one("goal_outcomes")
    logs = _one("logs")
    logs_request = _one("logs_request")
    restart = _one("restart")
    reconciler_status = _fixed("reconciler_status")
    reconciler_rollout = _fixed("reconciler_rollout")
    rollout_request = _fixed("rollout_request")
    all_launch = _fixed("launch")
    all_status = _fixed("status")
    all_description = _fixed("description")
    all_interfaces = _fixed("interfaces")
    all_goals = _fixed("goals")
    all_goal_outcomes = _fixed("goal_outcomes")

    @property
    def sync(self) -> str:
        """The head of every client's private marker topic (`<sync>/<client id>`)."""
        return BY_KEY["sync"].name(self.prefix).removesuffix("/+")

    def robot_of(self, topic: str) -> tuple[str, str] | None:
        """(robot id, leaf) for a topic under `<prefix>/robots/`, else None."""
        head = f"{self.prefix}/robots/"
        if not topic.startswith(head):
            return None
        parts = topic[len(head) :].split("/")
        if len(parts) != 2:
            return None
        return parts[0], parts[1]


def agent_client_id(robot_id: str) -> str:
    """The MQTT client id of a robot's agent (Mosquitto's robot listener makes it the user name,
    the robot id; `up`'s broker takes only these two)."""
    return f"robotconf-agent-{robot_id}"


def validate_prefix(prefix: str) -> str:
    if (
        not prefix
        or any(c in prefix for c in "#+")
        or prefix.startswith("/")
        or prefix.endswith("/")
    ):
        raise ValueError(
            f"topic prefix {prefix!r} is not usable: it must be non-empty, without '+' or '#', "
            "and not start or end with '/' (e.g. 'robotconf' or 'lab1/robotconf')"
        )
    return prefix


@dataclass(frozen=True)
class BrokerAddress:
    host: str
    port: int
    tls: bool
    username: str | None = None
    password: str | None = None

    @property
    def url(self) -> str:
        return f"{'mqtts' if self.tls else 'mqtt'}://{self.host}:{self.port}"


_USERINFO = re.compile(r"^([A-Za-z][A-Za-z0-9+.-]*://)[^/?#]*@")


def redact_url(url: str) -> str:
    """The URL without its user name and password: what logs, messages and statuses show.
    Textual, so that even a URL too broken to parse never echoes a secret."""
    return _USERINFO.sub(r"\1", url)


def parse_broker_url(url: str) -> BrokerAddress:
    """`mqtt://host[:port]` or `mqtts://host[:port]` (TLS); credentials in the URL allowed."""
    shown = redact_url(url)
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as exc:
        raise ValueError(
            f"broker URL {shown!r} is not valid ({exc}); e.g. mqtt://127.0.0.1:1883"
        ) from None
    if parts.scheme not in ("mqtt", "mqtts"):
        raise ValueError(
            f"broker URL {shown!r} must start with mqtt:// or mqtts:// (TLS), "
            "e.g. mqtt://127.0.0.1:1883"
        )
    if not parts.hostname:
        raise ValueError(f"broker URL {shown!r} has no host; e.g. mqtt://127.0.0.1:1883")
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise ValueError(f"broker URL {shown!r} must be only scheme://host:port")
    tls = parts.scheme == "mqtts"
    return BrokerAddress(
        host=parts.hostname,
        port=port or (8883 if tls else 1883),
        tls=tls,
        username=unquote(parts.username) if parts.username else None,
        password=unquote(parts.password) if parts.password else None,
    )


# ---------------------------------------------------------------- retained messages


class AgentState(str, Enum):
    """Supervisor states of an agent and its brain service: the table is
    docs/architecture.md#the-agents-states."""

    OFFLINE = "offline"
    IDLE = "idle"
    STARTING = "starting"
    RUNNING = "running"
    STOPPING = "stopping"
    EXITED = "exited"
    FAILED = "failed"
    BACKOFF = "backoff"
    REJECTED = "rejected"
    # A stop, restart or reload waits while the brain's hold file exists (agent.yaml
    # `max_defer`): the brain runs on, on the request it ran before.
    DEFERRED = "deferred"


# A brain is up, or about to be, in these states: the robot runs (or is made to run) something.
ACTIVE_STATES = frozenset(
    {
        AgentState.STARTING,
        AgentState.RUNNING,
        AgentState.STOPPING,
        AgentState.BACKOFF,
        AgentState.DEFERRED,
    }
)


_COMMIT = re.compile(r"[0-9a-f]{40}")


def is_commit(text: str) -> bool:
    """Whether `text` is a whole commit id (40 lower-case hex digits): what may reach git when
    it was read from the broker or a file, never an option or a ref expression."""
    return _COMMIT.fullmatch(text) is not None


def short_rev(revision: str | None) -> str:
    """A commit as people read it: its first 12 hex digits ("-" for none)."""
    return revision[:12] if revision else "-"


def short_digest(digest: str | None) -> str:
    """A request digest as people read it: its first 12 hex digits ("-" for none)."""
    return digest.removeprefix("sha256:")[:12] if digest else "-"


class _Message(BaseModel):
    # Tolerant on read: a newer peer may add fields.
    model_config = ConfigDict(extra="ignore")


class RobotDescription(_Message):
    """What the robot says about itself when it connects."""

    id: str = Field(pattern=ROBOT_ID_PATTERN)
    name: str | None = None
    recommended_template: str | None = None
    platform: str | None = None


class AgentStatus(_Message):
    """The agent's retained status; `seq` grows at every connection (late-will detection)."""

    robot_id: str
    state: AgentState
    digest: str | None = None
    revision: str | None = None
    pid: int | None = None
    exit_code: int | None = None
    restarts: int = 0
    # Times the running brain was signalled to reload a request instead of being restarted.
    reloads: int = 0
    since: float = Field(default_factory=now, description="unix time of the last transition")
    message: str = ""
    warnings: list[str] = Field(default_factory=list)
    seq: int = 0
    # The last restart asked for from the desk (`robotconf restart`) and carried out, or
    # deferred by the brain's hold file (state `deferred`): who asked (as the request says)
    # and when it was issued (unix time).
    restart_requested_by: str | None = None
    restart_requested_at: float | None = None
    # Why the robot's interfaces could not be read (agent.yaml `interfaces`), while they
    # cannot: the interfaces topic keeps the last lists read. Absent from older agents.
    interfaces_error: str | None = None
    # While `deferred`: since when (unix time, the agent's clock) and the most it defers
    # (agent.yaml `max_defer`, seconds) before it proceeds anyway.
    deferred_since: float | None = None
    max_defer: float | None = None
    # Its brain's hold file exists now: a stop, restart or reload would be deferred (for up to
    # `max_defer`, given with it). The reconciler holds a whole group's restart while one of
    # its robots is busy (fleet.yaml groups), so that a group never runs two revisions.
    busy: bool = False


def is_online(status: AgentStatus | None) -> bool:
    """The one test of a robot being online: its agent has reported, and its last status is
    not `offline` (its Last Will, or said on a clean stop)."""
    return status is not None and status.state is not AgentState.OFFLINE


# Logs from the desk (`robotconf logs`): the operator asks on `logs_request`, the agent answers
# on `logs`, only while asked. Bounds for both sides of that exchange:
MAX_LOG_MESSAGE_BYTES = 64 * 1024  # one answer message; a longer line is cut, with a marker
MAX_TAIL_LINES = 1000  # the most lines one request may ask for
LOG_FOLLOW_TTL = 30.0  # seconds the agent keeps streaming after the last request
SESSION_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"


class LogsRequest(_Message):
    """Asks an agent for the last `lines` of its brain's log (with the agent's own events in
    it), and with `follow` for what comes next, until LOG_FOLLOW_TTL after the newest ask."""

    model_config = ConfigDict(extra="forbid")

    apiVersion: Literal["robotconf/v1"] = "robotconf/v1"
    kind: Literal["LogsRequest"] = "LogsRequest"
    session: str = Field(pattern=SESSION_PATTERN, description="names the answers to this ask")
    lines: int = Field(50, ge=0, le=MAX_TAIL_LINES)
    follow: bool = False


class LogsChunk(_Message):
    """Part of a log on the `logs` topic: the tail answering `session`, or (session None) the
    stream that every follower reads."""

    robot_id: str
    session: str | None = None
    lines: list[str] = Field(default_factory=list)
    dropped: int = Field(
        0,
        description="lines left out before these: over the rate limit, or the queue's bound "
        "shared between askers",
    )
    end: bool = Field(False, description="the last chunk of the tail for `session`")
    following: bool = Field(False, description="the agent streams new lines after this")


class StatusDiagnostic(_Message):
    """One problem in the reconciler status, structured like the validator's diagnostics.

    A rule finding has its file and position and an RC code; a problem with no place in a
    file (the source is unreachable, a build crashed) has no path and the reason as its code."""

    path: str | None = None
    line: int | None = None
    column: int | None = None
    severity: Literal["error", "warning"] = "error"
    code: str = ""
    message: str

    @classmethod
    def of(cls, diagnostic: Diagnostic) -> StatusDiagnostic:
        return cls(
            path=diagnostic.path,
            line=diagnostic.line,
            column=diagnostic.col,
            severity=diagnostic.severity.value,
            code=diagnostic.code,
            message=diagnostic.message,
        )

    def __str__(self) -> str:
        """`path:line:col: severity CODE message`, as `robotconf validate` prints it."""
        where = ""
        if self.path is not None:
            where = ":".join(
                [self.path, *(str(n) for n in (self.line, self.column) if n is not None)]
            )
            where += ": "
        if not where and not self.code:  # the text form of older reconcilers
            return self.message
        code = f" {self.code}" if self.code else ""
        return f"{where}{self.severity}{code} {self.message}"


class ReconcilerReason(str, Enum):
    """Why the reconciler's status is what it is (like a Flux condition's reason)."""

    APPLIED = "Applied"  # the head commit is applied
    PROGRESSING = "Progressing"  # publishing
    BUILD_FAILED = "BuildFailed"  # the head commit does not validate or render
    EMPTY_FLEET_REFUSED = "EmptyFleetRefused"  # the head would unassign every robot
    SOURCE_UNAVAILABLE = "SourceUnavailable"  # the branch cannot be read or fetched
    BROKER_UNAVAILABLE = "BrokerUnavailable"  # the broker did not acknowledge every message
    INTERNAL_ERROR = "InternalError"  # a bug: logged with its traceback, retried
    OFFLINE = "Offline"  # the reconciler stopped, or its Last Will: it died
    ROLLOUT_PAUSED = "RolloutPaused"  # fleet.yaml's rollout says paused: no wave advances
    ROLLOUT_HALTED = "RolloutHalted"  # too many robots failed; on_failure: halt
    ROLLED_BACK = "RolledBack"  # too many robots failed; the moved ones run the stable revision


RolloutState = Literal["Progressing", "Paused", "Complete", "Halted", "RolledBack"]
MAX_LISTED = 100  # robot ids a rollout status lists per kind; the counts say how many in all


Verdict = Literal["Successful", "Failed", "Inconclusive"]
# What an operator runs on a wave paused on inconclusive evidence: the reconciler's message,
# the status line and the page name the same words.
RESUME_COMMAND = "robotconf rollout resume"  # passes the wave
ABORT_COMMAND = "robotconf rollout abort"  # fails it: rolled back or halted, as on_failure says
VERIFY_COMMANDS = f"{RESUME_COMMAND} passes it, {ABORT_COMMAND} rolls back"


class WaveVerification(_Message):
    """What a wave's goal outcomes show against what `rollout.verify` asks (Argo Rollouts'
    analysis run, counted in goals). No verdict yet: the evidence is still being gathered."""

    verdict: Verdict | None = Field(None, description="none yet: still gathering")
    dry_run: bool = Field(False, description="judged and shown, not gating")
    goals: int = Field(0, description="goals the wave's robots ended on the revision (decided)")
    min_goals: int = 0
    succeeded: int = 0
    failed: int = 0
    canceled: int = 0
    robots: int = Field(0, description="the wave's robots that reported an ended goal")
    rate: float | None = Field(None, description="succeeded / (succeeded + failed)")
    success_rate: float | None = Field(None, description="the threshold, when one is set")
    stable_rate: float | None = Field(
        None, description="the stable revision's robots' rate over the same window (compare)"
    )
    stable_goals: int = Field(0, description="the goals that rate is over")
    max_drop: float | None = None
    critical: list[str] = Field(default_factory=list, description="critical codes reported")
    deadline: float | None = Field(None, description="unix time the evidence is judged by")
    decided_by: str | None = Field(
        None, description="the operator who resumed (passed) or aborted (failed) it by hand"
    )
    message: str = ""


class OperatorAnswer(_Message):
    """The reconciler's answer to the last operator action it was sent (`robotconf rollout`):
    the desk that asked waits for the status that names its `issued_at`."""

    action: str
    requested_by: str
    issued_at: float
    accepted: bool
    message: str = ""


# revoked: verified on the stage, then failed there while later stages rolled: rolled back.
StageWord = Literal["waiting", "rolling", "verifying", "verified", "failed", "revoked"]


class StageState(_Message):
    """One stage of the promotion ladder (fleet.yaml `stages`) in a rollout: where the
    revision stands on it, and the revision verified for its robots."""

    name: str
    state: StageWord
    verified_revision: str | None = Field(
        None, description="the last revision verified on this stage: what its robots keep"
    )
    rollback_revision: str | None = Field(
        None,
        description="what this stage's robots go back to if the rollout fails on it: the "
        "revision verified for them when the rollout began",
    )


class RolloutStatus(_Message):
    """A rollout of `revision`, wave by wave, as the reconciler status carries it: where it is
    and why, and (stateless) what a restarted reconciler resumes from."""

    revision: str = Field(description="the commit being rolled out")
    stable_revision: str | None = Field(
        None, description="the last revision that fully rolled out: what a rollback restores"
    )
    state: RolloutState
    wave: int = Field(0, description="index of the current wave (0-based)")
    waves: int = 0
    wave_name: str = ""
    wave_started_at: float | None = Field(None, description="unix time the wave was published")
    healthy: list[str] = Field(default_factory=list, description="of the current wave")
    failed: list[str] = Field(default_factory=list, description="of the current wave")
    pending: list[str] = Field(default_factory=list, description="of the current wave")
    offline: list[str] = Field(
        default_factory=list,
        description="offline robots of this wave and the waves before that do not run the "
        "revision yet: skipped (rollout.offline: skip), they get it when they reconnect",
    )
    counts: dict[str, int] = Field(
        default_factory=dict,
        description="healthy, failed and pending robots of the wave, and offline ones as listed",
    )
    verification: WaveVerification | None = Field(
        None, description="the wave's goal outcomes against rollout.verify, when it is set"
    )
    stage: str | None = Field(None, description="the stage the current wave is in")
    stages: list[StageState] = Field(
        default_factory=list, description="the promotion ladder, in order (fleet.yaml stages)"
    )
    answer: OperatorAnswer | None = Field(
        None, description="the answer to the last operator action about this rollout"
    )
    message: str = ""


class HeldRobot(_Message):
    """A robot whose new request the reconciler holds back (fleet.yaml `drift: hold`): its
    reported interfaces do not fit it; it keeps its last good request until they do."""

    robot: str
    reason: str = Field(description="what it lacks, as drift words it")


# A heartbeat older than this many intervals (and at least STALE_MIN seconds, which absorbs a
# slow apply and some clock skew) means the reconciler is no longer working.
STALE_INTERVALS, STALE_MIN = 3, 60.0


ReconcilerState = Literal["Ready", "Stalled", "Progressing", "Offline"]


MAX_SUBJECT = 100  # characters of a commit subject carried (a shown one is shortened further)
MAX_COMMITS = 8  # commits a status describes: the revisions it names


class CommitLine(_Message):
    """A revision as people know it: the subject, author and time of its commit. Commit text
    is data from whoever can push: made printable and bounded on the way in."""

    revision: str = Field(max_length=64)
    subject: str = ""
    author: str = ""
    at: float | None = Field(None, description="unix time the commit was made")

    @field_validator("subject", "author", mode="before")
    @classmethod
    def _bounded(cls, value: object) -> object:
        if not isinstance(value, str):
            return value
        return shorten(printable(value.strip()), MAX_SUBJECT)


class ReconcilerStatus(_Message):
    """The reconciler's retained status (Flux-style: ready or stalled, with why)."""

    state: ReconcilerState
    ready: bool
    # A ReconcilerReason value; kept as text so that a reader older than a new reason still
    # reads the status.
    reason: str = ""
    branch: str | None = None
    source: str | None = None
    last_applied_revision: str | None = None
    last_attempted_revision: str | None = None
    failed_revision: str | None = Field(None, description="the revision the reason is about")
    diagnostics: list[StatusDiagnostic] = Field(default_factory=list)
    more_diagnostics: int = Field(0, description="diagnostics left out to keep the message small")
    message: str = ""
    robots: int = 0
    published: int = 0
    cleared: int = 0
    since: float = Field(default_factory=now)
    heartbeat: float | None = Field(None, description="unix time this status was published")
    interval: float | None = Field(None, description="seconds between heartbeats")
    broker_dropped: str | None = Field(
        None,
        description="how the reconciler knows that its reads of the broker lack retained "
        "messages the broker dropped (a per-client queue limit: max_queued_messages)",
    )
    ignored_payloads: dict[str, int] = Field(
        default_factory=dict, description="unreadable MQTT payloads skipped, by topic kind"
    )
    rollout: RolloutStatus | None = Field(
        None, description="the rollout in progress or last done, when fleet.yaml has a policy"
    )
    held: list[HeldRobot] = Field(
        default_factory=list,
        description=f"robots held back for drift (drift: hold), in id order; at most {MAX_LISTED}",
    )
    more_held: int = Field(0, description="held robots left out of `held`")
    commits: list[CommitLine] = Field(
        default_factory=list,
        max_length=MAX_COMMITS,
        description="the commits of the revisions this status names (subject, author, time)",
    )

    def commit(self, revision: str | None) -> CommitLine | None:
        """The commit line of `revision`, when the status carries it."""
        return next((c for c in self.commits if revision and c.revision == revision), None)

    @field_validator("diagnostics", mode="before")
    @classmethod
    def _older_text_form(cls, value: object) -> object:
        """Reconcilers before structured diagnostics published lines of text."""
        if isinstance(value, list):
            return [{"message": v} if isinstance(v, str) else v for v in value]
        return value

    def stale(self, at: float) -> bool:
        """True when its heartbeat is overdue; unknown (an older reconciler) is not stale."""
        if self.state == "Offline" or self.heartbeat is None or not self.interval:
            return False
        return at - self.heartbeat > max(STALE_INTERVALS * self.interval, STALE_MIN)
