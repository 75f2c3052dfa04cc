"""A robot template and a mapping scheme drafted from a robot's reported interfaces (pure).

Each interface the robot reports gets a mapping name: the catalogue's where one fits (same kind,
same type, the same name once resolved in the robot's namespace), else one derived from its name.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from pydantic import ValidationError

from robotconf.configurator.repository import Repository
from robotconf.configurator.rosnames import (
    UnresolvableName,
    absolute_namespace,
    mapping_name_problem,
    resolve_name,
)
from robotconf.configurator.types import MappingBinding, MappingKind, MappingScheme, RobotTemplate
from robotconf.configurator.types import SettingDefinition as Setting
from robotconf.contract.diagnostics import did_you_mean
from robotconf.contract.interfaces import (
    KIND_OF_MAPPING,
    MAX_INTERFACES,
    Interface,
    InterfaceKind,
    RobotInterfaces,
    same_type,
)
from robotconf.contract.yamlio import document_text

# The ROS graph's own plumbing, which no brain is configured with: a draft leaves it out.
INFRASTRUCTURE_TOPICS = frozenset({"/rosout", "/parameter_events"})
# Every node's parameter services (and, since Jazzy, its type description service).
PARAMETER_SERVICES = frozenset(
    {
        "describe_parameters",
        "get_parameter_types",
        "get_parameters",
        "list_parameters",
        "set_parameters",
        "set_parameters_atomically",
        "get_type_description",
    }
)
# Packages whose interfaces are the graph's management, whatever their names: parameters and
# logs (rcl_interfaces), lifecycle transitions, type descriptions, Nav2's bond heartbeats.
INFRASTRUCTURE_PACKAGES = frozenset(
    {"rcl_interfaces", "lifecycle_msgs", "type_description_interfaces", "bond"}
)
MAPPING_OF_KIND: dict[InterfaceKind, MappingKind] = {
    "topic": "topic",
    "service": "service",
    "action": "action_client",
}
# `pkg/msg/Type` (ROS 2) or `pkg/Type` (ROS 1 and older tools).
_TYPE = re.compile(r"[A-Za-z][A-Za-z0-9_]*/(?:[A-Za-z][A-Za-z0-9_]*/)?[A-Za-z][A-Za-z0-9_]*")
_CAMEL = re.compile(r"(?<=[a-z0-9])(?=[A-Z])")
MAX_DERIVED = 64  # characters of a derived mapping name


class ReportError(ValueError):
    """An interfaces report that cannot be drafted from; the message says why, in one line."""


def report_from(data: dict[str, Any]) -> RobotInterfaces:
    """A parsed interfaces message (the retained topic's JSON, or a file of it) checked: its
    fields, its entries' bounds and their number."""
    try:
        found = RobotInterfaces.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(part) for part in first["loc"]) or "the message"
        more = f" (and {exc.error_count() - 1} more)" if exc.error_count() > 1 else ""
        raise ReportError(f"{where}: {first['msg']}{more}") from None
    count = len(found.topics) + len(found.services) + len(found.actions)
    if count > MAX_INTERFACES:
        raise ReportError(f"it lists {count:,} interfaces, over the bound of {MAX_INTERFACES:,}")
    return found


@dataclass(frozen=True)
class Bound:
    """One mapping name as one mapping scheme of the catalogue binds it."""

    mapping: str
    binding: MappingBinding
    where: str  # `ROS2/gazebo`


@dataclass(frozen=True)
class DraftedMapping:
    """One mapping of the draft and the interface it binds."""

    mapping: str
    kind: InterfaceKind
    reported: str  # the name the robot reports, fully qualified
    type: str
    fits: tuple[str, ...]  # schemes binding this catalogue name alike; empty: a new name
    hint: str = ""  # for a new name: the catalogue's closest names


@dataclass(frozen=True)
class LeftOut:
    """A reported interface the draft does not bind, and why."""

    kind: InterfaceKind
    name: str
    type: str
    reason: str


