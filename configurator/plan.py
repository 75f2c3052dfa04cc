"""Plans a rollout: per robot, what changes between two rendered fleets (added, removed...)."""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from robotconf.configurator.drift import Drift, drift_lines, drift_of, needs_of_rendered
from robotconf.configurator.render import FleetRender
from robotconf.configurator.rendered import RenderedRequest
from robotconf.configurator.stages import plan_waves
from robotconf.configurator.types import RolloutPolicy, Stage, Verify
from robotconf.configurator.waves import assign_waves
from robotconf.contract.interfaces import Reported as Report
from robotconf.contract.textsafe import (
    markdown_code,
    markdown_text,
    printable,
    printable_lines,
    shorten,
)
from robotconf.contract.wire import short_rev

ChangeKind = Literal["added", "removed", "changed", "held"]


Action = Literal["start", "stop", "restart", "reload", "none"]


# A commit as a reconciler's status names it: hex only, so that text from the broker can never
# reach git as an option or a revision expression.
_COMMIT = re.compile(r"[0-9a-f]{7,64}")


@dataclass(frozen=True)
class FleetRead:
    """What the desk learnt from the broker at `url` of the revision the fleet runs: nothing
    (`unreached`: why the broker could not be read), or the reconciler's retained status's
    `applied` revision (None: no reconciler status, or none applied yet)."""

    url: str
    unreached: str | None = None
    applied: str | None = None


@dataclass(frozen=True)
class PlanBase:
    """The revision `plan` compares with when no --base is given, and why that one."""

    revision: str  # the fleet's applied commit, or "HEAD"
    from_fleet: bool
    why: str

    def line(self, commit: str) -> str:
        """The output's first line, once `revision` is known as `commit`."""
        if self.from_fleet:
            return f"against what the fleet runs: {short_rev(commit)} ({self.why})"
        return f"against HEAD {short_rev(commit)} ({self.why})"


def choose_base(read: FleetRead) -> PlanBase:
    """What the fleet's reconciler has applied when the broker said so, else HEAD."""
    if read.unreached is not None:
        return PlanBase("HEAD", False, read.unreached)
    if read.applied is not None and _COMMIT.fullmatch(read.applied):
        return PlanBase(read.applied, True, "applied by the reconciler")
    why = (
        "holds no revision applied by a reconciler"
        if read.applied is None
        else "names no commit as applied by the reconciler"
    )
    return PlanBase("HEAD", False, f"the broker at {read.url} {why}")


def action_of(old: RenderedRequest, new: RenderedRequest) -> Action:
    """Restart, unless only what a running brain can reload changed (same restart_digest)."""
    same = old.restart_digest is not None and old.restart_digest == new.restart_digest
    return "reload" if same else "restart"


@dataclass
class RobotChange:
    robot_id: str
    kind: ChangeKind  # held: it would change, but the robot is suspended
    scenario_before: str | None
    scenario_after: str | None
    fields: list[str] = field(default_factory=list)
    wave: str | None = None  # the head's rollout wave it falls in; None: no policy, or removed
    group: str | None = None  # the group it moves with (fleet.yaml groups), if any
    # What its agent will do: start, stop, restart the brain, or reload it (the capability is
    # unchanged: an agent with `reload:` signals the running brain, any other restarts it).
    action: Action = "none"
    # action -> (logics before, logics after), for each action whose logics changed
    logics: dict[str, tuple[list[str], list[str]]] = field(default_factory=dict)


@dataclass
class Plan:
    base: str
    head: str
    changes: list[RobotChange]  # in robot id order; with waves, in wave order first
    unchanged: int
    waves: list[str] | None = None  # the head's rollout waves in order; None: all at once
    offline: str | None = None  # the head's rollout.offline: what robots that are off do
    verify: Verify | None = None  # the head's rollout.verify: what each wave's goals must show
    stages: list[str] = field(default_factory=list)  # the promotion ladder, in words
    # robot -> its drift against the head's request, for the robots that would get a new one,
    # when the robots' interfaces were read (`plan --broker`); None: not read, nothing said
    drift: dict[str, Drift] | None = None
    # revision -> its commit's subject, as the edge read it (the work tree has none)
    subjects: dict[str, str] = field(default_factory=dict)

    @property
    def restarts(self) -> list[str]:
        """Robots whose brain the reconciler will restart or stop."""
        return [c.robot_id for c in self.changes if c.kind != "held"]


