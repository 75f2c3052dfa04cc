"""Which stage of the promotion ladder (fleet.yaml `stages`) each robot is on: pure, the same
for validation, `plan`, the reconciler and `status`."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from configurator.render import FleetRender
from configurator.types import Stage
from configurator.waves import matches


class SelectorError(ValueError):
    """A stage selector that is not `key=value[,key=value...]`."""


def parse_selector(text: str) -> dict[str, str]:
    """`"site=real"` or `"site=lab,ring=canary"` as labels; SelectorError says what is wrong."""
    found: dict[str, str] = {}
    for part in text.split(","):
        key, sign, value = part.partition("=")
        key, value = key.strip(), value.strip()
        if not sign or not key or not value:
            raise SelectorError(
                f'selector {text!r} is not labels: write "key=value" (several: "k=v,k2=v2")'
            )
        if key in found:
            raise SelectorError(f"selector {text!r} names label {key!r} twice")
        found[key] = value
    return found


@dataclass(frozen=True)
class Placement:
    """What places a robot on a stage: its labels, and its scenario's environment."""

    labels: Mapping[str, str]
    environment: str | None
    environment_type: str | None


def stage_of(placement: Placement, stages: Sequence[Stage]) -> int | None:
    """The index of the first stage that takes the robot, None when none does. A stage with a
    selector takes the robots whose labels match it; one with environments, the robots whose
    scenario runs in one of them (by name or by type, case as written)."""
    for index, stage in enumerate(stages):
        if stage.selector is not None:
            try:
                if matches(placement.labels, parse_selector(stage.selector)):
                    return index
            except SelectorError:
                continue  # validation says so (RC707); here it takes no robot
        wanted = set(stage.environments)
        if wanted and (placement.environment in wanted or placement.environment_type in wanted):
            return index
    return None


def assign_stages(placements: Mapping[str, Placement], stages: Sequence[Stage]) -> dict[str, int]:
    """robot id -> the index of its stage; robots no stage takes are absent (RC708)."""
    found: dict[str, int] = {}
    for robot, placement in placements.items():
        index = stage_of(placement, stages)
        if index is not None:
            found[robot] = index
    return found


def fleet_placements(fleet: FleetRender) -> dict[str, Placement]:
    """Each robot's labels and its scenario's environment, from a build."""
    found: dict[str, Placement] = {}
    for robot, request in fleet.requests.as_kept():
        scenario = request.scenario_requests.scenario
        found[robot] = Placement(
            fleet.labels.get(robot, {}), scenario.environment_name, scenario.environment_type
        )
    return found


def fleet_stages(fleet: FleetRender) -> dict[str, int]:
    """robot id -> its stage index in the build's ladder ({} without stages)."""
    if not fleet.stages:
        return {}
    return assign_stages(fleet_placements(fleet), fleet.stages)
