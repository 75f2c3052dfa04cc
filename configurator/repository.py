"""The loaded repository: every typed document by kind and name, and where each came from."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Generic, TypeVar

from pydantic import BaseModel

from robotconf.configurator.ruleconfig import IgnoreComment
from robotconf.configurator.types import (
    Action,
    CapabilityConfiguration,
    Environment,
    Fleet,
    MappingScheme,
    PlatformInfo,
    RobotTemplate,
    RuleConfiguration,
    ScenarioConfiguration,
    Task,
)
from robotconf.contract.yamlio import YamlDocument

M = TypeVar("M", bound=BaseModel)


@dataclass(frozen=True)
class Entry(Generic[M]):
    """One typed document and the file it was read from."""

    name: str
    model: M
    doc: YamlDocument

    @property
    def path(self) -> str:
        return self.doc.path


@dataclass
class Platform:
    name: str
    info: Entry[PlatformInfo] | None = None
    templates: dict[str, Entry[RobotTemplate]] = field(default_factory=dict)
    schemes: dict[str, Entry[MappingScheme]] = field(default_factory=dict)


@dataclass
class Repository:
    """What exists (the catalogue) and what is chosen (the configurations) at one revision."""

    # Asking git for the revision costs an import and a process: only rendering needs it.
    revision_of: Callable[[], str] = field(repr=False)
    platforms: dict[str, Platform] = field(default_factory=dict)
    actions: dict[str, Entry[Action]] = field(default_factory=dict)
    tasks: dict[str, Entry[Task]] = field(default_factory=dict)
    environments: dict[str, Entry[Environment]] = field(default_factory=dict)
    capabilities: dict[str, Entry[CapabilityConfiguration]] = field(default_factory=dict)
    scenarios: dict[str, Entry[ScenarioConfiguration]] = field(default_factory=dict)
    fleet: Entry[Fleet] | None = None
    # Files present but unreadable, by kind ("robot-template": {"ROS2/burger"}): references to
    # them are not reported a second time.
    broken: dict[str, set[str]] = field(default_factory=dict)
    files_read: int = 0
    # What the lab tunes (configurator/ruleconfig.py), for judging the findings: the rules
    # themselves never read these.
    rule_configuration: Entry[RuleConfiguration] | None = None
    ignores: dict[str, tuple[IgnoreComment, ...]] = field(default_factory=dict)  # by path

    @cached_property
    def revision(self) -> str:
        """The commit the repository was read from (the work tree: HEAD, `+dirty` if changed)."""
        return self.revision_of()

    def is_broken(self, kind: str, name: str) -> bool:
        return name in self.broken.get(kind, set())

    def platform(self, name: str) -> Platform | None:
        return self.platforms.get(name)
