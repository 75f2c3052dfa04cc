"""The typed documents of a Robot Configurator repository: catalogue models and configurations.

Pure pydantic. What the robot side shares (robot ids, the strict base, mapping bindings) is
declared in contract/models.py and re-exported here, so documents keep one import.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, model_validator

from robotconf.contract.durations import checked_seconds, parse_duration
from robotconf.contract.models import CODE_PATTERN
from robotconf.contract.models import MAX_ROS_DOMAIN_ID as MAX_ROS_DOMAIN_ID
from robotconf.contract.models import ROBOT_ID_PATTERN as ROBOT_ID_PATTERN
from robotconf.contract.models import ROS_DOMAIN_DESCRIPTION as ROS_DOMAIN_DESCRIPTION
from robotconf.contract.models import SERVICE_USERS as SERVICE_USERS
from robotconf.contract.models import JsonObject as JsonObject
from robotconf.contract.models import JsonScalar as JsonScalar
from robotconf.contract.models import MappingBinding as MappingBinding
from robotconf.contract.models import MappingKind as MappingKind
from robotconf.contract.models import StrictModel as StrictModel
from robotconf.contract.models import is_robot_id as is_robot_id
from robotconf.contract.models import reserved_robot_id as reserved_robot_id


# Empty defaults made by functions of ours, not by `dict` and `list`: pydantic reads each
# default factory's signature, and a builtin's is parsed from text by the tokenizer (its
# patterns compiled on first use): 6 ms of every `robotconf validate` start for these 15.
def _new_dict() -> dict[str, Any]:
    return {}


def _new_list() -> list[Any]:
    return []


# ---------------------------------------------------------------- settings


SettingType = Literal["number", "integer", "boolean", "string", "enum"]


class SettingDefinition(StrictModel):
    """A robot or logic setting: its type, default and bounds."""

    type: SettingType = Field(description="number, integer, boolean, string or enum")
    default: JsonScalar = Field(description="value used when a scenario does not set it")
    minimum: float | None = Field(None, description="lowest allowed value (number, integer)")
    maximum: float | None = Field(None, description="highest allowed value (number, integer)")
    choices: list[JsonScalar] | None = Field(None, description="allowed values (enum)")
    unit: str | None = Field(None, description="unit shown to people, e.g. m/s")
    description: str | None = None


# ---------------------------------------------------------------- catalogue: models/


class PlatformInfo(StrictModel):
    """Optional `models/platforms/<P>/platform.yaml`: what the platform is."""

    name: str | None = Field(None, description="must equal the folder name when given")
    description: str = ""


class RobotTemplate(StrictModel):
    """A robot model: the mappings it has and the robot settings it accepts."""

    name: str | None = Field(None, description="must equal the file name when given")
    description: str = ""
    mappings: list[str] = Field(description="names of the mappings this robot has")
    settings: dict[str, SettingDefinition] = Field(
        default_factory=_new_dict, description="robot setting -> its type, default and bounds"
    )


class MappingScheme(StrictModel):
    """How each mapping is bound on one platform (simulation and real robots differ)."""

    name: str | None = Field(None, description="must equal the file name when given")
    description: str = ""
    mappings: dict[str, MappingBinding] = Field(description="mapping -> how it is bound")


class Logic(StrictModel):
    """One implementation of an action: a code module of the brain service."""

    description: str = ""
    mappings: list[str] = Field(default_factory=_new_list, description="mappings the logic needs")
    settings: dict[str, SettingDefinition] = Field(
        default_factory=_new_dict, description="logic setting -> its type, default and bounds"
    )


class Action(StrictModel):
    """What a robot can do, on which platforms, by which alternative logics."""

    name: str | None = Field(None, description="must equal the file name when given")
    description: str = ""
    platforms: list[str] = Field(min_length=1, description="the platforms it is available on")
    requires: list[str] = Field(default_factory=_new_list, description="actions selected alongside")
    logics: dict[str, Logic] = Field(
        min_length=1, description="logic -> what it needs; a capability chooses one or several"
    )


class Task(StrictModel):
    """A platform-free activity, achieved by any one of its alternative action lists."""

    name: str | None = Field(None, description="must equal the file name when given")
    description: str = ""
    implementations: list[list[str]] = Field(
        min_length=1,
        description="alternative lists of actions; the task is achievable when every action "
        "of one list is selected",
    )


class OntologyObject(BaseModel):
    """An object of the environment (a Location, a door, another robot); extra fields allowed."""

    model_config = ConfigDict(extra="allow", coerce_numbers_to_str=True)

    id: str = Field(description="a goal's location may name it")
    name: str = Field(description="a goal's location may name it")
    type: str = Field(description="e.g. Location")


class Environment(StrictModel):
    """The world a scenario runs in: its objects and knowledge sets given to robots."""

    name: str | None = Field(None, description="must equal the file name when given")
    description: str = ""
    type: str = Field(description="e.g. 2D, Gazebo, Real")
    objects: list[OntologyObject] = Field(default_factory=_new_list, description="what is in it")
    knowledge_sets: dict[str, JsonObject] = Field(
        default_factory=_new_dict,
        description="name -> a JSON object a scenario may give its robots at launch",
    )
    ros_domain_id: int | None = Field(
        None,
        ge=0,
        le=MAX_ROS_DOMAIN_ID,
        description=f"{ROS_DOMAIN_DESCRIPTION}; the default of the robots whose scenario runs "
        "here (a robot's own wins); none: ROS's default, 0",
    )


# ---------------------------------------------------------------- configurations: configs/


def _distinct(names: list[str]) -> list[str]:
    if not names:
        raise ValueError("a list of one or more logic names")
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise ValueError(f"a list of distinct logic names ('{name}' is named twice)")
        seen.add(name)
    return names


# One logic name, or several (the thesis' autofill lights every logic that fits): a list that
# names each logic once. Both spellings of one logic are the same selection.
LogicChoice = (
    str
    | Annotated[
        list[str],
        Field(json_schema_extra={"minItems": 1, "uniqueItems": True}),
        AfterValidator(_distinct),
    ]
)


def logic_names(choice: LogicChoice) -> list[str]:
    """The logics an action's entry selects, in the order written."""
    return [choice] if isinstance(choice, str) else list(choice)


