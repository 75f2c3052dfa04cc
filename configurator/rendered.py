"""A robot's launch request as rendering keeps it: its own few values and its digests, the
scenario's content shared with the scenario's other robots and serialised once for them all.

10,000 robots are 10,000 small records, not 10,000 copies of their scenario: a request's bytes
and model are made when asked for (`payload`, `model`), from the scenario's bytes with the
robot's values written into them; the digests are those of the request serialised whole.
"""

from __future__ import annotations

import functools
import hashlib
import secrets
from collections.abc import ItemsView, Iterator, Mapping, MutableMapping
from json.encoder import encode_basestring
from typing import Any

from robotconf.configurator.rosnames import resolve_in
from robotconf.configurator.types import MappingBinding
from robotconf.contract.launch import (
    LaunchCapability,
    LaunchRequest,
    LaunchScenario,
    canonical_json,
    digest_content,
    restart_content_of,
)

# The bytes between the slots, and each slot's index in a robot's values (`_values`).
_Template = tuple[tuple[bytes, ...], tuple[int, ...]]
# The robot's own values, written into its scenario's bytes: the mapping names it resolves
# are its namespace in front of text of the scenario's, so the namespace is all they need.
_SLOT_NAMES = (
    "robot_id",
    "robot_name",
    "namespace",
    "ros_domain_id",
    "revision",
    "digest",
    "restart_digest",
)
_DOMAIN = "ros_domain_id"
# Slots written as JSON numbers, not inside a string: cut with their quotes, as nested ones.
_RAW = frozenset({_DOMAIN})
_SCENARIO = "scenario"
_CAPABILITY = "capability"
_MAPPINGS = "mappings"
# Slots a template is nested at (a whole JSON string replaced by an object), not values.
_NESTED = {_SCENARIO: -1, _CAPABILITY: -2, _MAPPINGS: -3}
# What every slot starts with: text of this process's own that a commit cannot know to
# contain (a commit that held the marks one by one would make a scenario cost a build per
# mark tried); should a scenario contain it anyway, the next mark is tried.
_TOKEN = secrets.token_hex(8)


def _prefix(mark: int) -> str:
    return f"\x00robotconf{_TOKEN}.{mark}:"


class ScenarioRequests:
    """The requests of one scenario's robots: the scenario serialised once with each robot's
    own values left as slots (its id, name, namespace, domain, revision and digests). A
    robot's digests hash its values between those bytes, its payload joins them: the same
    bytes as its whole request serialised, at a fraction of the cost. `ros_domain_id`: the
    domain of the robots that name none (their scenario's environment's), or None."""

    __slots__ = ("_templates", "ros_domain_id", "scenario")

    def __init__(self, scenario: LaunchScenario, ros_domain_id: int | None = None) -> None:
        self.scenario = scenario
        self.ros_domain_id = ros_domain_id
        # (with a namespace, with a domain) -> the templates of the digest content, restart
        # content, payload
        self._templates: dict[tuple[bool, bool], tuple[_Template, _Template, _Template]] = {}

    def request(
        self,
        robot_id: str,
        robot_name: str,
        revision: str,
        namespace: str | None,
        ros_domain_id: int | None = None,
    ) -> RenderedRequest:
        """The robot's request; `namespace` absolute, or None; `ros_domain_id` the robot's
        own (None: the scenario's default). Raises rosnames.UnresolvableName when a mapping
        name needs a namespace and the robot has none."""
        domain = self.ros_domain_id if ros_domain_id is None else ros_domain_id
        content, restart, _ = self._templates_for(namespace is not None, domain is not None)
        values = _values(robot_id, robot_name, namespace, domain)
        return RenderedRequest(
            self,
            robot_id,
            robot_name,
            revision,
            namespace,
            domain,
            _hash(content, values),
            _hash(restart, values),
        )

    def payload(self, request: RenderedRequest) -> bytes:
        """The canonical bytes published on the robot's launch topic, unsigned."""
        domain = request.ros_domain_id
        template = self._templates_for(request.namespace is not None, domain is not None)[2]
        values = _values(
            request.robot_id,
            request.robot_name,
            request.namespace,
            domain,
            request.revision,
            request.digest,
            request.restart_digest,
        )
        return _join(template, values)

    def resolved(self, namespace: str | None) -> LaunchScenario:
        """The scenario with its mapping names resolved in `namespace` (fully qualified)."""
        capability = self.scenario.capability
        mappings = {
            key: _renamed(binding, resolve_in(binding.name, namespace))
            for key, binding in capability.mappings.items()
        }
        return self.scenario.model_copy(
            update={"capability": capability.model_copy(update={"mappings": mappings})}
        )

    def _templates_for(
        self, with_namespace: bool, with_domain: bool
    ) -> tuple[_Template, _Template, _Template]:
        key = (with_namespace, with_domain)
        found = self._templates.get(key)
        if found is None:
            mark = 0
            while (found := self._make(with_namespace, with_domain, mark)) is None:
                mark += 1
            self._templates[key] = found
        return found

    def _make(
        self, with_namespace: bool, with_domain: bool, mark: int
    ) -> tuple[_Template, _Template, _Template] | None:
        """The templates with slots `mark` names; None when text of the scenario contains
        that mark (a slot must be found where the robot's value goes, and nowhere else).

        Each part is serialised once: the scenario with its capability as a slot, the
        capability with its mappings as a slot, the mappings with their names resolved in
        the namespace's slot (those two shared by a capability's scenarios:
        `_capability_templates`); the request around the scenario, the restart content around
        the capability (both the same for every scenario: `_around`)."""
        capability = _capability_templates(
            self.scenario.capability, with_namespace, with_domain, mark
        )
        if capability is None:
            return None
        around_capability, restart = capability
        prefix = _prefix(mark)
        body = self.scenario.model_dump(mode="json", exclude={_CAPABILITY})
        body[_CAPABILITY] = f"{prefix}{_CAPABILITY}\x00"
        around_scenario = canonical_json(body)
        marker = _inner(prefix)
        if around_scenario.count(marker) != 1:
            return None
        scenario = _nest(_template(around_scenario, marker), _CAPABILITY, around_capability)
        content, _, payload = _around(with_namespace, with_domain, mark)
        return _shared(
            _nest(content, _SCENARIO, scenario), restart, _nest(payload, _SCENARIO, scenario)
        )


