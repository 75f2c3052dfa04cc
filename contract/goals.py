"""What robots achieve, on the wire: the brain's reports to its agent and the agent's to the fleet.

Two exchanges, both bounded here and only here:

- brain → agent: JSON lines over the local socket the agent owns in the brain's work folder
  (`ROBOTCONF_BRAIN_SOCKET`, mode 0600). One JSON object a line, at most `MAX_LINE_BYTES`;
  `BrainMessage` reads one. The brain never holds broker credentials.
- agent → everyone: a retained `GoalsSummary` per robot (`<prefix>/robots/<id>/goals`) and a
  non-retained stream of `OutcomeRecord`s (`<prefix>/robots/<id>/goals/outcomes`). Every record
  carries the revision and request digest the brain ran under (as the agent knows them, never as
  the brain says) and the brain's run.

Pure pydantic; agent-safe (the robot-only install has it).
"""

from __future__ import annotations

from enum import Enum
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

from robotconf.contract.clock import now
from robotconf.contract.models import CODE_PATTERN as CODE_PATTERN

WIRE_VERSION = 1
MAX_LINE_BYTES = 4096  # one JSON line from a brain; a longer one is cut off and counted
MAX_TEXT = 200  # characters of a note, a message or a vital's text kept (longer: cut, with …)
MAX_CODE = 64
GOAL_ID_PATTERN = r"^[A-Za-z0-9_.:-]{1,64}$"  # the brain's own id of one goal in its run
TASK_PATTERN = r"^[A-Za-z0-9_.:/-]{1,128}$"  # a task's name, as the models write them
MAX_VITALS = 16  # named vitals a robot reports at once; more are refused
VITAL_NAME_PATTERN = r"^[A-Za-z][A-Za-z0-9_.-]{0,31}$"
MAX_EVENTS_KEPT = 10  # events a summary carries, newest last
MAX_RECENT_KEPT = 10  # ended goals a summary carries, newest last
MAX_TASKS_KEPT = 64  # tasks a summary counts separately; the rest are counted under OTHER_TASK
OTHER_TASK = "(other)"
MAX_ETA = 7 * 24 * 3600.0  # seconds: a longer ETA is cut to this


class OutcomeState(str, Enum):
    """How a goal ended. `stale` is the agent's word, not the brain's: a goal underway with no
    progress for the agent's `stale_after` (the goal may still end later)."""

    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELED = "canceled"
    STALE = "stale"


class Severity(str, Enum):
    INFO = "info"
    WARNING = "warning"
    ERROR = "error"
    CRITICAL = "critical"


VitalValue = float | int | bool | Annotated[str, Field(max_length=MAX_TEXT)]


def success_rate(succeeded: int, failed: int) -> float | None:
    """The one success rate of the project: succeeded of succeeded and failed goals. A canceled
    goal was called off and a stale one may still end: neither counts for or against a revision.
    None before any goal has succeeded or failed."""
    ended = succeeded + failed
    return succeeded / ended if ended else None


# ---------------------------------------------------------------- brain → agent (JSON lines)


class _Line(BaseModel):
    # Strict on the brain's side: a misspelled field is an error the brain's author sees.
    model_config = ConfigDict(extra="forbid", frozen=True)
    v: Literal[1] = 1


class Hello(_Line):
    """The first line of a connection: the library (or a C++ brain) says who it is."""

    type: Literal["hello"]
    pid: int | None = Field(None, ge=1, description="the brain process's pid")
    digest: str | None = Field(
        None, max_length=80, description="the digest the brain believes it runs (checked)"
    )
    library: str = Field("", max_length=64, description="e.g. robotconf.brain/1, my-cpp-brain/2")


class Ready(_Line):
    """As systemd's READY=1: from now on the brain is healthy (not from process start)."""

    type: Literal["ready"]


