"""The capability tree (tasks > actions > logics): what is chosen, what could be, and why not."""

from __future__ import annotations

from dataclasses import dataclass, field

from configurator.composition import implementation_for, missing_requires, why_unavailable
from configurator.repository import Repository
from configurator.resolve import ResolvedCapability, resolve_capability
from configurator.textsafe import printable_lines


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
    for logic_name, logic in action.logics.items():
        chosen = config.actions.get(name) == logic_name
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


def _action_lines(node: ActionNode, prefix: str, last: bool) -> list[str]:
    branch, cont = ("└─ ", "   ") if last else ("├─ ", "│  ")
    mark = "✔" if node.selected and not node.reasons else ("✗" if node.reasons else "○")
    state = "selected" if node.selected else "not selected"
    why = f"; {'; '.join(node.reasons)}" if node.reasons else ""
    lines = [f"{prefix}{branch}{mark} action {node.name} ({state}{why})"]
    for i, logic in enumerate(node.logics):
        lb = "└─ " if i == len(node.logics) - 1 else "├─ "
        if logic.chosen:
            text = f"● {logic.name} (chosen"
            text += f"; but {'; '.join(logic.reasons)})" if logic.reasons else ")"
        elif logic.reasons:
            text = f"✗ {logic.name}: {'; '.join(logic.reasons)}"
        else:
            text = f"○ {logic.name} (available)"
        lines.append(f"{prefix}{cont}{lb}{text}")
    return lines


def format_tree(tree: CapabilityTree) -> str:
    template = tree.robot_template or "no robot template"
    lines = [f"{tree.name}  (platform {tree.platform}, scheme {tree.mapping_scheme}, {template})"]
    groups: list[tuple[str, list[tuple[str | None, list[ActionNode]]]]] = []
    for task in tree.tasks:
        if task.achieved_by is not None:
            head = f"✔ task {task.name}: achieved by {', '.join(task.achieved_by)}"
        else:
            head = f"○ task {task.name}: not achievable with the selected actions"
        if len(task.implementations) == 1:
            groups.append((head, [(None, task.implementations[0])]))
        else:
            groups.append(
                (
                    head,
                    [
                        (f"alternative {i + 1}: {', '.join(a.name for a in impl)}", impl)
                        for i, impl in enumerate(task.implementations)
                    ],
                )
            )
    if tree.other_actions:
        groups.append(("actions in no task", [(None, tree.other_actions)]))
    for gi, (head, alternatives) in enumerate(groups):
        last_group = gi == len(groups) - 1
        lines.append(("└─ " if last_group else "├─ ") + head)
        gp = "   " if last_group else "│  "
        for ai, (title, actions) in enumerate(alternatives):
            prefix = gp
            if title is not None:
                last_alt = ai == len(alternatives) - 1
                lines.append(gp + ("└─ " if last_alt else "├─ ") + title)
                prefix = gp + ("   " if last_alt else "│  ")
            for i, node in enumerate(actions):
                lines.extend(_action_lines(node, prefix, i == len(actions) - 1))
    return printable_lines(lines)
