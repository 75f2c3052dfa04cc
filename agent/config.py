"""agent.yaml (docs/architecture.md#agentyaml): the AgentConfig model, and a loader whose
errors name file:line.

Loading never raises a traceback at the user: every problem becomes one `ConfigError` line.
"""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_core import ErrorDetails

from robotconf.contract.diagnostics import did_you_mean
from robotconf.contract.models import MAX_ROS_DOMAIN_ID, ROBOT_ID_PATTERN, StrictModel
from robotconf.contract.mqtt import MAX_TLS_FILE as MAX_CREDENTIAL_BYTES
from robotconf.contract.mqtt import Connection
from robotconf.contract.trust import Trust, UntrustedFile, check_trusted, read_trusted
from robotconf.contract.typing_errors import error_path, error_text, type_error_text
from robotconf.contract.wire import (
    BROKER_ENV,
    DEFAULT_BROKER,
    DEFAULT_PREFIX,
    RobotDescription,
    parse_broker_url,
    validate_prefix,
)
from robotconf.contract.yamlio import (
    MAX_FILE_BYTES,
    YamlDocument,
    YamlProblem,
    YamlReadError,
    parse_document,
)

COMMAND_EXAMPLE = '[python3, -m, cbs, --config, "{launch_request}"]'


# Values of their own type only (`stop_timeout: "10"`, `insecure: "yes"` are mistakes); paths
# are the exception (`Field(strict=False)`): YAML gives them as text.


class DescriptionConfig(StrictModel):
    """The robot as it describes itself; strict here although the wire type is tolerant."""

    id: str = Field(
        pattern=ROBOT_ID_PATTERN,
        description="the robot id, a topic level: 1-64 of A-Z a-z 0-9 _ . -, starting with a "
        "letter or digit",
    )
    name: str | None = Field(None, description="published as the robot's description")
    recommended_template: str | None = Field(
        None,
        description="published as the robot's description; a request whose capability targets "
        "another template (or none) runs, with a warning in the status",
    )
    platform: str | None = Field(
        None, description="when set, a request for another platform is rejected"
    )

    def to_wire(self) -> RobotDescription:
        return RobotDescription(**self.model_dump())


class RestartConfig(StrictModel):
    """When the brain is started again after it exited, and how soon."""

    policy: Literal["on-failure", "always", "never"] = Field(
        "on-failure", description="on-failure: restart on a non-zero exit"
    )
    max_restarts: int = Field(default=5, ge=0, description="restarts in a row before `failed`")
    backoff_initial: float = Field(
        default=1.0, gt=0, description="seconds before the first restart, doubled per failure"
    )
    backoff_max: float = Field(default=60.0, gt=0, description="the longest delay (s)")
    # A brain that stayed up this long is healthy again: its next crash starts a fresh backoff.
    reset_after: float = Field(
        default=60.0,
        gt=0,
        description="a brain that ran this long starts a fresh backoff when it next crashes (s)",
    )

    @model_validator(mode="after")
    def _ordered(self) -> RestartConfig:
        if self.backoff_initial > self.backoff_max:
            raise ValueError(
                f"backoff_initial ({self.backoff_initial}) is larger than backoff_max "
                f"({self.backoff_max}); make backoff_initial <= backoff_max"
            )
        return self


# Signals whose default action a brain can replace with a handler, and that mean nothing else
# to the agent (SIGTERM stops, SIGKILL and SIGSTOP cannot be caught).
RELOAD_SIGNALS = ("SIGHUP", "SIGUSR1", "SIGUSR2")


class ReloadConfig(StrictModel):
    """How the brain is told to re-read its request when only reloadable parts changed."""

    signal: Literal["SIGHUP", "SIGUSR1", "SIGUSR2"] = Field(
        description="a new request whose restart_digest equals the running brain's is written "
        "over the request file and this signal sent to the brain's process group, instead of a "
        "restart"
    )

    @field_validator("signal", mode="before")
    @classmethod
    def _catchable(cls, value: Any) -> Any:
        if value not in RELOAD_SIGNALS:
            near = did_you_mean(str(value).upper(), RELOAD_SIGNALS)
            raise ValueError(
                f"{value!r} is not a signal a brain catches to reload; use one of "
                f"{', '.join(RELOAD_SIGNALS)}, e.g. reload: {{signal: SIGHUP}}"
                + (near if "did you mean" in near else "")
            )
        return value


