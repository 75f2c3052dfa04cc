"""The capability tree (tasks > actions > logics): what is chosen, what could be, and why not.

The words of each node are here; `robotconf tree` draws them (workstation/cli/views.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from robotconf.configurator.composition import implementation_for, missing_requires, why_unavailable
from robotconf.configurator.repository import Repository
from robotconf.configurator.resolve import ResolvedCapability, resolve_capability


@dataclass
class LogicNode:
    name: str
    chosen: bool
    reasons: list[str]  # empty: usable on this robot


@dataclass
class ActionNode:
    name: str
    selected: bool
    reasons: list[str]
    logics: list[LogicNode] = field(default_factory=list)


@dataclass
class TaskNode:
    name: str
    achieved_by: list[str] | None
    implementations: list[list[ActionNode]]


@dataclass
class CapabilityTree:
    name: str
    platform: str
    mapping_scheme: str
    robot_template: str | None
    tasks: list[TaskNode]
    other_actions: list[ActionNode]  # selected, but part of no task


def _action_node(repo: Repository, resolved: ResolvedCapability, name: str) -> ActionNode:
    config = resolved.config
    entry = repo.actions.get(name)
    selected = name in config.actions
    if entry is None:
        return ActionNode(name, selected, ["not in the catalogue"])
    action = entry.model
    reasons = []
    if config.platform not in action.platforms:
        reasons.append(f"for {', '.join(action.platforms)}, not {config.platform}")
    missing = missing_requires(action, config.actions)
    if missing:
        reasons.append(f"requires {', '.join(missing)} (not selected)")
    node = ActionNode(name, selected, reasons)
    chosen_logics = config.logics_of(name)
    for logic_name, logic in action.logics.items():
        chosen = logic_name in chosen_logics
        why = why_unavailable(action, logic, config.platform, resolved.template, resolved.scheme)
        # The platform reason is the action's, not each logic's.
        why = [r for r in why if not r.startswith("action is for")]
        node.logics.append(LogicNode(logic_name, chosen, why))
    return node


def build_tree(repo: Repository, capability: str) -> CapabilityTree:
    config = repo.capabilities[capability].model
    resolved = resolve_capability(repo, config)
    tasks = []
    in_tasks: set[str] = set()
    for task_name, entry in sorted(repo.tasks.items()):
        task = entry.model
        impls = []
        for implementation in task.implementations:
            impls.append([_action_node(repo, resolved, a) for a in implementation])
            in_tasks.update(implementation)
        tasks.append(TaskNode(task_name, implementation_for(task, config.actions), impls))
    others = [_action_node(repo, resolved, a) for a in config.actions if a not in in_tasks]
    return CapabilityTree(
        capability,
        config.platform,
        config.mapping_scheme,
        config.robot_template,
        tasks,
        others,
    )


def heading(tree: CapabilityTree) -> str:
    template = tree.robot_template or "no robot template"
    return f"{tree.name}  (platform {tree.platform}, scheme {tree.mapping_scheme}, {template})"


def task_label(task: TaskNode) -> str:
    if task.achieved_by is not None:
        return f"✔ task {task.name}: achieved by {', '.join(task.achieved_by)}"
    return f"○ task {task.name}: not achievable with the selected actions"


def alternative_label(index: int, actions: list[ActionNode]) -> str:
    return f"alternative {index + 1}: {', '.join(a.name for a in actions)}"


def action_label(node: ActionNode) -> str:
    mark = "✔" if node.selected and not node.reasons else ("✗" if node.reasons else "○")
    state = "selected" if node.selected else "not selected"
    chosen = sum(logic.chosen for logic in node.logics)
    if chosen > 1:
        state += f", {chosen} logics"
    why = f"; {'; '.join(node.reasons)}" if node.reasons else ""
    return f"{mark} action {node.name} ({state}{why})"


def logic_label(logic: LogicNode) -> str:
    if logic.chosen:
        return f"● {logic.name} (chosen" + (
            f"; but {'; '.join(logic.reasons)})" if logic.reasons else ")"
        )
    if logic.reasons:
        return f"✗ {logic.name}: {'; '.join(logic.reasons)}"
    return f"○ {logic.name} (available)"
