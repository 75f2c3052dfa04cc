"""What exists: a summary of the catalogue for `robotconf catalog` (JSON, and the words of its
text form, which workstation/cli/views.py draws)."""

from __future__ import annotations

from typing import Any

from robotconf.configurator.repository import Repository


def catalogue_summary(repo: Repository) -> dict[str, Any]:
    return {
        "platforms": {
            name: {
                "description": p.info.model.description if p.info else "",
                "robot_templates": {
                    t: {"mappings": e.model.mappings, "settings": sorted(e.model.settings)}
                    for t, e in sorted(p.templates.items())
                },
                "mapping_schemes": {
                    s: sorted(e.model.mappings) for s, e in sorted(p.schemes.items())
                },
            }
            for name, p in sorted(repo.platforms.items())
        },
        "tasks": {name: e.model.implementations for name, e in sorted(repo.tasks.items())},
        "actions": {
            name: {
                "platforms": e.model.platforms,
                "requires": e.model.requires,
                "logics": {
                    logic: {"mappings": lg.mappings, "settings": sorted(lg.settings)}
                    for logic, lg in e.model.logics.items()
                },
            }
            for name, e in sorted(repo.actions.items())
        },
        "environments": {
            name: {
                "type": e.model.type,
                "locations": [o.name for o in e.model.objects if o.type == "Location"],
                "knowledge_sets": sorted(e.model.knowledge_sets),
            }
            for name, e in sorted(repo.environments.items())
        },
    }


Entry = tuple[str, list[str]]  # a line, and the lines beneath it
Section = tuple[str, list[Entry]]


def catalogue_sections(summary: dict[str, Any]) -> list[Section]:
    """The summary in words: per section, each entry's line and the lines beneath it."""
    platforms = [
        (
            name + (f"  - {p['description']}" if p["description"] else ""),
            [
                f"template {t}: {', '.join(info['mappings'])}"
                for t, info in p["robot_templates"].items()
            ]
            + [f"scheme   {s}: binds {', '.join(m)}" for s, m in p["mapping_schemes"].items()],
        )
        for name, p in summary["platforms"].items()
    ]
    tasks: list[Entry] = [
        (f"{name}: {' | '.join('[' + ', '.join(i) + ']' for i in impls)}", [])
        for name, impls in summary["tasks"].items()
    ]
    actions = [
        (
            f"{name} ({', '.join(a['platforms'])})"
            + (f"  requires {', '.join(a['requires'])}" if a["requires"] else ""),
            [
                f"logic {logic}: needs {', '.join(info['mappings']) or 'no mappings'}"
                for logic, info in a["logics"].items()
            ],
        )
        for name, a in summary["actions"].items()
    ]
    environments: list[Entry] = [
        (
            f"{name} ({e['type']}): locations {', '.join(e['locations']) or '-'}; "
            f"knowledge sets {', '.join(e['knowledge_sets']) or '-'}",
            [],
        )
        for name, e in summary["environments"].items()
    ]
    return [
        ("Platforms", platforms),
        ("Tasks", tasks),
        ("Actions", actions),
        ("Environments", environments),
    ]
