"""One robot's page, pure: its row's facts, its launch request as a capability tree, its
interfaces, its recent status history, and the place of its brain's log tail."""

from __future__ import annotations

from urllib.parse import quote

from robotconf.contract.interfaces import Interface, RobotInterfaces
from robotconf.contract.launch import LaunchRequest
from robotconf.contract.wire import ReconcilerStatus
from robotconf.readmodel.verdicts import RobotRow
from robotconf.workstation.ui.auth import Identity
from robotconf.workstation.ui.goals_html import goals_box, revision_link
from robotconf.workstation.ui.model import HistoryEntry, Snapshot
from robotconf.workstation.ui.pages import MAX_LISTED, banner_box, page
from robotconf.workstation.ui.text import age, definitions, digest, esc, when


def robot_page(
    snap: Snapshot,
    robot_id: str,
    who: Identity,
    launch: LaunchRequest | None,
    interfaces: RobotInterfaces | None,
    outcome: str = "",
) -> str:
    """`outcome`: the latest restart the UI asked of it, as forms.outcome_html renders it
    (escaped there), for operators."""
    rid = esc(robot_id)
    path = f"/robots/{quote(robot_id, safe='')}"
    action = (
        f'<p><a data-action="restart" href="{path}/restart">Restart {rid}</a></p>'
        if who.operator
        else ""
    )
    log = (
        f'<pre data-log-tail data-log-src="{path}/logs" aria-live="polite"></pre>'
        if who.operator
        else "<pre data-log-tail>Operators only: log in to follow its brain's log.</pre>"
    )
    body = (
        f'<div data-robot-page="{rid}"><h1>Robot {rid}</h1>{outcome}{action}'
        + banner_box(snap)
        + robot_box(snap, robot_id)
        + goals_box(snap, robot_id)
        + launch_section(launch, snap.fleet.reconciler if snap.fleet else None)
        + interfaces_section(interfaces)
        + f"<section><h2>Brain log</h2>{log}</section></div>"
    )
    events = f"/events?robot={quote(robot_id, safe='')}"
    attrs = f' data-page="robot" data-version="{snap.version}" data-events="{esc(events)}"'
    return page(f"Robot {robot_id}", body, who, attrs)


def robot_box(snap: Snapshot, robot_id: str) -> str:
    """What changes live: its verdict and facts, drift, warnings, and its status history."""
    row = snap.row(robot_id)
    if row is None:
        return (
            '<section data-box="robot"><p>Not in the fleet and not known to the broker '
            "(yet).</p></section>"
        )
    return (
        f'<section data-box="robot" data-verdict="{row.verdict.value}">'
        f'<h2>Status: <span class="badge">{row.verdict.value}</span></h2>'
        f'<p class="why">{esc(row.reason)}</p>{definitions(facts(row))}'
        f"{drift_list(row)}{warnings(row)}"
        f"{history(snap.history.get(robot_id, ()))}</section>"
    )


def facts(row: RobotRow) -> list[tuple[str, str]]:
    labels = ", ".join(f"{k}={v}" for k, v in sorted(row.labels.items())) or "-"
    found = [
        ("State", esc(row.state, 40)),
        ("Online", "yes" if row.online else "no"),
        ("Labels", esc(labels)),
        ("Wave", esc(row.wave or "-")),
        ("Scenario", esc(row.scenario or "-")),
        ("Desired", digest(row.desired)),
        ("Published", digest(row.published)),
        ("Reported", digest(row.reported)),
        ("Restarts", str(row.restarts)),
        ("Reloads", str(row.reloads)),
        ("Drift", esc(row.drift.summary())),
    ]
    line = row.restart_line()
    if line is not None:
        found.append(("Last restart", esc(line)))
    return found


def drift_list(row: RobotRow) -> str:
    items = [f"<li>{esc(item.text())}</li>" for item in row.drift.items[:MAX_LISTED]]
    if row.drift.note:
        items.append(f"<li>{esc(row.drift.note)}</li>")
    return f"<h3>Drift</h3><ul data-drift>{''.join(items)}</ul>" if items else ""


def warnings(row: RobotRow) -> str:
    items = [f"<li>{esc(w)}</li>" for w in row.warnings[:20]]
    return f"<h3>Warnings</h3><ul>{''.join(items)}</ul>" if items else ""


