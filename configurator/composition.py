"""What a capability composition needs and achieves: the one home of the composition rules.

Pure functions over the typed models; the validator, `tree`, `autofill` and the renderer all ask
these, so "a logic needs a mapping the template lacks" is decided here and nowhere else.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from robotconf.configurator.types import (
    Action,
    Environment,
    JsonScalar,
    Logic,
    MappingScheme,
    OntologyObject,
    RobotTemplate,
    SettingDefinition,
    Task,
)
from robotconf.contract.diagnostics import describe_value


def template_gaps(logic: Logic, template: RobotTemplate) -> list[str]:
    """Mappings the logic needs that the robot template does not have, in the logic's order."""
    have = set(template.mappings)
    return [m for m in logic.mappings if m not in have]


def scheme_gaps(logic: Logic, scheme: MappingScheme) -> list[str]:
    """Mappings the logic needs that the mapping scheme does not bind."""
    return [m for m in logic.mappings if m not in scheme.mappings]


def missing_requires(action: Action, selected: Iterable[str]) -> list[str]:
    chosen = set(selected)
    return [r for r in action.requires if r not in chosen]


def implementation_for(task: Task, selected: Iterable[str]) -> list[str] | None:
    """The first of the task's alternative action lists that the selection covers."""
    chosen = selected if isinstance(selected, set | frozenset) else set(selected)
    for implementation in task.implementations:
        if chosen.issuperset(implementation):
            return implementation
    return None


def achievable_tasks(tasks: Mapping[str, Task], selected: Iterable[str]) -> list[str]:
    chosen = set(selected)
    return sorted(name for name, task in tasks.items() if implementation_for(task, chosen))


def why_unavailable(
    action: Action,
    logic: Logic,
    platform: str,
    template: RobotTemplate | None,
    scheme: MappingScheme | None,
) -> list[str]:
    """Reasons a logic cannot run on this platform / template / scheme; empty when it can."""
    reasons = []
    if platform not in action.platforms:
        reasons.append(f"action is for {', '.join(action.platforms)}, not {platform}")
    if template is not None:
        gaps = template_gaps(logic, template)
        if gaps:
            reasons.append(f"robot template lacks {', '.join(gaps)}")
    if scheme is not None:
        unbound = scheme_gaps(logic, scheme)
        if unbound:
            reasons.append(f"mapping scheme does not bind {', '.join(unbound)}")
    return reasons


def find_location(environment: Environment, ref: str) -> list[OntologyObject]:
    """Objects a goal location names: by id first, else by name."""
    by_id = [o for o in environment.objects if o.id == ref]
    return by_id or [o for o in environment.objects if o.name == ref]


def setting_problem(definition: SettingDefinition, value: JsonScalar) -> tuple[str, str] | None:
    """(code, what is wrong) when the value does not fit the definition, else None."""
    kind = definition.type
    is_number = isinstance(value, int | float) and not isinstance(value, bool)
    fits = {
        "number": is_number,
        "integer": isinstance(value, int) and not isinstance(value, bool),
        "boolean": isinstance(value, bool),
        "string": isinstance(value, str),
        "enum": not isinstance(value, list | dict),
    }[kind]
    if not fits:
        expected = {
            "number": "a number",
            "integer": "a whole number",
            "boolean": "true or false",
            "string": "text",
            "enum": "one of the choices",
        }[kind]
        return "RC402", f"must be {expected}, got {describe_value(value)}"
    if definition.choices is not None and not is_choice(value, definition.choices):
        options = ", ".join(repr(c) for c in definition.choices)
        return "RC404", f"{value!r} is not one of the choices: {options}"
    if is_number and kind in ("number", "integer"):
        number = float(value)
        low, high = definition.minimum, definition.maximum
        if (low is not None and number < low) or (high is not None and number > high):
            lower = _num(low) if low is not None else "-inf"
            upper = _num(high) if high is not None else "inf"
            bounds = f"{lower}..{upper}"
            unit = f" {definition.unit}" if definition.unit else ""
            return "RC403", f"{value!r} is outside {bounds}{unit}"
    return None


def is_choice(value: JsonScalar, choices: list[JsonScalar]) -> bool:
    """Type and value: in Python `True == 1 == 1.0`, but `true` is not the choice `1`."""
    return any(type(value) is type(c) and value == c for c in choices)


def _num(value: float) -> str:
    return str(int(value)) if value == int(value) else str(value)


def definition_problems(definition: SettingDefinition) -> list[tuple[str, str, str]]:
    """(field, code, message) for a setting definition that contradicts itself."""
    found = []
    numeric = definition.type in ("number", "integer")
    for bound in ("minimum", "maximum"):
        if getattr(definition, bound) is not None and not numeric:
            found.append((bound, "RC602", f"'{bound}' applies to number and integer settings only"))
    if (
        numeric
        and definition.minimum is not None
        and definition.maximum is not None
        and definition.minimum > definition.maximum
    ):
        found.append(("minimum", "RC602", "minimum is greater than maximum"))
    if definition.type == "enum" and not definition.choices:
        found.append(("type", "RC602", "an enum setting needs 'choices'"))
    if not found:
        problem = setting_problem(definition, definition.default)
        if problem is not None:
            found.append(("default", "RC601", f"default {problem[1]}"))
    return found