def logic_choice(names: list[str]) -> LogicChoice:
    """The entry that selects `names`: one name as itself, several as a list."""
    return names[0] if len(names) == 1 else list(names)


class CapabilityConfiguration(StrictModel):
    """A robot's composition: platform, scheme, optional template, the logics of each action."""

    name: str | None = Field(None, description="must equal the file name when given")
    description: str = ""
    platform: str = Field(description="the robot's software platform")
    mapping_scheme: str = Field(description="how mappings are bound on the platform")
    robot_template: str | None = Field(None, description="when set, the config must fit it")
    actions: dict[str, LogicChoice] = Field(
        description="action -> chosen logic, or a list of several logics"
    )

    def logics_of(self, action: str) -> list[str]:
        """The logics selected for `action` (none when it is not selected)."""
        choice = self.actions.get(action)
        return [] if choice is None else logic_names(choice)

    def selected_logics(self) -> list[tuple[str, str]]:
        """(action, logic) for every selected logic, in the order written."""
        return [(a, name) for a, choice in self.actions.items() for name in logic_names(choice)]


class Goal(StrictModel):
    """An initial task for the robot's planner, optionally at a location of the environment."""

    task: str = Field(description="the task to achieve")
    location: str | None = Field(None, description="id or name of a Location object")


class ScenarioConfiguration(StrictModel):
    """A capability configuration plus the world it runs in, its settings and goals."""

    name: str | None = Field(None, description="must equal the file name when given")
    description: str = ""
    capability: str = Field(description="the capability configuration it runs")
    environment: str | None = Field(None, description="the world it runs in")
    robot_settings: dict[str, JsonScalar] = Field(
        default_factory=_new_dict,
        description="robot setting -> value, within the template's bounds",
    )
    logic_settings: dict[str, dict[str, JsonScalar]] = Field(
        default_factory=_new_dict,
        description="logic -> its setting -> value, for the logics the capability chose",
    )
    knowledge_sets: list[str] = Field(
        default_factory=_new_list, description="the environment's sets, deep-merged in order"
    )
    knowledge: JsonObject = Field(
        default_factory=_new_dict, description="deep-merged over the knowledge sets"
    )
    goals: list[Goal] = Field(default_factory=_new_list, description="the robot's initial tasks")