# Capability name -> its templates, shared by the scenarios of a capability while it stays the
# same (many scenarios use one capability); bounded, and checked equal before each use.
_CAPABILITIES: dict[tuple[str, bool, bool, int], tuple[LaunchCapability, _Template, _Template]] = {}
_MAX_CAPABILITIES = 4096


def _capability_templates(
    capability: LaunchCapability, with_namespace: bool, with_domain: bool, mark: int
) -> tuple[_Template, _Template] | None:
    """The capability with its mapping names resolved in the namespace's slot, and the
    restart content around it; None when its text contains the mark."""
    key = (capability.name, with_namespace, with_domain, mark)
    found = _CAPABILITIES.get(key)
    if found is not None and found[0] == capability:
        return found[1], found[2]
    prefix = _prefix(mark)
    in_namespace = f"{prefix}namespace\x00" if with_namespace else None
    outer = capability.model_dump(mode="json")
    bindings = outer[_MAPPINGS]
    for binding in bindings.values():
        binding["name"] = resolve_in(binding["name"], in_namespace)
    mappings = canonical_json(bindings)
    outer[_MAPPINGS] = f"{prefix}{_MAPPINGS}\x00"
    around_mappings = canonical_json(outer)
    marker = _inner(prefix)
    names = [b.name for b in capability.mappings.values()]
    namespaced = sum(resolve_in(name, "") != name for name in names)
    if around_mappings.count(marker) != 1 or mappings.count(marker) != (
        namespaced if with_namespace else 0
    ):
        return None
    template = _nest(_template(around_mappings, marker), _MAPPINGS, _template(mappings, marker))
    restart = _nest(_around(with_namespace, with_domain, mark)[1], _CAPABILITY, template)
    if len(_CAPABILITIES) >= _MAX_CAPABILITIES:
        _CAPABILITIES.clear()
    _CAPABILITIES[key] = (capability, template, restart)
    return template, restart