class GoalLine(_Line):
    """One step of one goal: started, progress, or one end."""

    type: Literal["goal"]
    id: str = Field(pattern=GOAL_ID_PATTERN)
    task: str = Field(pattern=TASK_PATTERN)
    state: Literal["started", "progress", "succeeded", "failed", "canceled"]
    fraction: float | None = Field(None, ge=0.0, le=1.0, allow_inf_nan=False)
    eta: float | None = Field(None, ge=0.0, allow_inf_nan=False, description="seconds left")
    note: str | None = Field(None, max_length=4 * MAX_TEXT)
    code: str | None = Field(None, pattern=CODE_PATTERN, description="with state failed")
    message: str | None = Field(None, max_length=4 * MAX_TEXT)


class VitalsLine(_Line):
    """A few named numbers or short strings: battery, pose, CPU, topic rates."""

    type: Literal["vitals"]
    values: dict[Annotated[str, Field(pattern=VITAL_NAME_PATTERN)], VitalValue] = Field(
        max_length=MAX_VITALS
    )


class EventLine(_Line):
    type: Literal["event"]
    severity: Severity
    message: str = Field(max_length=4 * MAX_TEXT)


BrainMessage = Annotated[
    Hello | Ready | GoalLine | VitalsLine | EventLine, Field(discriminator="type")
]


# ---------------------------------------------------------------- agent → fleet (MQTT)


class _Message(BaseModel):
    # Tolerant on read: a newer peer may add fields.
    model_config = ConfigDict(extra="ignore")


class CurrentGoal(_Message):
    goal: str
    task: str
    started_at: float = Field(description="unix time, the agent's clock")
    updated_at: float = Field(description="unix time of its last start or progress")
    fraction: float | None = None
    eta: float | None = Field(None, description="seconds left, as the brain last said")
    note: str | None = None
    stale: bool = Field(False, description="no progress for the agent's stale_after")


class LastOutcome(_Message):
    goal: str
    task: str
    outcome: OutcomeState
    code: str | None = None
    message: str | None = None
    ended_at: float
    duration: float | None = Field(None, description="seconds from its start, when seen")


class TaskCounts(_Message):
    """Ended goals of one task since the current request, and those underway."""

    completed: int = 0  # succeeded
    failed: int = 0
    canceled: int = 0
    underway: int = 0
    stale: int = 0


class BrainEvent(_Message):
    at: float
    severity: Severity
    message: str


class GoalsSummary(TaskCounts):
    """A robot's retained goals summary: what its brain achieved since the current request.

    The totals (`completed` ... `stale`, inherited) are over every task; `tasks` splits them."""

    robot_id: str
    revision: str | None = None
    digest: str | None = None
    scenario: str | None = None
    run: str | None = Field(None, description="the brain run the counts are of (agent's id)")
    since: float | None = Field(None, description="unix time the counted request was accepted")
    reporting: bool = Field(
        False, description="the brain speaks the library's wire; false: goals are unknown"
    )
    ready: bool | None = Field(None, description="said ready; None: never will (no library)")
    tasks: dict[str, TaskCounts] = Field(default_factory=dict)
    current: CurrentGoal | None = None
    last: LastOutcome | None = None
    recent: list[LastOutcome] = Field(default_factory=list, description="newest last")
    vitals: dict[str, VitalValue] = Field(default_factory=dict)
    vitals_at: float | None = None
    events: list[BrainEvent] = Field(default_factory=list, description="newest last")
    dropped: int = Field(0, description="lines refused or throttled since the current request")
    updated: float = Field(default_factory=now)


class OutcomeRecord(_Message):
    """One ended (or gone stale) goal: the stream the reconciler's ledger keeps."""

    kind: Literal["OutcomeRecord"] = "OutcomeRecord"
    robot_id: str
    revision: str | None
    digest: str | None
    scenario: str | None = None
    run: str
    seq: int = Field(ge=0, description="grows per run: (robot, run, seq) is one record")
    goal: str
    task: str
    outcome: OutcomeState
    code: str | None = None
    message: str | None = None
    started_at: float | None = None
    ended_at: float
    duration: float | None = None