def changed_fields(before: Any, after: Any, path: str = "") -> list[str]:
    """Dotted paths of the leaves that differ (lists of equal length compared item by item)."""
    if isinstance(before, dict) and isinstance(after, dict):
        found = []
        for key in sorted(set(before) | set(after)):
            sub = f"{path}.{key}" if path else str(key)
            if key not in before or key not in after:
                found.append(sub)
            else:
                found.extend(changed_fields(before[key], after[key], sub))
        return found
    if isinstance(before, list) and isinstance(after, list) and len(before) == len(after):
        found = []
        for i, (b, a) in enumerate(zip(before, after, strict=True)):
            found.extend(changed_fields(b, a, f"{path}[{i}]"))
        return found
    return [] if before == after else [path or "(whole request)"]


_LOGICS = "scenario.capability.logics."


def _logic_changes(before: Any, after: Any) -> dict[str, tuple[list[str], list[str]]]:
    """action -> (its logics before, after), for the actions whose logics differ; one logic
    is its name in a request, several a list."""

    def logics(content: Any) -> dict[str, list[str]]:
        found = content.get("scenario", {}).get("capability", {}).get("logics", {})
        return {a: [c] if isinstance(c, str) else list(c) for a, c in found.items()}

    old, new = logics(before), logics(after)
    return {
        a: (old.get(a, []), new.get(a, []))
        for a in sorted(set(old) | set(new))
        if old.get(a) != new.get(a)
    }


def _whole_logic_lists(fields: list[str]) -> list[str]:
    """An action's logics as one field: `logics.Follow`, not `logics.Follow[1]` (the
    position of a logic in the list says nothing)."""
    found: list[str] = []
    for name in fields:
        if name.startswith(_LOGICS) and name.endswith("]"):
            name = name[: name.index("[", len(_LOGICS))]
        if name not in found:
            found.append(name)
    return found


def make_plan(base: FleetRender, head: FleetRender, rollout: RolloutPolicy | None = None) -> Plan:
    """What changes per robot from `base` to `head`; with the head's `rollout` policy, which
    wave each robot of the head falls in, the changes in wave order."""
    changes: list[RobotChange] = []
    unchanged = 0
    for robot_id in sorted(set(base.requests) | set(head.requests)):
        old = base.requests.get(robot_id)
        new = head.requests.get(robot_id)
        before, after = base.scenario_of.get(robot_id), head.scenario_of.get(robot_id)
        if old is None:
            kind: ChangeKind = "held" if robot_id in head.suspended else "added"
            action: Action = "none" if kind == "held" else "start"
            changes.append(RobotChange(robot_id, kind, None, after, action=action))
        elif new is None:
            changes.append(RobotChange(robot_id, "removed", before, None, action="stop"))
        elif old.digest != new.digest:
            kind = "held" if robot_id in head.suspended else "changed"
            old_content, new_content = old.content(), new.content()
            fields = _whole_logic_lists(changed_fields(old_content, new_content))
            action = "none" if kind == "held" else action_of(old, new)
            logics = (
                _logic_changes(old_content, new_content)
                if any(f.startswith(_LOGICS) for f in fields)
                else {}
            )
            changes.append(
                RobotChange(robot_id, kind, before, after, fields, action=action, logics=logics)
            )
        else:
            unchanged += 1
    if rollout is None:
        return Plan(base.revision, head.revision, changes, unchanged)
    names = [wave.name for wave in rollout.waves]
    placed = assign_waves(head.labels, rollout.waves)
    group_of: dict[str, str] = {}
    if head.rollout is not None:  # stages and groups: as the reconciler will move them
        staged = plan_waves(head)
        names, placed, group_of = [s.name for s in staged.specs], staged.of, staged.group_of
    for change in changes:
        index = placed.get(change.robot_id)
        change.wave = None if index is None else names[index]
        change.group = group_of.get(change.robot_id)
    # Removed robots (and any no wave takes) last: they are in no wave of the head.
    changes.sort(key=lambda c: (placed.get(c.robot_id, len(names)), c.robot_id))
    return Plan(
        base.revision,
        head.revision,
        changes,
        unchanged,
        names,
        rollout.offline,
        rollout.verify,
        [stage_text(stage) for stage in head.stages],
    )


def stage_text(stage: Stage) -> str:
    """'sim (Gazebo; soak 6 goals)': a stage, what takes its robots, and its soak."""
    takes = ", ".join(stage.environments) if stage.environments else stage.selector or ""
    soak = f"; soak {stage.soak.goals} goals" if stage.soak is not None else ""
    return f"{stage.name} ({takes}{soak})"


Reported = Mapping[str, tuple[Report | None, str | None]]  # robot -> (report, error)


def with_drift(plan: Plan, head: FleetRender, reported: Reported) -> Plan:
    """The plan with the drift of each robot that would get a new request (added or changed)
    against the interfaces it reports: what it would lack, before it is told."""
    drift: dict[str, Drift] = {}
    for change in plan.changes:
        request = head.requests.get(change.robot_id)
        if change.kind not in ("added", "changed") or request is None:
            continue
        found, error = reported.get(change.robot_id, (None, None))
        needs = needs_of_rendered(request, head.needed_by.get(request.capability_name))
        drift[change.robot_id] = drift_of(change.robot_id, needs, found, error)
    plan.drift = drift
    return plan