@functools.cache
def _around(
    with_namespace: bool, with_domain: bool, mark: int
) -> tuple[_Template, _Template, _Template]:
    """The digest content, restart content and payload around the scenario (or capability):
    the same for every scenario, since what is not the robot's own there is constant."""
    prefix = _prefix(mark)
    slot = {name: f"{prefix}{name}\x00" for name in (*_SLOT_NAMES, *_NESTED)}
    probe = LaunchRequest.model_construct(  # type: ignore[call-arg]  # no scenario: left out
        robot_id=slot["robot_id"],
        robot_name=slot["robot_name"],
        revision=slot["revision"],
        digest=slot["digest"],
        restart_digest=slot["restart_digest"],
        namespace=slot["namespace"] if with_namespace else None,
        # A number: its slot (text) is written over it where the model writes it.
        ros_domain_id=0 if with_domain else None,
    )
    content = digest_content(probe, without={_SCENARIO})
    payload = probe.wire(without={_SCENARIO})
    content[_SCENARIO] = payload[_SCENARIO] = slot[_SCENARIO]
    for written in (content, payload):
        if _DOMAIN in written:
            written[_DOMAIN] = slot[_DOMAIN]
    restart = restart_content_of(
        slot[_CAPABILITY], probe.namespace, slot[_DOMAIN] if with_domain else None
    )
    marker = _inner(prefix)
    return (
        _template(canonical_json(content), marker),
        _template(canonical_json(restart), marker),
        _template(canonical_json(payload), marker),
    )


class RenderedRequest:
    """One robot's launch request: its own values and digests; the rest is its scenario's."""

    __slots__ = (
        "digest",
        "namespace",
        "restart_digest",
        "revision",
        "robot_id",
        "robot_name",
        "ros_domain_id",
        "scenario_requests",
    )

    def __init__(
        self,
        scenario_requests: ScenarioRequests,
        robot_id: str,
        robot_name: str,
        revision: str,
        namespace: str | None,
        ros_domain_id: int | None,
        digest: str,
        restart_digest: str,
    ) -> None:
        self.scenario_requests = scenario_requests
        self.robot_id = robot_id
        self.robot_name = robot_name
        self.revision = revision
        self.namespace = namespace
        self.ros_domain_id = ros_domain_id
        self.digest = digest
        self.restart_digest = restart_digest

    @property
    def scenario_name(self) -> str:
        return self.scenario_requests.scenario.name

    @property
    def capability_name(self) -> str:
        return self.scenario_requests.scenario.capability.name

    @property
    def robot_template(self) -> str | None:
        return self.scenario_requests.scenario.capability.robot_template

    def with_revision(self, revision: str) -> RenderedRequest:
        """The same request rendered from another commit (the digests do not cover it)."""
        return RenderedRequest(
            self.scenario_requests,
            self.robot_id,
            self.robot_name,
            revision,
            self.namespace,
            self.ros_domain_id,
            self.digest,
            self.restart_digest,
        )

    def payload(self) -> bytes:
        """The canonical bytes published on the launch topic (unsigned)."""
        return self.scenario_requests.payload(self)

    def model(self) -> LaunchRequest:
        """The request as the agent reads it: for signing, planning and showing."""
        return LaunchRequest.model_construct(
            robot_id=self.robot_id,
            robot_name=self.robot_name,
            revision=self.revision,
            digest=self.digest,
            restart_digest=self.restart_digest,
            namespace=self.namespace,
            ros_domain_id=self.ros_domain_id,
            scenario=self.scenario_requests.resolved(self.namespace),
        )

    def content(self) -> dict[str, Any]:
        """What the digest covers (launch.digest_content)."""
        return self.model().content()

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RenderedRequest):
            return NotImplemented
        return self.revision == other.revision and self.payload() == other.payload()

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"RenderedRequest({self.robot_id!r}, {self.scenario_name!r}, {self.digest[:15]}…)"


class FleetRequests(MutableMapping[str, RenderedRequest]):
    """Every robot's request of one build, each stamped with the build's revision as it is
    read. A robot whose request did not change keeps the one an earlier build rendered, with
    that build's revision, until it is read here: a commit then costs what it changes, not a
    new request for each of 10,000 robots (a revision is not covered by the digests, and an
    unchanged request is never published again unless its robot lost it)."""

    __slots__ = ("_digests", "_kept", "revision")

    def __init__(self, revision: str, kept: Mapping[str, RenderedRequest] | None = None) -> None:
        self.revision = revision
        self._kept: dict[str, RenderedRequest] = dict(kept or {})
        self._digests: dict[str, str] | None = None

    def __getitem__(self, robot_id: str) -> RenderedRequest:
        request = self._kept[robot_id]
        if request.revision != self.revision:
            request = self._kept[robot_id] = request.with_revision(self.revision)
        return request

    def __setitem__(self, robot_id: str, request: RenderedRequest) -> None:
        self._kept[robot_id] = request
        self._digests = None

    def __delitem__(self, robot_id: str) -> None:
        del self._kept[robot_id]
        self._digests = None

    def __iter__(self) -> Iterator[str]:
        return iter(self._kept)

    def __len__(self) -> int:
        return len(self._kept)

    def __contains__(self, robot_id: object) -> bool:
        return robot_id in self._kept

    def digests(self) -> Mapping[str, str]:
        """robot -> its request's digest, without stamping any (worked out once)."""
        if self._digests is None:
            self._digests = {robot_id: r.digest for robot_id, r in self._kept.items()}
        return self._digests

    def as_kept(self) -> ItemsView[str, RenderedRequest]:
        """The requests as kept, maybe of an earlier commit: for what a revision does not
        change (digests, contents), never to publish."""
        return self._kept.items()

    def __repr__(self) -> str:
        return f"FleetRequests({self.revision[:12]!r}, {len(self._kept)} robots)"