class RobotAssignment(StrictModel):
    """Which scenario one robot runs."""

    scenario: str = Field(description="the scenario this robot runs")
    name: str | None = Field(None, description="display name; defaults to the robot id")
    suspended: bool = Field(False, description="leave the robot as it is")
    labels: dict[str, str] = Field(
        default_factory=_new_dict,
        description="groups the robot belongs to (ring: canary, site: hall-a); keys and values "
        "as robot ids: letters, digits, '_', '.', '-'",
    )
    namespace: str | None = Field(
        None,
        description="the robot's ROS 2 namespace, e.g. tb3_01 (or /fleet/tb3_01): relative "
        "mapping names resolve in it; tokens of letters, digits and single '_', not starting "
        "with a digit; none by default",
    )
    ros_domain_id: int | None = Field(
        None,
        ge=0,
        le=MAX_ROS_DOMAIN_ID,
        description=f"{ROS_DOMAIN_DESCRIPTION}; none: its environment's, else ROS's default, 0",
    )


class Wave(StrictModel):
    """One step of a rollout. With `selector`, the robots whose labels match all of it; with
    `percent`, up to that share (cumulative, in robot id order) of those robots, or of the
    fleet; with neither, every robot left."""

    name: str = Field(description="shown in status and plan")
    selector: dict[str, str] = Field(
        default_factory=_new_dict, description="labels a robot must have"
    )
    percent: int | None = Field(None, description="cumulative share, 1 to 100")


def _duration(value: str | float) -> str | float:
    try:
        parse_duration(value) if isinstance(value, str) else checked_seconds(value, str(value))
    except ValueError:
        # Said as what would be right: the message reads "timeout must be <this>, got ...".
        raise ValueError("a duration such as 30m, 2h or 7d (at most 3650d), or seconds") from None
    return value


class Verify(StrictModel):
    """What a wave must show in goal outcomes before the next one starts (Argo Rollouts'
    analysis, counted in goals): its robots' goals ended on the new revision since the wave
    was published, judged against a threshold and/or the robots still on the stable one."""

    min_goals: int = Field(
        1,
        ge=0,
        description="goals (succeeded or failed) the wave's robots must end before a verdict; "
        "0 lets a wave pass on no evidence",
    )
    success_rate: float | None = Field(
        None, ge=0.0, le=1.0, description="succeeded / (succeeded + failed) at least this"
    )
    compare: Literal["stable"] | None = Field(
        None,
        description="stable: no worse than the same scenarios' robots still on the stable "
        "revision over the same window",
    )
    max_drop: float = Field(
        0.1, ge=0.0, le=1.0, description="with compare: how far below the stable rate is allowed"
    )
    critical: list[Annotated[str, Field(pattern=CODE_PATTERN)]] = Field(
        default_factory=_new_list,
        description="failure codes that fail the wave at once, whatever the sample",
    )
    timeout: Annotated[str | float, AfterValidator(_duration)] = Field(
        "10m",
        description="how long after the wave is published its evidence is gathered (30m, 2h; "
        "a number: seconds); too few goals by then is Inconclusive",
    )
    inconclusive: Literal["pause", "fail", "pass"] = Field(
        "pause", description="what Inconclusive does: pause for an operator, fail, or pass"
    )
    dry_run: bool = Field(
        False, description="judge and show the verdict, but gate on health alone (shadow)"
    )

    @model_validator(mode="after")
    def _drop_needs_compare(self) -> Verify:
        if "max_drop" in self.model_fields_set and self.compare is None:
            raise ValueError("max_drop needs compare: stable (the rate it is a drop from)")
        return self

    @property
    def timeout_seconds(self) -> float:
        return (
            self.timeout if isinstance(self.timeout, float | int) else parse_duration(self.timeout)
        )