class TlsConfig(StrictModel):
    """The broker connection's TLS (only with mqtts://)."""

    ca_file: Path | None = Field(
        None, strict=False, description="the CA to trust; none: the system's CAs"
    )
    cert_file: Path | None = Field(None, strict=False, description="the client certificate")
    key_file: Path | None = Field(None, strict=False, description="the client certificate's key")
    insecure: bool = Field(False, description="skip the server certificate check: lab benches only")


class LogConfig(StrictModel):
    """brain.log in the workdir, rotated (copied, then truncated) past a size."""

    max_bytes: int = Field(
        default=10 * 1024 * 1024, ge=4096, description="rotate past this size (checked every 2 s)"
    )
    backups: int = Field(default=3, ge=0, description="rotated copies kept: brain.log.1, ...")


class GoalsConfig(StrictModel):
    """Relaying the brain's goals, vitals and events (agent/relay.py): the bounds a brain
    cannot pass, however it writes to its socket."""

    stale_after: float = Field(
        default=300.0,
        gt=0,
        description="seconds a goal underway may go without progress before it is stale "
        "(once, with an outcome record; it may still end later)",
    )
    lines_per_second: float = Field(
        default=50.0,
        gt=0,
        le=10_000,
        description="lines a brain may write a second (twice that in a burst); more are "
        "refused and counted in the summary's dropped",
    )
    records_per_second: float = Field(
        default=10.0,
        gt=0,
        le=10_000,
        description="outcome records a second (twice that in a burst); more are counted in "
        "dropped, not sent",
    )


INTERFACES_EXAMPLE = "interfaces: {interval: 30}"
# The default source runs three `ros2 ... list -t` (each a Python start, and the first one
# may start the ROS 2 daemon): seconds, not milliseconds, on a small robot computer.
DEFAULT_INTERFACES_TIMEOUT = 20.0


class InterfacesConfig(StrictModel):
    """Reporting the robot's ROS interfaces (agent/interfaces.py): on when the section is
    there. `command` replaces `ros2 topic/service/action list -t` by a program printing JSON."""

    interval: float = Field(gt=0, description="seconds from the end of one reading to the next")
    command: list[str] | None = Field(
        None,
        description='a program (argument list) printing one JSON object {"topics": [{"name", '
        '"type"}...], "services": [...], "actions": [...]}; none: ros2 on the brain\'s PATH',
    )
    timeout: float = Field(
        default=DEFAULT_INTERFACES_TIMEOUT,
        gt=0,
        description="seconds each command may take before its process group is killed",
    )

    @field_validator("command", mode="before")
    @classmethod
    def _command_is_a_list(cls, value: Any) -> Any:
        if isinstance(value, str):
            raise ValueError(
                "must be an argument list, never a shell string; "
                "e.g. command: [/opt/robot/bin/list-interfaces, --json]"
            )
        return value

    @field_validator("command")
    @classmethod
    def _command(cls, value: list[str] | None) -> list[str] | None:
        if value is not None and (not value or not value[0].strip()):
            raise ValueError(
                "is empty; give a program that prints the interfaces as "
                "JSON, e.g. command: [/opt/robot/bin/list-interfaces, --json], or leave it "
                "out to run `ros2 ... list -t`"
            )
        return value


# ---------------------------------------------------------------- the brain's environment

# POSIX's portable names: what every shell and `os.environ` takes as a variable name.
_ENV_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
# The variables the agent sets for its brain (ROBOTCONF_LAUNCH_REQUEST, ..._ROBOT_ID, ..._DIGEST,
# and any later one): agent.yaml must not override what tells the brain its request.
AGENT_ENV_PREFIX = "ROBOTCONF_"
# Linux refuses one environment string longer than 128 KiB at exec time: the brain would never
# start, and only the robot's log would say why. Far below, and plenty for any setting.
MAX_ENV_VALUE = 32 * 1024
# ROS_DOMAIN_ID is checked against MAX_ROS_DOMAIN_ID (contract/models.py) so a typo is an
# agent.yaml error at start-up, not a brain restarting until it gives up.


def _env_name(name: str) -> str:
    if _ENV_NAME.fullmatch(name) is None:
        raise ValueError(
            "is not an environment variable name: letters, digits and '_', not starting with "
            "a digit (e.g. ROS_DOMAIN_ID)"
        )
    if name.upper().startswith(AGENT_ENV_PREFIX):
        raise ValueError(
            f"is the agent's own: it sets {AGENT_ENV_PREFIX}* for the brain (the request's file, "
            "the robot id, the digest); choose another name"
        )
    return name


