"""What the robots hold during a rollout, pure: what each keeps while the rollout has not moved
it (the stable revision's request, or the one verified for its stage), what a step has them
hold (the head's for the waves started), and what a rollback gives them back."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from robotconf.configurator.render import FleetRender
from robotconf.configurator.rendered import RenderedRequest
from robotconf.configurator.stages import WavePlan
from robotconf.contract.wire import RolloutStatus, short_rev
from robotconf.reconciler.rollout_scope import RolloutScope, RolloutStep


def stage_bases(
    head: FleetRender, previous: RolloutStatus | None, stable: str | None
) -> list[str | None]:
    """Per stage of the head (fleet.yaml stages), the revision verified for its robots when
    the rollout of the head began: what they keep until the head is verified on the stage
    before, and go back to if it fails on theirs. Read from the retained rollout: its own
    (a restart), or the one before it (a new head: what each stage verified last); a stage it
    does not name has the stable revision."""
    if not head.stages:
        return []
    same = previous is not None and previous.revision == head.revision
    known = {stage.name: stage for stage in previous.stages} if previous is not None else {}
    bases: list[str | None] = []
    for stage in head.stages:
        found = known.get(stage.name)
        base = None
        if found is not None:
            base = found.rollback_revision if same else found.verified_revision
        bases.append(base or stable)
    return bases


def kept_requests(
    head: FleetRender,
    stable: FleetRender | None,
    bases: Sequence[str | None],
    builds: Mapping[str, FleetRender],
    plan: WavePlan,
) -> Mapping[str, RenderedRequest]:
    """What each robot keeps while the rollout has not moved it: the stable revision's
    request, or (fleet.yaml stages) the one of the revision verified for its stage. A stage
    whose revision could not be built keeps the stable one."""
    requests: Mapping[str, RenderedRequest] = stable.requests if stable is not None else {}
    revision = stable.revision if stable is not None else None
    other = {
        index: builds[base]
        for index, base in enumerate(bases)
        if base is not None and base != revision and base in builds
    }
    if not other:
        return requests
    merged = dict(requests)
    for robot, stage in plan.stage_of.items():
        build = other.get(stage)
        request = build.requests.get(robot) if build is not None else None
        if request is not None:
            merged[robot] = request
    return merged


def hold(scope: RolloutScope, started: int, busy_held: set[str]) -> RolloutStep:
    """Robots of started waves hold the head's request; the others are not touched (a
    robot that holds nothing readable gets the stable request back). `busy_held`: robots
    whose group waits for a busy member (`WaveJudge`), not sent the head's request yet."""
    head = scope.seen.head
    step = RolloutStep()
    for robot, request in head.requests.items():
        if robot in head.suspended:
            step.requests[robot] = request  # the diff leaves suspended robots as they are
            continue
        waiting = robot in busy_held  # its group waits for a busy member
        if not waiting and (
            robot not in scope.changed or scope.waves.get(robot, scope.count) <= started
        ):
            step.requests[robot] = request
        elif scope.seen.launches.get(robot) is not None:
            step.keep.add(robot)
            step.requests[robot] = request  # held as it is: the diff leaves it alone
        elif robot in scope.stable_requests:
            step.requests[robot] = scope.stable_requests[robot]
    return step


def back(scope: RolloutScope, stage: int | None) -> tuple[RolloutStep, str]:
    """Rolled back from a failure on `stage`, and what the status says of it: the stage and
    those after it get what was verified for them when the rollout began, the stages
    before it keep the head (verified there). Without stages, or when that is the stable
    revision everywhere, the whole fleet is served the stable revision."""
    stable = scope.stable_revision()
    if stage is None or (stage == 0 and all(b in (None, stable) for b in scope.bases)):
        return RolloutStep(serve_stable=True), f"; rolled back to {short_rev(stable)}"
    head, step = scope.seen.head, RolloutStep()
    for robot, request in head.requests.items():
        at = scope.plan.stage_of.get(robot)
        if robot in head.suspended or (at is not None and at < stage):
            step.requests[robot] = request
        elif robot in scope.stable_requests:
            step.requests[robot] = scope.stable_requests[robot]
    for robot in scope.stable_requests.keys() - head.requests.keys():
        step.requests[robot] = scope.stable_requests[robot]  # gone from the head: back
    names = [s.name for s in head.stages]
    told = ", ".join(
        f"'{names[i]}' to {short_rev(scope.bases[i] if i < len(scope.bases) else stable)}"
        for i in range(stage, len(names))
    )
    kept = ", ".join(f"'{name}'" for name in names[:stage])
    what = f"; rolled back stage {told}" + (
        f"; stage {kept} keeps {short_rev(head.revision)}, verified there" if kept else ""
    )
    return step, what