class RolloutPolicy(StrictModel):
    """How a commit reaches the fleet: wave by wave, each gated by the robots' health."""

    waves: list[Wave] = Field(
        min_length=1, description="in order; the last should take every robot left"
    )
    healthy_after: float = Field(
        30.0, description="seconds running the new request before a robot counts as healthy"
    )
    max_failures: int | str = Field(
        0, description="failed robots a wave tolerates: a count, or a share like '10%'"
    )
    wave_timeout: float = Field(300.0, description="seconds a robot has to become healthy")
    on_failure: Literal["rollback", "halt"] = Field(
        "rollback", description="rollback: the moved robots get the last complete revision"
    )
    paused: bool = Field(False, description="no wave advances until a commit sets it false")
    offline: Literal["skip", "wait", "fail"] = Field(
        "skip",
        description="what a robot offline when its wave is published does to the wave: skip (the "
        "default: a robot on its charger never holds a commit up; the wave goes on without it "
        "and it gets the revision its wave reached when it reconnects, still health-gated), wait "
        "(up to wave_timeout) or fail (it counts as failed at once). A robot that goes dark after "
        "its wave published its request has failed, whatever this says",
    )
    verify: Verify | None = Field(
        None, description="gate each wave on its robots' goal outcomes, not only their health"
    )
    groups: Literal["scenario"] | None = Field(
        None,
        description="scenario: the robots of each scenario move together as a group, as "
        "fleet.yaml's groups do",
    )


class Soak(StrictModel):
    """How long a revision stays on a stage before the next stage gets it, counted in goals."""

    goals: int = Field(
        ge=1,
        description="goals the stage's robots end on the revision after its last wave, judged "
        "as rollout.verify judges a wave, before the next stage gets it",
    )


class Stage(StrictModel):
    """One rung of the promotion ladder (sim, then Gazebo, then the real robots): the robots
    whose scenario runs in one of `environments` (an environment's name or type), or whose
    labels match `selector`. A revision reaches a stage only once verified on the one before."""

    name: str = Field(description="shown in status and plan; `robotconf promote --to` names it")
    environments: list[str] = Field(
        default_factory=_new_list,
        description="environment names or types (GazeboDemo1, Gazebo, Real): the robots whose "
        "scenario runs in one",
    )
    selector: str | None = Field(
        None, description='labels a robot must have, "key=value" (several: "k=v,k2=v2")'
    )
    soak: Soak | None = Field(None, description="goals to end on the stage before the next")


class Fleet(StrictModel):
    """The desired robot assignments."""

    robots: dict[str, RobotAssignment] = Field(
        default_factory=_new_dict, description="robot id -> what it runs"
    )
    allow_empty: bool = Field(False, description="allow a commit that unassigns every robot")
    rollout: RolloutPolicy | None = Field(
        None, description="roll out in health-gated waves; absent: every robot at once"
    )
    groups: dict[str, list[str] | str] = Field(
        default_factory=_new_dict,
        description="robots that work together and move as one: name -> robot ids, or labels "
        '"key=value" (several: "k=v,k2=v2"); a wave never splits a group, and one member '
        "failing fails them all",
    )
    stages: list[Stage] = Field(
        default_factory=_new_list,
        description="the promotion ladder, in order: each stage's robots get a revision only "
        "once it was verified on the stage before (needs rollout:)",
    )
    drift: Literal["warn", "hold"] = Field(
        "warn",
        description="what a robot's reported interfaces not fitting its request does: warn "
        "(deliver, and report the drift) or hold (keep its last good request until they fit)",
    )


# ---------------------------------------------------------------- rule configuration


class RuleConfiguration(StrictModel):
    """`.robotconf.yaml` at the repository root: the severity a lab gives a rule it may tune
    (configurator/ruleconfig.py judges the codes and values)."""

    # YAML reads a bare `off` as false: both mean off.
    rules: dict[str, str | bool] = Field(
        default_factory=_new_dict, description="rule code -> error, warning or off"
    )
