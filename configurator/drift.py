"""Drift, pure: the interfaces a robot's launch request needs against those the robot reports.

A needed interface that is missing, or present with another type, is one drift item. Nothing
reported (`unknown`) or a failed source (`error`) is never read as the robot lacking anything.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from robotconf.configurator.rendered import RenderedRequest
from robotconf.configurator.rosnames import resolve_in
from robotconf.configurator.types import Action
from robotconf.contract.interfaces import (
    KIND_OF_MAPPING,
    InterfacesVerdict,
    Reported,
    index,
    interfaces_verdict,
    same_type,
)
from robotconf.contract.launch import LaunchCapability, LaunchRequest

DriftPolicy = Literal["warn", "hold"]
DRIFT_POLICIES: tuple[DriftPolicy, ...] = ("warn", "hold")
# mapping -> the logics of a capability that need it, sorted (from the catalogue)
NeededBy = Mapping[str, Sequence[str]]


@dataclass(frozen=True)
class Need:
    """One interface a request needs: a bound mapping, its name fully qualified."""

    mapping: str
    name: str
    kind: str  # the mapping kind: topic, service, action_client
    type: str
    logics: tuple[str, ...] = ()  # who needs it; () when not known


@dataclass(frozen=True)
class DriftItem:
    """A needed interface the robot lacks (`found` empty) or reports with other types."""

    robot_id: str
    need: Need
    found: tuple[str, ...] = ()

    @property
    def missing(self) -> bool:
        return not self.found

    def as_json(self) -> dict[str, Any]:
        """As `robotconf status --json` names it: `found_type` null when missing."""
        return {
            "mapping": self.need.mapping,
            "name": self.need.name,
            "kind": self.need.kind,
            "expected_type": self.need.type,
            "found_type": ", ".join(self.found) if self.found else None,
        }

    def text(self) -> str:
        """`tb3-04 lacks /scan (sensor_msgs/msg/LaserScan), needed by patrol_with_lidar via
        mapping scan`."""
        need = self.need
        if self.missing:
            what = f"{self.robot_id} lacks {need.name} ({need.type})"
        else:
            what = f"{self.robot_id} has {need.name} as {', '.join(self.found)}, not {need.type}"
        return f"{what}, {needed_by_text(need)}"

    def reason(self) -> str:
        """The text without the robot's id in front (for a line already about the robot)."""
        return self.text()[len(self.robot_id) + 1 :]


def needed_by_text(need: Need) -> str:
    kind = "" if need.kind == "topic" else f"{need.kind.replace('_', ' ')} "
    who = f"needed by {' and '.join(need.logics)} " if need.logics else "needed "
    return f"{who}via {kind}mapping {need.mapping}"


@dataclass(frozen=True)
class Drift:
    """One robot's drift: what its interfaces are (`reported`, `unknown`, `error`), the items,
    and a note when something could not be judged (an error, interfaces cut by the bounds)."""

    interfaces: InterfacesVerdict
    items: tuple[DriftItem, ...] = ()
    note: str | None = None
    unsure: tuple[Need, ...] = field(default=(), repr=False)  # not found, but maybe cut
    judged: bool = True  # False: no request to judge against (unassigned, suspended)

    @property
    def drifted(self) -> bool:
        return bool(self.items)

    def summary(self) -> str:
        """A few words for a table cell: `ok`, `2 missing, 1 type`, `unknown`, `error`; `-`
        for a robot that reports but has no request to be judged against."""
        if self.interfaces != "reported":
            return self.interfaces
        if not self.judged:
            return "-"
        if not self.items:
            return "ok" if not self.unsure else "ok?"
        missing = sum(1 for item in self.items if item.missing)
        parts = [f"{missing} missing"] if missing else []
        if len(self.items) > missing:
            parts.append(f"{len(self.items) - missing} type")
        return ", ".join(parts)


UNKNOWN = Drift("unknown")


def logics_needing(
    capability: LaunchCapability, actions: Mapping[str, Action]
) -> dict[str, tuple[str, ...]]:
    """mapping -> the capability's selected logics that need it, from the catalogue's actions.
    `logics` maps an action to one logic, or to several (multi-logic actions)."""
    needed: dict[str, set[str]] = {}
    for action_name, chosen in capability.logics.items():
        action = actions.get(action_name)
        names: Iterable[Any] = [chosen] if isinstance(chosen, str) else chosen
        for logic_name in names:
            logic = action.logics.get(str(logic_name)) if action is not None else None
            for mapping in logic.mappings if logic is not None else ():
                needed.setdefault(mapping, set()).add(str(logic_name))
    return {mapping: tuple(sorted(names)) for mapping, names in needed.items()}


