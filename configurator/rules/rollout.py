"""Fleet rules for labels and the rollout policy (RC502, RC7xx): every robot in a wave, every
selector naming labels that exist."""

from __future__ import annotations

from robotconf.configurator.repository import Entry, Repository
from robotconf.configurator.rules.report import Reporter
from robotconf.configurator.stages import Placement, SelectorError, assign_stages, parse_selector
from robotconf.configurator.types import Fleet, RolloutPolicy, Stage, is_robot_id
from robotconf.configurator.waves import assign_waves, failure_budget, matches

# An error listing robots names this many, then how many more.
_SHOWN = 5
_ID_RULE = "use 1-64 letters, digits, '_', '.', '-', starting with a letter or digit"


def check_labels(fleet: Entry[Fleet], report: Reporter) -> None:
    """Label keys and values follow the robot-id rules: they name groups in selectors, status
    and plan, and may become topic levels or file names later."""
    for robot_id, assignment in fleet.model.robots.items():
        for key, value in assignment.labels.items():
            loc: list[str | int] = ["robots", robot_id, "labels", key]
            if not is_robot_id(key):
                report.add(
                    fleet, loc, "RC502", f"label key {key!r} is not usable: {_ID_RULE}", key=True
                )
            if not is_robot_id(value):
                report.add(
                    fleet,
                    loc,
                    "RC502",
                    f"label {key!r} has value {value!r}, not usable: {_ID_RULE}",
                )


def check_rollout(fleet: Entry[Fleet], report: Reporter) -> None:
    policy = fleet.model.rollout
    if policy is None:
        return
    percents_ok = _check_numbers(fleet, policy, report)
    _check_wave_names(fleet, policy, report)
    selectors_ok = _check_selectors(fleet, policy, report)
    robots = {robot_id: a.labels for robot_id, a in fleet.model.robots.items()}
    placed = assign_waves(robots, policy.waves)
    left = sorted(set(robots) - set(placed))
    if left:
        shown = ", ".join(left[:_SHOWN]) + (
            f", ... ({len(left)} in all)" if len(left) > _SHOWN else ""
        )
        report.add(
            fleet,
            ["rollout", "waves"],
            "RC705",
            f"no wave takes robot(s) {shown}, so no commit would ever reach them; add a last wave "
            "without selector, e.g. {name: all}",
            key=True,
        )
    if not (percents_ok and selectors_ok) or not robots:
        return  # a wrong selector or percent already says why a wave takes what it takes
    taken = set(placed.values())
    for index, wave in enumerate(policy.waves):
        if index not in taken:
            report.add(
                fleet,
                ["rollout", "waves", index, "name"],
                "RC706",
                f"wave '{wave.name}' takes no robot: the waves before it take every robot it "
                "selects, or none has its labels",
            )


def _check_numbers(fleet: Entry[Fleet], policy: RolloutPolicy, report: Reporter) -> bool:
    """The policy's numbers in range; False when a wave's percent is not."""
    if policy.healthy_after < 0:
        report.add(
            fleet,
            ["rollout", "healthy_after"],
            "RC702",
            f"healthy_after is {policy.healthy_after:g}: seconds, 0 or more",
        )
    if policy.wave_timeout <= 0:
        report.add(
            fleet,
            ["rollout", "wave_timeout"],
            "RC702",
            f"wave_timeout is {policy.wave_timeout:g}: seconds, more than 0",
        )
    if failure_budget(policy.max_failures, 0) is None:
        report.add(
            fleet,
            ["rollout", "max_failures"],
            "RC702",
            f"max_failures is {policy.max_failures!r}: a count of robots (0 or more) or a share "
            "of a wave's robots like '10%' (0% to 100%)",
        )
    percents_ok = True
    for index, wave in enumerate(policy.waves):
        if wave.percent is not None and not 1 <= wave.percent <= 100:
            percents_ok = False
            report.add(
                fleet,
                ["rollout", "waves", index, "percent"],
                "RC702",
                f"wave '{wave.name}' has percent {wave.percent}: 1 to 100",
            )
    return percents_ok


def _check_wave_names(fleet: Entry[Fleet], policy: RolloutPolicy, report: Reporter) -> None:
    first: dict[str, int] = {}
    for index, wave in enumerate(policy.waves):
        loc: list[str | int] = ["rollout", "waves", index, "name"]
        if not is_robot_id(wave.name):
            report.add(fleet, loc, "RC701", f"wave name {wave.name!r} is not usable: {_ID_RULE}")
        elif wave.name in first:
            line, _ = fleet.doc.locate(["rollout", "waves", first[wave.name], "name"])
            report.add(
                fleet, loc, "RC701", f"wave name '{wave.name}' is used twice (first at line {line})"
            )
        else:
            first[wave.name] = index


def _check_selectors(fleet: Entry[Fleet], policy: RolloutPolicy, report: Reporter) -> bool:
    """Each selector names a label some robot carries, with a value some robot has: a typo
    must not quietly empty a wave (or move its robots to a later one)."""
    known: dict[str, set[str]] = {}
    for assignment in fleet.model.robots.values():
        for key, value in assignment.labels.items():
            known.setdefault(key, set()).add(value)
    ok = True
    for index, wave in enumerate(policy.waves):
        for key, value in wave.selector.items():
            loc: list[str | int] = ["rollout", "waves", index, "selector", key]
            if key not in known:
                ok = False
                report.unknown(
                    fleet,
                    loc,
                    "RC703",
                    f"wave '{wave.name}' selects label '{key}', which no robot has",
                    key,
                    known,
                    key=True,
                )
            elif value not in known[key]:
                ok = False
                report.unknown(
                    fleet,
                    loc,
                    "RC704",
                    f"wave '{wave.name}' selects {key}: {value}, and no robot has that value",
                    value,
                    known[key],
                )
    return ok