def _values(
    robot_id: str, robot_name: str, namespace: str | None, domain: int | None, *rest: str
) -> list[bytes]:
    """A robot's values as they are written inside JSON strings (the domain as a JSON
    number), in _SLOT_NAMES order; `rest` the revision and digests (the digests' templates
    hold none of them)."""
    return [
        _inner(robot_id),
        _inner(robot_name),
        b"" if namespace is None else _inner(namespace),
        b"" if domain is None else b"%d" % domain,
        *(map(_inner, rest) if rest else _NOT_DIGESTED),
    ]


_NOT_DIGESTED = (b"", b"", b"")


def _renamed(binding: MappingBinding, name: str) -> MappingBinding:
    """`binding` under `name`: itself when the name is the same (an absolute name), else a
    copy that shares its set of fields."""
    if name == binding.name:
        return binding
    return MappingBinding.model_construct(
        binding.model_fields_set, kind=binding.kind, name=name, type=binding.type
    )


def _inner(text: str) -> bytes:
    """`text` as canonical JSON writes it inside a string: JSON escapes character by
    character, so a string's encoding is the encodings of its pieces in a row."""
    return encode_basestring(text)[1:-1].encode("utf-8")


_SLOT_END = b"\\u0000"


def _template(serialised: bytes, marker: bytes) -> _Template:
    """`serialised` cut at each slot: text that starts with `marker` and ends at the next NUL
    (the slots are text nothing else in it contains). A nested slot is cut with its quotes:
    a JSON object goes there, not text; so is a raw one (_RAW): a number goes there."""
    parts: list[bytes] = []
    slots: list[int] = []
    start = 0
    while (at := serialised.find(marker, start)) >= 0:
        close = serialised.index(_SLOT_END, at + len(marker))
        name = serialised[at + len(marker) : close].decode()
        index = _index(name)
        end = close + len(_SLOT_END)
        if index < 0 or name in _RAW:
            at, end = at - 1, end + 1
        parts.append(serialised[start:at])
        slots.append(index)
        start = end
    parts.append(serialised[start:])
    return tuple(parts), tuple(slots)


def _index(name: str) -> int:
    return _NESTED[name] if name in _NESTED else _SLOT_NAMES.index(name)


def _nest(outer: _Template, name: str, inner: _Template) -> _Template:
    """`outer` with its slot `name` (if any) filled by the template `inner`."""
    parts = list(outer[0][:1])
    slots: list[int] = []
    for slot, part in zip(outer[1], outer[0][1:], strict=True):
        if slot == _NESTED[name]:
            parts[-1] += inner[0][0]
            parts.extend(inner[0][1:])
            slots.extend(inner[1])
            parts[-1] += part
        else:
            slots.append(slot)
            parts.append(part)
    return tuple(parts), tuple(slots)


def _shared(*templates: _Template) -> tuple[_Template, _Template, _Template]:
    """The templates with equal parts one object (the digest content and the payload end in
    the same scenario bytes): what 1,000 scenarios' templates hold, halved."""
    seen: dict[bytes, bytes] = {}
    content, restart, payload = (
        (tuple(seen.setdefault(part, part) for part in parts), slots) for parts, slots in templates
    )
    return content, restart, payload


def _join(template: _Template, values: list[bytes]) -> bytes:
    parts, slots = template
    joined: list[bytes] = [b""] * (2 * len(parts) - 1)
    joined[0::2] = parts
    joined[1::2] = [values[i] for i in slots]
    return b"".join(joined)


def _hash(template: _Template, values: list[bytes]) -> str:
    return "sha256:" + hashlib.sha256(_join(template, values)).hexdigest()