def _fallback_logics(capability: LaunchCapability) -> tuple[str, ...]:
    """Without the catalogue: the capability's one logic needs every mapping; with several,
    which needs which is not said (rather than named wrong)."""
    names: set[str] = set()
    for chosen in capability.logics.values():
        names.update([chosen] if isinstance(chosen, str) else [str(n) for n in chosen])
    return tuple(names) if len(names) == 1 else ()


def needs_of(request: LaunchRequest, needed_by: NeededBy | None = None) -> tuple[Need, ...]:
    """What a request needs of the robot: its capability's mappings, already resolved in the
    robot's namespace (fully qualified), in mapping order."""
    return _needs(request.scenario.capability, None, needed_by, resolve=False)


def needs_of_rendered(
    request: RenderedRequest, needed_by: NeededBy | None = None
) -> tuple[Need, ...]:
    """The same as `needs_of(request.model())`, without building the model."""
    capability = request.scenario_requests.scenario.capability
    return _needs(capability, request.namespace, needed_by, resolve=True)


def _needs(
    capability: LaunchCapability,
    namespace: str | None,
    needed_by: NeededBy | None,
    *,
    resolve: bool,
) -> tuple[Need, ...]:
    fallback = _fallback_logics(capability) if needed_by is None else ()
    return tuple(
        Need(
            mapping,
            resolve_in(binding.name, namespace) if resolve else binding.name,
            binding.kind,
            binding.type,
            tuple(needed_by.get(mapping, ())) if needed_by is not None else fallback,
        )
        for mapping, binding in sorted(capability.mappings.items())
    )


def drift_of(
    robot_id: str, needs: Sequence[Need], found: Reported | None, error: str | None = None
) -> Drift:
    """The robot's drift. `error`: its interfaces payload could not be read (why)."""
    if error is not None:
        return Drift("error", note=f"its interfaces cannot be read: {error}")
    verdict = interfaces_verdict(found)
    if found is None:
        return UNKNOWN
    if verdict == "error":
        return Drift("error", note=f"its interfaces source failed: {found.error}")
    table = index(found)
    items: list[DriftItem] = []
    unsure: list[Need] = []
    for need in needs:
        kind = KIND_OF_MAPPING.get(need.kind)
        types = table.get((kind, need.name), []) if kind is not None else []
        if any(same_type(need.type, t) for t in types):
            continue
        if types:
            items.append(DriftItem(robot_id, need, tuple(types)))
        elif found.truncated > 0:
            unsure.append(need)  # perhaps one of the entries the bounds cut
        else:
            items.append(DriftItem(robot_id, need))
    note = None
    if unsure:
        names = ", ".join(n.name for n in unsure[:5]) + (", ..." if len(unsure) > 5 else "")
        note = (
            f"{len(unsure)} needed interface(s) not among those reported ({names}); the "
            f"report was cut ({found.truncated} entries left out), so they are not claimed "
            "missing"
        )
    return Drift("reported", tuple(items), note, tuple(unsure))


class DriftMemo:
    """Each robot's drift, computed again only when its request (digest) or its interfaces
    (the reading of its payload) changed: one robot's new interfaces cost that robot."""

    def __init__(self) -> None:
        self._kept: dict[str, tuple[str, object, Drift]] = {}
        self.computed = 0  # drifts worked out (not served from the memo): for tests and bench

    def get(
        self,
        robot_id: str,
        digest: str,
        needs: Sequence[Need],
        found: Reported | None,
        error: str | None = None,
    ) -> Drift:
        """The drift of `needs` (the request of `digest`) against `found` (or the `error` its
        payload gave), from the memo when neither changed since the last call for the robot."""
        key: object = error if error is not None else found
        kept = self._kept.get(robot_id)
        if kept is not None and kept[0] == digest and (kept[1] is key or kept[1] == key):
            return kept[2]
        drift = drift_of(robot_id, needs, found, error)
        self.computed += 1
        self._kept[robot_id] = (digest, key, drift)
        return drift

    def keep_only(self, robots: Iterable[str]) -> None:
        wanted = set(robots)
        if len(self._kept) > len(wanted):
            self._kept = {r: k for r, k in self._kept.items() if r in wanted}


def drift_lines(drifts: Mapping[str, Drift]) -> list[str]:
    """One line per drift item, and per note, robots in id order."""
    lines: list[str] = []
    for robot_id in sorted(drifts):
        drift = drifts[robot_id]
        lines += [item.text() for item in drift.items]
        if drift.note is not None:
            lines.append(f"{robot_id}: {drift.note}")
    return lines