def _drift_lines(plan: Plan) -> list[str]:
    if plan.drift is None:
        return []
    drifts = plan.drift
    lines = [f"drift: {line}" for line in drift_lines(drifts)]
    unknown = sorted(r for r, d in drifts.items() if d.interfaces == "unknown")
    if unknown:
        lines.append(f"drift not judged (no interfaces reported): {', '.join(unknown)}")
    if not lines and drifts:
        lines.append("drift: none — every robot that would change reports what it needs")
    return lines


def _counts(plan: Plan) -> str:
    count = {
        k: sum(c.kind == k for c in plan.changes) for k in ("changed", "added", "removed", "held")
    }
    text = f"{count['changed']} changed, {count['added']} added, {count['removed']} removed"
    if count["held"]:
        text += f", {count['held']} held (suspended)"
    return text + f", {plan.unchanged} unchanged"


def _short(rev: str) -> str:
    return short_rev(rev) if len(rev) >= 40 and "+" not in rev else rev


_SIGN = {"added": "+", "removed": "-", "changed": "~", "held": "="}


def _change_line(c: RobotChange) -> str:
    scenario = c.scenario_after or c.scenario_before or ""
    if c.kind == "removed":
        detail = f"(was {c.scenario_before}; its brain will be stopped)"
    elif c.kind == "added":
        detail = scenario
    else:
        moved = (
            f"{c.scenario_before} -> {c.scenario_after}"
            if c.scenario_before != c.scenario_after
            else scenario
        )
        detail = f"{moved}: {', '.join(_field_text(c, f) for f in c.fields)}"
        if c.kind == "held":
            detail += " (suspended: left as it is)"
        else:
            detail += f" [{c.action}]"
    if c.group is not None:
        detail += f" (group {c.group})"
    return f"  {_SIGN[c.kind]} {c.robot_id}  {detail}"


def _field_text(c: RobotChange, name: str) -> str:
    """A changed field as the plan shows it: an action's logics with what they were and are."""
    action = name.removeprefix(_LOGICS)
    if action == name or action not in c.logics:
        return name
    before, after = c.logics[action]
    return (
        f"logics of {action}: {' + '.join(before) or '(none)'} -> {' + '.join(after) or '(none)'}"
    )


def _wave_heading(waves: list[str], wave: str | None) -> str:
    if wave is None:
        return "in no wave (removed):"
    return f"wave {wave} ({waves.index(wave) + 1} of {len(waves)}):"


_OFFLINE = {
    "skip": "robots that are off are skipped, and get it when they reconnect",
    "wait": "robots that are off are waited for up to wave_timeout",
    "fail": "robots that are off count as failed",
}


def _offline_text(plan: Plan) -> str:
    return f"; {_OFFLINE[plan.offline]}" if plan.offline in _OFFLINE else ""


def verify_text(verify: Verify) -> str:
    """What each wave's goal outcomes must show before the next wave starts, in words: 'at least
    20 goals, success rate ≥ 90%, no worse than stable by more than 10%, critical: COLLISION;
    inconclusive after 10m: pause'."""
    if verify.min_goals == 0:
        parts = ["no minimum of goals"]
    else:
        parts = [f"at least {verify.min_goals} goal{'' if verify.min_goals == 1 else 's'}"]
    if verify.success_rate is not None:
        parts.append(f"success rate ≥ {verify.success_rate:.0%}")
    if verify.compare == "stable":
        parts.append(f"no worse than stable by more than {verify.max_drop:.0%}")
    if verify.critical:
        parts.append(f"critical: {', '.join(verify.critical)}")
    # The timeout as fleet.yaml wrote it: '10m' reads as the file does; a number is seconds.
    timeout = verify.timeout if isinstance(verify.timeout, str) else f"{verify.timeout:g}s"
    text = f"{', '.join(parts)}; inconclusive after {timeout}: {verify.inconclusive}"
    return text + (" (dry run: judged, not gating)" if verify.dry_run else "")


def _commit_lines(plan: Plan) -> list[str]:
    """`  3f2a9c1b7d0e "Rename the lab robots"`: each side's commit subject, when known."""
    return [
        f'  {_short(rev)} "{shorten(plan.subjects[rev], 72)}"'
        for rev in dict.fromkeys((plan.base, plan.head))
        if plan.subjects.get(rev)
    ]