def _env_text(value: Any) -> Any:
    # The value itself is never echoed: env may hold secrets (a token, a password).
    if isinstance(value, (bool, int, float)):
        raise ValueError('values are text: quote it, e.g. ROS_DOMAIN_ID: "7"')
    return value


def _env_value(value: str) -> str:
    if "\0" in value:
        raise ValueError("has a NUL character, which no environment variable can hold")
    if len(value) > MAX_ENV_VALUE:
        raise ValueError(f"is longer than {MAX_ENV_VALUE} characters")
    return value


EnvName = Annotated[str, AfterValidator(_env_name)]
EnvValue = Annotated[str, BeforeValidator(_env_text), AfterValidator(_env_value)]


def _domain_id_problem(value: str) -> str | None:
    if not (value.isascii() and value.isdigit()) or int(value) > MAX_ROS_DOMAIN_ID:
        return (
            f"ROS_DOMAIN_ID {value!r} is not a domain id: an integer from 0 to "
            f'{MAX_ROS_DOMAIN_ID} written as text, e.g. ROS_DOMAIN_ID: "7" (DDS derives its '
            "ports from it; higher ones do not exist)"
        )
    return None


# Five minutes: a manoeuvre, a docking, a tray delivered; long enough for a task's safe point,
# short enough that a brain that forgets its hold file does not keep a fix from the robot long.
DEFAULT_MAX_DEFER = 300.0
MAX_MAX_DEFER = 86_400.0  # a day: beyond that a hold is a robot out of the fleet, not a task
# Two minutes: a ROS 2 brain bringing up Nav2 and its maps takes tens of seconds on a small
# computer; one that has not said ready by then is wedged, and a restart is the answer.
DEFAULT_READY_TIMEOUT = 120.0