def history(entries: tuple[HistoryEntry, ...]) -> str:
    if not entries:
        return "<h3>Recent status</h3><p>No change seen since this page's server started.</p>"
    rows = "".join(
        f'<tr><td>{age(e.at)}</td><td class="verdict">{e.verdict}</td>'
        f'<td class="why">{esc(e.reason, 200)}</td><td>{esc(e.state, 40)}</td>'
        f"<td>{digest(e.reported)}</td><td>{e.restarts}</td><td>{e.reloads}</td></tr>"
        for e in reversed(entries)
    )
    return (
        '<h3>Recent status</h3><div class="scroll"><table data-history><thead><tr>'
        '<th scope="col">When</th><th scope="col">Verdict</th><th scope="col">Why</th>'
        '<th scope="col">State</th><th scope="col">Reported</th><th scope="col">Restarts</th>'
        f'<th scope="col">Reloads</th></tr></thead><tbody>{rows}</tbody></table></div>'
    )


def launch_section(launch: LaunchRequest | None, status: ReconcilerStatus | None) -> str:
    """Its published launch request as a tree: capability > tasks, actions > logics, mappings
    as bound, goals."""
    if launch is None:
        return (
            "<section data-launch><h2>Launch request</h2><p>None published for it, or none "
            "that can be read.</p></section>"
        )
    scenario = launch.scenario
    cap = scenario.capability
    facts = [
        ("Name", esc(launch.robot_name)),
        ("Revision", revision_link(launch.revision, status)),
        ("Digest", digest(launch.digest)),
        ("Scenario", esc(scenario.name)),
        (
            "Environment",
            esc(f"{scenario.environment_name or '-'} ({scenario.environment_type or '-'})"),
        ),
        ("Namespace", esc(launch.namespace or "-")),
        ("ROS domain", esc(launch.ros_domain_id if launch.ros_domain_id is not None else "-")),
    ]
    tasks = "".join(f"<li>{esc(t)}</li>" for t in cap.tasks[:MAX_LISTED])
    actions = "".join(
        f"<li>{esc(a)}<ul>{logic_items(cap.logics.get(a))}</ul></li>"
        for a in cap.actions[:MAX_LISTED]
    )
    mappings = "".join(
        f"<li>{esc(name)}: {esc(b.kind)} <code>{esc(b.name)}</code> <code>{esc(b.type)}</code></li>"
        for name, b in list(cap.mappings.items())[:MAX_LISTED]
    )
    goals = "".join(f"<li>{esc(g.task)}</li>" for g in scenario.goals[:MAX_LISTED])
    tree = (
        f'<ul class="tree" data-capability="{esc(cap.name)}"><li>Capability {esc(cap.name)} '
        f"({esc(cap.platform)}, template {esc(cap.robot_template or '-')}, mapping scheme "
        f"{esc(cap.mapping_scheme)})<ul>"
        f"<li>Tasks<ul>{tasks}</ul></li><li>Actions and their logics<ul>{actions}</ul></li>"
        f"<li>Mappings<ul>{mappings}</ul></li></ul></li></ul>"
    )
    goal_list = f"<h3>Goals</h3><ul>{goals}</ul>" if goals else ""
    return (
        f"<section data-launch><h2>Launch request</h2>{definitions(facts)}{tree}{goal_list}"
        "</section>"
    )


def logic_items(logics: str | list[str] | None) -> str:
    if logics is None:
        return ""
    names = [logics] if isinstance(logics, str) else logics
    return "".join(f"<li>logic {esc(n)}</li>" for n in names[:MAX_LISTED])


def interfaces_section(report: RobotInterfaces | None) -> str:
    if report is None:
        return "<section data-interfaces><h2>Interfaces</h2><p>Not reported.</p></section>"
    groups = "".join(
        interface_group(name, items)
        for name, items in (
            ("Topics", report.topics),
            ("Services", report.services),
            ("Actions", report.actions),
        )
    )
    notes = [f"source {esc(report.source or '-')}, read {esc(when(report.at))}"]
    if report.truncated:
        notes.append(f"{report.truncated} left out by the bounds")
    if report.error:
        notes.append(f"error: {esc(report.error)}")
    return (
        f"<section data-interfaces><h2>Interfaces</h2><p>{'; '.join(notes)}</p>{groups}</section>"
    )


def interface_group(name: str, items: list[Interface]) -> str:
    shown = "".join(
        f"<li><code>{esc(i.name)}</code> <code>{esc(i.type)}</code></li>"
        for i in items[:MAX_LISTED]
    )
    more = f"<li>… {len(items) - MAX_LISTED} more</li>" if len(items) > MAX_LISTED else ""
    return f"<details><summary>{name} ({len(items)})</summary><ul>{shown}{more}</ul></details>"