def _placements(repo: Repository, fleet: Entry[Fleet]) -> dict[str, Placement]:
    """Each assigned robot's labels and its scenario's environment (name and type)."""
    types = {name: e.model.type for name, e in repo.environments.items()}
    found: dict[str, Placement] = {}
    for robot_id, assignment in fleet.model.robots.items():
        scenario = repo.scenarios.get(assignment.scenario)
        environment = scenario.model.environment if scenario is not None else None
        found[robot_id] = Placement(assignment.labels, environment, types.get(environment or ""))
    return found


def check_stages(repo: Repository, fleet: Entry[Fleet], report: Reporter) -> None:
    """The promotion ladder: each stage says which robots it takes (environments, or a
    selector), every robot is on one, and a rollout is there to verify a revision on them."""
    stages = fleet.model.stages
    if not stages:
        return
    if fleet.model.rollout is None:
        report.add(
            fleet,
            ["stages"],
            "RC707",
            "stages promote a revision once a rollout verified it: add a rollout: policy "
            "(with verify: to judge what the robots achieve)",
            key=True,
        )
    known_environments = {name: e.model.type for name, e in repo.environments.items()}
    words = set(known_environments) | set(known_environments.values())
    seen: dict[str, int] = {}
    for index, stage in enumerate(stages):
        _check_stage(fleet, index, stage, words, seen, report)
    placements = _placements(repo, fleet)
    left = sorted(set(placements) - set(assign_stages(placements, stages)))
    if left:
        shown = ", ".join(left[:_SHOWN]) + (
            f", ... ({len(left)} in all)" if len(left) > _SHOWN else ""
        )
        report.add(
            fleet,
            ["stages"],
            "RC708",
            f"no stage takes robot(s) {shown}, so no revision would be promoted to them; add "
            "their environment to a stage, or a last stage that selects them",
            key=True,
        )


def _check_stage(
    fleet: Entry[Fleet],
    index: int,
    stage: Stage,
    words: set[str],
    seen: dict[str, int],
    report: Reporter,
) -> None:
    """One stage: its name, and how it takes robots (environments known by name or type, or
    a readable selector; one of the two)."""
    loc: list[str | int] = ["stages", index]
    if not is_robot_id(stage.name):
        report.add(fleet, [*loc, "name"], "RC707", f"stage name {stage.name!r}: {_ID_RULE}")
    elif stage.name in seen:
        report.add(fleet, [*loc, "name"], "RC707", f"stage '{stage.name}' is named twice")
    seen.setdefault(stage.name, index)
    if bool(stage.environments) == (stage.selector is not None):
        report.add(
            fleet,
            loc,
            "RC707",
            f"stage '{stage.name}' needs environments (names or types) or a selector "
            '("key=value"), one of the two',
        )
    if stage.selector is not None:
        try:
            parse_selector(stage.selector)
        except SelectorError as exc:
            report.add(fleet, [*loc, "selector"], "RC707", f"stage '{stage.name}': {exc}")
    for at, word in enumerate(stage.environments):
        if word not in words:
            report.unknown(
                fleet,
                [*loc, "environments", at],
                "RC707",
                f"stage '{stage.name}' names environment '{word}', which is neither an "
                "environment's name nor its type",
                word,
                words,
            )


def check_groups(repo: Repository, fleet: Entry[Fleet], report: Reporter) -> None:
    """Groups name assigned robots (or labels), each robot in one group, each group on one
    stage: a group moves as one, and a ladder would have to split it."""
    robots = fleet.model.robots
    owner: dict[str, str] = {}
    for name, chosen in fleet.model.groups.items():
        loc: list[str | int] = ["groups", name]
        if not is_robot_id(name):
            report.add(fleet, loc, "RC709", f"group name {name!r}: {_ID_RULE}", key=True)
        if isinstance(chosen, str):
            try:
                wanted = parse_selector(chosen)
            except SelectorError as exc:
                report.add(fleet, loc, "RC709", f"group '{name}': {exc}")
                continue
            members = [r for r, a in robots.items() if matches(a.labels, wanted)]
        else:
            members = []
            for at, robot in enumerate(chosen):
                if robot not in robots:
                    report.unknown(
                        fleet,
                        [*loc, at],
                        "RC709",
                        f"group '{name}' names robot '{robot}', which is not assigned",
                        robot,
                        robots,
                    )
                else:
                    members.append(robot)
        for robot in members:
            if robot in owner and owner[robot] != name:
                report.add(
                    fleet,
                    loc,
                    "RC709",
                    f"robot '{robot}' is in groups '{owner[robot]}' and '{name}': a robot moves "
                    "with one group",
                )
            owner.setdefault(robot, name)
    if not fleet.model.stages:
        return
    placements = _placements(repo, fleet)
    stage_of = assign_stages(placements, fleet.model.stages)
    spans: dict[str, set[int]] = {}
    for robot, name in owner.items():
        if robot in stage_of:
            spans.setdefault(name, set()).add(stage_of[robot])
    for name, stages in sorted(spans.items()):
        if len(stages) > 1:
            report.add(
                fleet,
                ["groups", name],
                "RC709",
                f"group '{name}' has robots on {len(stages)} stages: a group moves as one, a "
                "ladder would split it",
            )
