"""Whether a logic fits a live robot: each mapping it needs is among the robot's reported
interfaces, with its kind and type (pure; autofill takes it to select from a live robot)."""

from __future__ import annotations

from collections.abc import Callable

from robotconf.configurator.rosnames import UnresolvableName, resolve_name
from robotconf.configurator.types import Action, Logic, MappingScheme
from robotconf.contract.interfaces import KIND_OF_MAPPING, RobotInterfaces, index, same_type


def logic_fits_interfaces(
    logic: Logic, scheme: MappingScheme, namespace: str | None, interfaces: RobotInterfaces
) -> list[str]:
    """Why `logic` cannot run on a robot in `namespace` (valid, or None) that reports
    `interfaces` under `scheme`; empty when it can. A report whose source failed proves
    nothing, so nothing fits it; interfaces cut by the report's bounds are said, not guessed."""
    if interfaces.error is not None:
        return [f"the robot's interfaces are not known: {interfaces.error}"]
    found = index(interfaces)
    cut = (
        f" ({interfaces.truncated} interface(s) were left out of the report)"
        if interfaces.truncated
        else ""
    )
    reasons: list[str] = []
    for mapping in logic.mappings:
        binding = scheme.mappings.get(mapping)
        if binding is None:
            reasons.append(f"mapping scheme does not bind {mapping}")
            continue
        try:
            name = resolve_name(binding.name, namespace)
        except UnresolvableName as exc:
            reasons.append(f"mapping {mapping}: {exc}")
            continue
        kind = KIND_OF_MAPPING[binding.kind]
        types = found.get((kind, name), [])
        if not types:
            reasons.append(f"robot lacks {kind} {name} ({binding.type}), mapping {mapping}{cut}")
        elif not any(same_type(binding.type, t) for t in types):
            reasons.append(
                f"robot's {kind} {name} is {', '.join(types)}, not {binding.type} "
                f"(mapping {mapping})"
            )
    return reasons


def interfaces_fit(
    scheme: MappingScheme, namespace: str | None, interfaces: RobotInterfaces
) -> Callable[[str, Action, str, Logic], list[str]]:
    """Autofill's "does this logic fit" from a live robot (`autofill.LogicFit`)."""

    def fits(_name: str, _action: Action, _logic_name: str, logic: Logic) -> list[str]:
        return logic_fits_interfaces(logic, scheme, namespace, interfaces)

    return fits