@dataclass
class Draft:
    template: RobotTemplate
    scheme: MappingScheme
    mappings: list[DraftedMapping]
    infrastructure: int = 0  # interfaces left out as the ROS graph's own plumbing
    left_out: list[LeftOut] = field(default_factory=list)


def catalogue(repo: Repository, first: str | None = None) -> list[Bound]:
    """Every mapping name bound by a mapping scheme of the repository, the schemes of platform
    `first` before the others (their names win when two fit one interface)."""
    order = sorted(repo.platforms, key=lambda name: (name != first, name))
    return [
        Bound(mapping, binding, f"{platform}/{scheme_name}")
        for platform in order
        for scheme_name, scheme in sorted(repo.platforms[platform].schemes.items())
        for mapping, binding in scheme.model.mappings.items()
    ]


def infrastructure_reason(kind: InterfaceKind, entry: Interface) -> str | None:
    """Why an interface is the ROS graph's plumbing rather than the robot's, or None."""
    tokens = entry.name.split("/")
    if any(token.startswith("_") for token in tokens):
        return "hidden (a token starts with '_')"
    if kind == "topic" and entry.name in INFRASTRUCTURE_TOPICS:
        return "the graph's log or parameter events"
    if kind == "service" and tokens[-1] in PARAMETER_SERVICES:
        return "a node's parameter service"
    if entry.type.split("/")[0] in INFRASTRUCTURE_PACKAGES:
        return f"of package {entry.type.split('/')[0]}"
    return None


def written_name(reported: str, namespace: str | None) -> str:
    """The name as a scheme writes it: relative under the robot's namespace, else absolute."""
    if namespace is not None:
        prefix = absolute_namespace(namespace) + "/"
        if reported.startswith(prefix) and len(reported) > len(prefix):
            return reported[len(prefix) :]
    return reported


def unusable(entry: Interface, written: str) -> str | None:
    """Why a reported interface cannot be written into a scheme, or None."""
    if not entry.name.startswith("/"):
        return "is not a fully qualified name (the ROS 2 tools print names from '/')"
    problem = mapping_name_problem(written)
    if problem is not None:
        return problem
    if _TYPE.fullmatch(entry.type) is None:
        return f"type {entry.type!r} is not an interface type like pkg/msg/Type"
    return None


def derive_name(written: str, type_name: str, taken: set[str]) -> str:
    """A snake_case mapping name from the name's last two tokens, not in `taken`: the type's
    name, then a number, is added when it is."""
    tokens = [t for t in written.split("/") if t][-2:]
    base = _snake("_".join(tokens)) or "mapping"
    if base[0].isdigit():
        base = "m_" + base
    base = base[:MAX_DERIVED].rstrip("_")
    candidates = [base, f"{base}_{_snake(type_name.split('/')[-1])}".rstrip("_")]
    for candidate in candidates:
        if candidate not in taken:
            return candidate
    number = 2
    while f"{candidates[-1]}_{number}" in taken:
        number += 1
    return f"{candidates[-1]}_{number}"


def _snake(text: str) -> str:
    lowered = _CAMEL.sub("_", text).lower()
    return re.sub(r"_+", "_", re.sub(r"[^a-z0-9_]", "_", lowered)).strip("_")


def _fitting(bounds: Iterable[Bound], namespace: str | None) -> dict[tuple[str, str], list[Bound]]:
    """(interface kind, fully qualified name) -> the catalogue's bindings resolving to it."""
    table: dict[tuple[str, str], list[Bound]] = {}
    for bound in bounds:
        try:
            resolved = resolve_name(bound.binding.name, namespace)
        except UnresolvableName:
            continue  # `{namespace}/...` fits no robot without a namespace
        table.setdefault((KIND_OF_MAPPING[bound.binding.kind], resolved), []).append(bound)
    return table