def format_plan_text(plan: Plan) -> str:
    lines = [f"plan {_short(plan.base)} -> {_short(plan.head)}: {_counts(plan)}"]
    lines += _commit_lines(plan)
    if plan.waves is not None:
        lines.append(f"rollout in waves: {', '.join(plan.waves)}{_offline_text(plan)}")
    if plan.waves is not None and plan.verify is not None:
        lines.append(f"verified by: {verify_text(plan.verify)}")
    if plan.stages:
        lines.append(f"stages (each verified before the next): {' → '.join(plan.stages)}")
    heading: str | None = None
    for c in plan.changes:
        if plan.waves is not None and _wave_heading(plan.waves, c.wave) != heading:
            heading = _wave_heading(plan.waves, c.wave)
            lines.append(heading)
        lines.append(_change_line(c))
    return printable_lines(lines + _drift_lines(plan))


def format_plan_markdown(plan: Plan) -> str:
    lines = [
        f"### robotconf plan `{_short(plan.base)}` → `{_short(plan.head)}`",
        "",
        *[f"- {markdown_text(line.strip())}" for line in _commit_lines(plan)],
        *([""] if plan.subjects else []),
        _counts(plan) + ".",
        "",
    ]
    if plan.waves is not None:
        waves_text = " → ".join(markdown_text(w) for w in plan.waves)
        lines += [f"Rollout in waves: {waves_text}{_offline_text(plan)}.", ""]
    if plan.waves is not None and plan.verify is not None:
        lines += [f"Each wave verified by: {markdown_text(verify_text(plan.verify))}.", ""]
    if plan.stages:
        ladder = " → ".join(markdown_text(stage) for stage in plan.stages)
        lines += [f"Stages, each verified before the next: {ladder}.", ""]
    if not plan.changes:
        lines.append("No robot's Launch Request changes: no robot restarts.")
        return "\n".join(lines) + "\n"
    waves = plan.waves is not None
    lines += [
        ("| wave " if waves else "") + "| robot | change | scenario | changed fields |",
        ("| --- " if waves else "") + "| --- | --- | --- | --- |",
    ]
    for c in plan.changes:
        scenario = (
            f"{markdown_text(c.scenario_before)} → {markdown_text(c.scenario_after)}"
            if c.scenario_before and c.scenario_after and c.scenario_before != c.scenario_after
            else markdown_text(c.scenario_after or c.scenario_before or "")
        )
        fields = "<br>".join(markdown_code(_field_text(c, f)) for f in c.fields[:20])
        if len(c.fields) > 20:
            fields += f"<br>… {len(c.fields) - 20} more"
        kind: str = "held (suspended)" if c.kind == "held" else c.kind
        if c.kind == "changed":
            kind += f", {c.action}"
        wave = (f"| {markdown_text(c.wave or '—')} ") if waves else ""
        lines.append(f"{wave}| {markdown_code(c.robot_id)} | {kind} | {scenario} | {fields} |")
    drift = _drift_lines(plan)
    if drift:
        lines += ["", *(f"- {markdown_text(line)}" for line in drift)]
    return "\n".join(lines) + "\n"


def _change_json(c: RobotChange, waves: bool, drift: dict[str, Drift] | None) -> dict[str, Any]:
    found: dict[str, Any] = {
        "robot_id": c.robot_id,
        "change": c.kind,
        "scenario_before": c.scenario_before,
        "scenario_after": c.scenario_after,
        "fields": c.fields,
        "action": c.action,
    }
    if waves:
        found["wave"] = c.wave
        found["group"] = c.group
    if c.logics:
        found["logics"] = {
            a: {"before": before, "after": after} for a, (before, after) in c.logics.items()
        }
    if drift is not None:
        judged = drift.get(c.robot_id)
        found["interfaces"] = judged.interfaces if judged is not None else None
        found["drift"] = [i.as_json() for i in judged.items] if judged is not None else []
    return found


def plan_as_json(plan: Plan) -> dict[str, Any]:
    """For scripts; `waves`, `offline`, `verify` (none without rollout.verify), `stages` (in
    words, [] without) and each change's
    `wave` only when the head has a rollout policy; each change's `interfaces` and `drift` only
    when the robots' interfaces were read."""
    found: dict[str, Any] = {"base": plan.base, "head": plan.head, "unchanged": plan.unchanged}
    if plan.subjects:  # the revisions' commit subjects, when read
        found["subjects"] = {rev: printable(text) for rev, text in plan.subjects.items()}
    if plan.waves is not None:
        found["waves"] = plan.waves
        found["offline"] = plan.offline
        found["verify"] = plan.verify.model_dump(mode="json") if plan.verify else None
        found["stages"] = plan.stages
    found["changes"] = [_change_json(c, plan.waves is not None, plan.drift) for c in plan.changes]
    return found
