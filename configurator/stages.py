"""How a rollout moves the fleet beyond its waves, pure, the same for validation, `plan`, the
reconciler and `status`: which stage of the promotion ladder (fleet.yaml `stages`) each robot
is on, which group it moves with (fleet.yaml `groups`, `rollout.groups`), and the rollout's
steps in order (each stage's waves, then its gate; no group split)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from robotconf.configurator.types import Stage
from robotconf.configurator.waves import assign_waves, matches

if TYPE_CHECKING:  # validate places robots without the rendering's models
    from robotconf.configurator.render import FleetRender


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


@dataclass(frozen=True)
class WaveSpec:
    """One step of a rollout: a wave of the policy (within a stage, when there are stages), or
    a stage's gate — no robots of its own; the whole stage's evidence, judged before the next
    stage's first wave."""

    name: str  # the wave's ("canary"), "sim/canary" within stage sim, "sim" for its gate
    stage: int | None = None
    gate: bool = False


@dataclass(frozen=True)
class WavePlan:
    specs: tuple[WaveSpec, ...]
    of: dict[str, int]  # robot id -> the index of its wave in `specs`
    stage_of: dict[str, int]  # robot id -> its stage ({} without stages)
    group_of: dict[str, str] = field(default_factory=dict)  # robot id -> its group, if any

    def first_of_stage(self, stage: int) -> int:
        return next(i for i, spec in enumerate(self.specs) if spec.stage == stage)

    def gate_of(self, stage: int) -> int:
        return next(i for i, s in enumerate(self.specs) if s.stage == stage and s.gate)


def plan_waves(fleet: FleetRender) -> WavePlan:
    """The rollout's steps, in order. Without stages, the policy's waves. With stages, each
    stage's robots go through the policy's waves (selectors and shares among that stage's
    robots), then the stage's gate; the next stage starts after it. A robot no stage takes
    (RC708 refuses such a commit) goes with the last stage."""
    policy = fleet.rollout
    assert policy is not None
    if not fleet.stages:
        plain = tuple(WaveSpec(wave.name) for wave in policy.waves)
        return _together(WavePlan(plain, assign_waves(fleet.labels, policy.waves), {}), fleet)
    stages = fleet_stages(fleet)
    last = len(fleet.stages) - 1
    stage_of = {robot: stages.get(robot, last) for robot in fleet.labels}
    width = len(policy.waves) + 1
    specs: list[WaveSpec] = []
    of: dict[str, int] = {}
    for index, stage in enumerate(fleet.stages):
        specs.extend(WaveSpec(f"{stage.name}/{w.name}", index) for w in policy.waves)
        specs.append(WaveSpec(stage.name, index, gate=True))
        members = {r: fleet.labels[r] for r, s in stage_of.items() if s == index}
        for robot, wave in assign_waves(members, policy.waves).items():
            of[robot] = index * width + wave
    return _together(WavePlan(tuple(specs), of, stage_of), fleet)


def _together(plan: WavePlan, fleet: FleetRender) -> WavePlan:
    """A wave never splits a group: its robots all go in the earliest wave any of them is in."""
    group_of = fleet_groups(fleet)
    if not group_of:
        return plan
    first: dict[str, int] = {}
    for robot, group in group_of.items():
        if robot in plan.of:
            first[group] = min(first.get(group, plan.of[robot]), plan.of[robot])
    of = dict(plan.of)
    for robot, group in group_of.items():
        if group in first:
            of[robot] = first[group]
    return WavePlan(plan.specs, of, plan.stage_of, group_of)


def fleet_groups(fleet: FleetRender) -> dict[str, str]:
    """robot id -> the group it moves with (fleet.yaml `groups`, and with `rollout.groups:
    scenario` every scenario's robots); robots alone are absent. Groups that share a robot are
    one group (validation refuses it, RC709; here nothing is split)."""
    members: dict[str, set[str]] = {}
    robots = set(fleet.labels)
    for name, chosen in fleet.groups.items():
        if isinstance(chosen, str):
            try:
                wanted = parse_selector(chosen)
            except SelectorError:
                continue  # RC709 says so; here it takes no robot
            members[name] = {r for r in robots if matches(fleet.labels[r], wanted)}
        else:
            members[name] = {r for r in chosen if r in robots}
    if fleet.rollout is not None and fleet.rollout.groups == "scenario":
        for robot, scenario in fleet.scenario_of.items():
            members.setdefault(f"scenario:{scenario}", set()).add(robot)
    found: dict[str, str] = {}
    for name in sorted(members):  # a robot in two groups joins them: the first name stays
        together = set(members[name])
        known = {found[r] for r in together if r in found}
        for other in known:
            together |= {r for r, g in found.items() if g == other}
        label = min(known | {name})
        if len(together) > 1:
            for robot in together:
                found[robot] = label
    return found