def _hint(mapping: str, kind: InterfaceKind, type_name: str, bounds: list[Bound]) -> str:
    """A did-you-mean for a new name: the catalogue's names of the same kind and type first."""
    alike = sorted(
        {
            b.mapping
            for b in bounds
            if KIND_OF_MAPPING[b.binding.kind] == kind and same_type(b.binding.type, type_name)
        }
    )
    if alike:
        names = ", ".join(f"'{name}'" for name in alike[:3])
        return f"; did you mean {names} (same kind and type in the catalogue)?"
    near = did_you_mean(mapping, {b.mapping for b in bounds})
    return near if near.startswith("; did you mean") else ""


def _entries(found: RobotInterfaces) -> list[tuple[InterfaceKind, Interface]]:
    """Each distinct reported interface once, by kind then name; at most MAX_INTERFACES."""
    kinds: tuple[InterfaceKind, ...] = ("topic", "service", "action")
    seen = {(kind, entry.name, entry.type) for kind in kinds for entry in found.of_kind(kind)}
    ordered = sorted(seen, key=lambda e: (kinds.index(e[0]), e[1], e[2]))
    return [(kind, Interface(name=name, type=type_)) for kind, name, type_ in ordered][
        :MAX_INTERFACES
    ]


def draft(
    found: RobotInterfaces,
    bounds: list[Bound],
    namespace: str | None,
    *,
    description: str = "",
    settings: dict[str, Setting] | None = None,
) -> Draft:
    """The template and scheme of a robot that reports `found`, in `namespace` (valid, or None).
    The template lists exactly what the scheme binds; settings are the ones given."""
    table = _fitting(bounds, namespace)
    catalogue_names = {b.mapping for b in bounds}
    taken: set[str] = set()
    result = Draft(RobotTemplate(mappings=[]), MappingScheme(mappings={}), [])
    bindings: dict[str, MappingBinding] = {}
    for kind, entry in _entries(found):
        if infrastructure_reason(kind, entry) is not None:
            result.infrastructure += 1
            continue
        written = written_name(entry.name, namespace)
        why = unusable(entry, written)
        if why is not None:
            result.left_out.append(LeftOut(kind, entry.name, entry.type, why))
            continue
        fits = [
            b for b in table.get((kind, entry.name), []) if same_type(b.binding.type, entry.type)
        ]
        free = [b for b in fits if b.mapping not in taken]
        if free:
            mapping = free[0].mapping
            where = tuple(b.where for b in free if b.mapping == mapping)
            drafted = DraftedMapping(mapping, kind, entry.name, entry.type, where)
        else:
            mapping = derive_name(written, entry.type, taken | catalogue_names)
            hint = _hint(mapping, kind, entry.type, bounds)
            drafted = DraftedMapping(mapping, kind, entry.name, entry.type, (), hint)
        taken.add(mapping)
        bindings[mapping] = MappingBinding(
            kind=MAPPING_OF_KIND[kind], name=written, type=entry.type
        )
        result.mappings.append(drafted)
    result.template = RobotTemplate(
        description=description, mappings=list(bindings), settings=dict(settings or {})
    )
    result.scheme = MappingScheme(description=description, mappings=bindings)
    return result


def _text(schema_ref: str, comment: str, body: dict[str, Any]) -> str:
    """A file with the editor modeline, written by the emitter (contract.yamlio)."""
    return document_text(
        [f"yaml-language-server: $schema={schema_ref}", comment], body, flow_leaves=True
    )


def template_yaml(template: RobotTemplate, schema_ref: str, comment: str) -> str:
    body: dict[str, Any] = {"description": template.description, "mappings": template.mappings}
    if template.settings:
        body["settings"] = {
            name: setting.model_dump(exclude_none=True)
            for name, setting in template.settings.items()
        }
    return _text(schema_ref, comment, body)


def scheme_yaml(scheme: MappingScheme, schema_ref: str, comment: str) -> str:
    mappings = {name: b.model_dump() for name, b in scheme.mappings.items()}
    return _text(schema_ref, comment, {"description": scheme.description, "mappings": mappings})