class AgentConfig(StrictModel):
    """One robot's agent: its broker, its robot, its brain. Relative paths are relative to the
    folder of agent.yaml."""

    broker: str = Field(
        default_factory=lambda: os.environ.get(BROKER_ENV, DEFAULT_BROKER),
        description=f"mqtt://host[:port] or mqtts://host[:port]; default: ${BROKER_ENV}, else "
        f"{DEFAULT_BROKER}",
    )
    prefix: str = Field(DEFAULT_PREFIX, description="the topic prefix")
    description: DescriptionConfig
    command: list[str] = Field(
        description="the brain's argument list (never a shell string); {launch_request} "
        "becomes the request file's path, as one argument"
    )
    workdir: Path = Field(
        strict=False,
        description="where launch-request.json (mode 0600), brain.log, brain.pid, brain.sock "
        "and agent.seq live; created if missing, must be writable",
    )
    stop_timeout: float = Field(
        default=10.0, gt=0, description="seconds from SIGTERM (to the brain's group) to SIGKILL"
    )
    startsecs: float = Field(
        default=1.0, ge=0, description="seconds the brain must stay up to count as running"
    )
    ready_timeout: float = Field(
        default=DEFAULT_READY_TIMEOUT,
        ge=0,
        description="seconds a brain that said hello on its socket has to say ready; past "
        "them it is stopped and counts as a failed start (the restart policy applies); 0: it "
        "may take as long as it likes (starting until then)",
    )
    max_defer: float = Field(
        default=DEFAULT_MAX_DEFER,
        ge=0,
        le=MAX_MAX_DEFER,
        description="seconds a stop, restart or reload waits at most while the brain's hold "
        "file exists; 0: the hold file is ignored",
    )
    restart: RestartConfig = Field(default_factory=lambda: RestartConfig())
    keepalive: int = Field(
        default=30,
        ge=5,
        le=3600,
        description="MQTT keepalive (s): how soon the broker notices a dead agent",
    )
    log: LogConfig = Field(default_factory=lambda: LogConfig())
    reload: ReloadConfig | None = Field(
        None, description="absent: every new request restarts the brain"
    )
    username: str | None = Field(None, description="the broker login")
    password_file: Path | None = Field(
        None, strict=False, description="the broker password, read from this file"
    )
    tls: TlsConfig | None = None
    public_key: Path | None = Field(
        None,
        strict=False,
        description="the reconciler's Ed25519 public key (robotconf keys generate): when set, "
        "unsigned, tampered or wrongly signed requests are rejected, and so is a signed one "
        "older than the newest this robot accepted (unless it runs it)",
    )
    # Never logged or published, as it may hold secrets; so it stays out of the model's repr
    # too. ROS_DOMAIN_ID is checked on reading (`_env_problems`), located at its own line.
    env: dict[EnvName, EnvValue] = Field(
        default_factory=dict,
        repr=False,
        description="extra environment of the brain only (ROS_DOMAIN_ID, RMW_IMPLEMENTATION): "
        "values are text; the agent's own ROBOTCONF_* are refused",
    )
    interfaces: InterfacesConfig | None = Field(
        None,
        description="report the robot's ROS interfaces; absent: none reported (unknown)",
    )
    goals: GoalsConfig = Field(
        default_factory=lambda: GoalsConfig(),
        description="the bounds of relaying the brain's goals, vitals and events",
    )

    @field_validator("broker")
    @classmethod
    def _broker(cls, value: str) -> str:
        parse_broker_url(value)
        return value

    @field_validator("prefix")
    @classmethod
    def _prefix(cls, value: str) -> str:
        return validate_prefix(value)

    @field_validator("command", mode="before")
    @classmethod
    def _command_is_a_list(cls, value: Any) -> Any:
        if isinstance(value, str):
            raise ValueError(
                f"command must be an argument list, never a shell string; e.g. {COMMAND_EXAMPLE}"
            )
        return value

    @field_validator("command")
    @classmethod
    def _command(cls, value: list[str]) -> list[str]:
        if not value or not value[0].strip():
            raise ValueError(
                f"command is empty; give the brain service's argument list, e.g. {COMMAND_EXAMPLE}"
            )
        return value

    @field_validator("reload", mode="before")
    @classmethod
    def _reload_is_a_mapping(cls, value: Any) -> Any:
        if isinstance(value, str):
            name = value if value in RELOAD_SIGNALS else "SIGHUP"
            raise ValueError(
                f"reload is a mapping of its settings, e.g. reload: {{signal: {name}}}"
            )
        return value

    @field_validator("interfaces", mode="before")
    @classmethod
    def _interfaces_is_a_mapping(cls, value: Any) -> Any:
        if value is not None and not isinstance(value, dict):
            raise ValueError(f"interfaces is a mapping of its settings, e.g. {INTERFACES_EXAMPLE}")
        return value

    @model_validator(mode="after")
    def _credentials(self) -> AgentConfig:
        if self.password_file is not None and not self.username:
            raise ValueError("password_file is set but username is not; add username: ROBOT_USER")
        if self.tls is not None and not parse_broker_url(self.broker).tls:
            raise ValueError(
                f"tls options need a TLS broker URL, but broker is {self.broker}; "
                "use mqtts://host:8883"
            )
        if self.tls is not None and self.tls.key_file and not self.tls.cert_file:
            raise ValueError(
                "tls.key_file is set without tls.cert_file; add the client certificate"
            )
        return self

    @property
    def robot_id(self) -> str:
        return self.description.id

    def connection(self) -> Connection:
        tls = self.tls or TlsConfig()
        return Connection(
            url=self.broker,
            username=self.username,
            password_file=self.password_file,
            ca_file=tls.ca_file,
            cert_file=tls.cert_file,
            key_file=tls.key_file,
            insecure=tls.insecure,
        )

    def resolved(self, base: Path) -> AgentConfig:
        """Paths relative to the configuration file's folder, as a person reading it expects."""

        def rel(path: Path | None) -> Path | None:
            return None if path is None else (base / path.expanduser()).absolute()

        update: dict[str, Any] = {
            "workdir": rel(self.workdir),
            "password_file": rel(self.password_file),
            "public_key": rel(self.public_key),
        }
        if self.tls is not None:
            update["tls"] = self.tls.model_copy(
                update={
                    "ca_file": rel(self.tls.ca_file),
                    "cert_file": rel(self.tls.cert_file),
                    "key_file": rel(self.tls.key_file),
                }
            )
        return self.model_copy(update=update)


@dataclass(frozen=True)
class ConfigError:
    """One problem: where it is and what would be right."""

    file: str
    line: int | None
    message: str

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}" if self.line else self.file
        return f"{where}: {self.message}"


class ConfigInvalid(Exception):
    def __init__(self, errors: Sequence[ConfigError]) -> None:
        super().__init__("\n".join(str(e) for e in errors))
        self.errors = list(errors)


