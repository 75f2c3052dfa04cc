"""What exists: a plain summary of the catalogue for `robotconf catalog`."""

from __future__ import annotations

from typing import Any

from configurator.repository import Repository
from configurator.textsafe import printable_lines


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


def format_catalogue(summary: dict[str, Any]) -> str:
    out: list[str] = []
    out.append("Platforms")
    for name, p in summary["platforms"].items():
        out.append(f"  {name}" + (f"  - {p['description']}" if p["description"] else ""))
        for t, info in p["robot_templates"].items():
            out.append(f"    template {t}: {', '.join(info['mappings'])}")
        for s, mappings in p["mapping_schemes"].items():
            out.append(f"    scheme   {s}: binds {', '.join(mappings)}")
    out.append("Tasks")
    for name, impls in summary["tasks"].items():
        alternatives = " | ".join("[" + ", ".join(i) + "]" for i in impls)
        out.append(f"  {name}: {alternatives}")
    out.append("Actions")
    for name, a in summary["actions"].items():
        req = f"  requires {', '.join(a['requires'])}" if a["requires"] else ""
        out.append(f"  {name} ({', '.join(a['platforms'])}){req}")
        for logic, info in a["logics"].items():
            needs = ", ".join(info["mappings"]) or "no mappings"
            out.append(f"    logic {logic}: needs {needs}")
    out.append("Environments")
    for name, e in summary["environments"].items():
        out.append(
            f"  {name} ({e['type']}): locations {', '.join(e['locations']) or '-'}; "
            f"knowledge sets {', '.join(e['knowledge_sets']) or '-'}"
        )
    return printable_lines(out)