Loc = tuple[str | int, ...]


_SECTIONS: dict[Loc, type[BaseModel]] = {
    (): AgentConfig,
    ("description",): DescriptionConfig,
    ("restart",): RestartConfig,
    ("tls",): TlsConfig,
    ("log",): LogConfig,
    ("reload",): ReloadConfig,
    ("interfaces",): InterfacesConfig,
    ("goals",): GoalsConfig,
}

_HINTS: dict[str, str] = {
    "description": "e.g. description: {id: tb3-01, name: Delivery bot}",
    "id": "the robot id, e.g. tb3-01",
    "command": f"e.g. command: {COMMAND_EXAMPLE}",
    "workdir": "e.g. workdir: /var/lib/robotconf/tb3-01",
    "signal": "e.g. reload: {signal: SIGHUP}",
    "interval": f"e.g. {INTERFACES_EXAMPLE} (seconds between readings)",
}


def _explain(error: ErrorDetails) -> tuple[Loc, str]:
    loc: Loc = tuple(error["loc"])
    if loc[-1:] == ("[key]",):  # a mapping's key was refused: report it at the key
        loc = loc[:-1]
    kind = error["type"]
    where = error_path(loc)
    if kind == "extra_forbidden":
        parent, key = loc[:-1], str(loc[-1])
        model = _SECTIONS.get(parent)
        allowed = sorted(model.model_fields) if model else []
        near = did_you_mean(key, allowed)
        hint = near[2:] if "did you mean" in near else f"allowed here: {', '.join(allowed)}"
        return loc, f"unknown key '{where}'; {hint}"
    if kind == "missing":
        hint = _HINTS.get(str(loc[-1]), "")
        return loc, f"'{where}' is required" + (f"; {hint}" if hint else "")
    if kind == "string_pattern_mismatch" and loc[-1:] == ("id",):
        return loc, (
            f"robot id {error['input']!r} is not topic-safe; use 1-64 letters, digits, "
            "'_', '.' or '-', starting with a letter or digit (e.g. tb3-01)"
        )
    if kind == "literal_error":
        return loc, f"{where}: {error['input']!r} is not allowed; {error['msg'].lower()}"
    message = error_text(error)
    if kind == "value_error":
        # Our own messages usually name the field already ("broker URL ... must ...").
        if loc == () or str(loc[-1]) in message.split()[:3]:
            return loc, message
        return loc, f"{where}: {message}"
    if loc[:1] == ("env",):
        return loc, f"{where}: {message}"  # never the value: env may hold secrets
    natural = type_error_text(error)
    if natural is not None:
        return loc, f"{where} {natural}"
    return loc, f"{where}: {message} (got {error.get('input')!r})"


def _env_problems(config: AgentConfig) -> Iterator[tuple[Loc, str]]:
    """What the ROS 2 variables of `env` must be (the rest is any text)."""
    domain = config.env.get("ROS_DOMAIN_ID")
    problem = None if domain is None else _domain_id_problem(domain)
    if problem is not None:
        yield ("env", "ROS_DOMAIN_ID"), f"env: {problem}"


def _check_environment(config: AgentConfig, prepare: bool) -> Iterator[tuple[Loc, str]]:
    """What only the machine can tell: files readable, the work directory writable (made
    when `prepare`; only looked at otherwise)."""
    problem = _workdir_problem(config.workdir) if prepare else _workdir_unusable(config.workdir)
    if problem:
        yield (
            ("workdir",),
            (
                f"workdir {config.workdir} is not usable ({problem}); "
                "choose a directory the agent's user can create and write"
            ),
        )
    if config.public_key is not None:
        from robotconf.contract.signing import SigningKeyError, load_public_key

        try:
            load_public_key(config.public_key)
        except SigningKeyError as exc:
            yield ("public_key",), f"public_key: {exc}"
    yield from _file_problems(config)


def _file_problems(config: AgentConfig) -> Iterator[tuple[Loc, str]]:
    """Each file agent.yaml names, judged as it will be read (contract/trust.py): readable,
    the agent's (or root's), changed by nobody else, a secret read by nobody else."""
    files: list[tuple[Loc, Path | None, Trust]] = [
        (("password_file",), config.password_file, Trust.SECRET)
    ]
    if config.tls is not None:
        key_in_cert = config.tls.key_file is None  # then the certificate file holds the key
        files += [
            (("tls", "ca_file"), config.tls.ca_file, Trust.CONFIG),
            (
                ("tls", "cert_file"),
                config.tls.cert_file,
                Trust.SECRET if key_in_cert else Trust.CONFIG,
            ),
            (("tls", "key_file"), config.tls.key_file, Trust.SECRET),
        ]
    for loc, path, kind in files:
        if path is None:
            continue
        try:
            check_trusted(path, kind, MAX_CREDENTIAL_BYTES)
        except UntrustedFile as exc:
            yield loc, f"{error_path(loc)}: {path} {exc}"
        except OSError as exc:
            reason = exc.strerror or str(exc)
            yield loc, f"{error_path(loc)}: cannot read {path} ({reason}); give a readable file"


def _workdir_unusable(path: Path) -> str | None:
    """Why the agent could not make or use `path`, judged without changing anything."""
    existing = path
    while not existing.exists():
        if existing.parent == existing:
            break
        existing = existing.parent
    if existing.exists() and not existing.is_dir():
        return f"{existing} is not a directory"
    if not os.access(existing, os.W_OK | os.X_OK):
        return f"{existing} is not writable"
    return None


def _workdir_problem(path: Path) -> str | None:
    try:
        path.mkdir(mode=0o700, parents=True, exist_ok=True)
        # The request may carry a lab's knowledge and goals: only the agent's user reads it.
        path.chmod(0o700)
        # A real write, because permission bits say nothing when running as root.
        with tempfile.NamedTemporaryFile(dir=path, prefix=".probe-"):
            pass
    except OSError as exc:
        return exc.strerror or str(exc)
    return None


def parse_config(
    text: str, filename: str, base: Path | None = None, *, prepare: bool = True
) -> AgentConfig:
    """Validate agent.yaml text; raises ConfigInvalid listing every problem with its line."""
    # The repository's strict reader: duplicate keys, aliases, tabs refused, positions kept.
    try:
        doc = parse_document(filename, text.encode("utf-8"))
    except YamlReadError as exc:
        raise ConfigInvalid([_yaml_error(filename, p) for p in exc.problems]) from None
    try:
        config = AgentConfig.model_validate(doc.data)
    except ValidationError as exc:
        raise ConfigInvalid(_errors(filename, doc, (_explain(e) for e in exc.errors()))) from None
    if base is not None:
        config = config.resolved(base)
    problems = [*_env_problems(config), *_check_environment(config, prepare)]
    if problems:
        raise ConfigInvalid(_errors(filename, doc, problems))
    return config


def _yaml_error(filename: str, problem: YamlProblem) -> ConfigError:
    message = problem.message
    if problem.code == "RC003":
        message = "not valid YAML: " + message.removeprefix("YAML syntax error: ")
    elif problem.code == "RC007" and "top of the file" in message:
        message = "must be a mapping of agent settings (broker, description, command, workdir...)"
    return ConfigError(filename, problem.line, message)


def _errors(
    filename: str, doc: YamlDocument, found: Iterable[tuple[Loc, str]]
) -> list[ConfigError]:
    out = [ConfigError(filename, doc.locate(loc)[0], message) for loc, message in found]
    return sorted(out, key=lambda e: (e.line or 0, e.message))


def load_config(path: Path, *, prepare: bool = True) -> AgentConfig:
    """`prepare=False` (`--check`) changes nothing on disk: the work directory is not made."""
    try:
        # Whoever may change agent.yaml decides what the robot runs: checked as ssh would.
        text = read_trusted(path, Trust.CONFIG, MAX_FILE_BYTES).decode("utf-8")
    except UntrustedFile as exc:
        raise ConfigInvalid([ConfigError(str(path), None, str(exc))]) from None
    except (OSError, UnicodeDecodeError) as exc:
        reason = (exc.strerror or str(exc)) if isinstance(exc, OSError) else "not UTF-8 text"
        raise ConfigInvalid([ConfigError(str(path), None, f"cannot read: {reason}")]) from None
    return parse_config(text, str(path), base=path.parent.absolute(), prepare=prepare)


def with_broker(config: AgentConfig, url: str) -> AgentConfig:
    """The `--broker` override, validated like the file's value."""
    try:
        validated = AgentConfig.model_validate({**config.model_dump(), "broker": url})
    except ValidationError as exc:
        messages = [_explain(e)[1] for e in exc.errors()]
        raise ConfigInvalid([ConfigError("--broker", None, m) for m in messages]) from None
    return validated
