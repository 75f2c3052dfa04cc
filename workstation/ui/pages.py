"""The fleet page and its live boxes as HTML, pure; `esc` is the one way text reaches a page, and no
page has an inline script or style (the CSP forbids them). DOM contract: docs/architecture.md."""

from __future__ import annotations

from collections.abc import Iterable
from urllib.parse import quote, urlencode

from robotconf.contract.wire import (
    ABORT_COMMAND,
    RESUME_COMMAND,
    ReconcilerStatus,
    RolloutStatus,
    WaveVerification,
)
from robotconf.readmodel.verdicts import (
    Health,
    RobotRow,
    Verdict,
    paused_for_evidence,
    reconciler_health,
)
from robotconf.workstation.ui.auth import Identity
from robotconf.workstation.ui.goals_html import goals_cell, percent, rates_box, revision_link
from robotconf.workstation.ui.model import FleetQuery, Snapshot, Visible, rank, visible
from robotconf.workstation.ui.text import age, definitions, digest, esc, fold, when

MAX_LISTED = 300  # items of one list on a robot page (interfaces, mappings); the rest counted
DIAGNOSTICS = 50  # diagnostics listed; the rest counted
# What says what is wrong comes first (robot, verdict, why): at a laptop's width, or a phone's,
# the rest of a wide row scrolls in the table's own box, never these.
COLUMNS = (
    "Robot",
    "Verdict",
    "Why",
    "State",
    "Online",
    "Labels",
    "Wave",
    "Scenario",
    "Desired",
    "Reported",
    "Restarts",
    "Reloads",
    "Goals",
    "Drift",
)


def page(title: str, body: str, who: Identity, attrs: str = "") -> str:
    """A whole document: the stylesheet and the script by URL, nothing inline."""
    account = (
        '<form method="post" action="/logout" class="inline">'
        f'<input type="hidden" name="csrf" value="{esc(who.csrf)}">'
        '<button type="submit">Log out</button></form>'
        if who.operator
        else '<a href="/login">Log in</a>'
    )
    return (
        '<!doctype html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{esc(title)} · robotconf</title>"
        '<link rel="stylesheet" href="/static/ui.css">'
        '<script src="/static/ui.js" defer></script></head>'
        f"<body{attrs}>"
        '<a class="skip" href="#main">Skip to content</a>'
        '<header><nav aria-label="site"><a href="/">Fleet</a> '
        '<a href="/timeline">Timeline</a> '
        f'<span class="who">{_who(who)}</span> '
        f"{account}</nav></header>"
        f'<main id="main" tabindex="-1">{body}</main></body></html>\n'
    )


def _who(who: Identity) -> str:
    if not who.operator:
        return "viewer (read-only)"
    return f"operator {esc(who.name)}" if who.name else "operator"


def error_page(code: int, message: str, who: Identity) -> str:
    body = f'<h1>{code}</h1><p data-error>{esc(message)}</p><p><a href="/">The fleet</a></p>'
    return page(f"{code}", body, who)


# ------------------------------------------------------------------ the fleet page


def fleet_page(snap: Snapshot, query: FleetQuery, who: Identity) -> str:
    shown = visible(snap.fleet, query) if snap.fleet is not None else None
    events = "/events" + (f"?{urlencode(query.as_query())}" if query.as_query() else "")
    body = (
        "<h1>Fleet</h1>"
        + banner_box(snap)
        + reconciler_box(snap)
        + rollout_box(snap)
        + filter_form(query)
        + summary_box(shown, query)
        + rates_box(snap, query)
        + '<div class="scroll" id="robots"><table data-fleet><caption>Robots, worst first'
        + "</caption><thead><tr>"
        + "".join(f'<th scope="col">{name}</th>' for name in COLUMNS)
        + "</tr></thead><tbody data-rows>"
        + "".join(row_html(row) for row in (shown.rows if shown else []))
        + "</tbody></table></div>"
    )
    attrs = f' data-page="fleet" data-version="{snap.version}" data-events="{esc(events)}"'
    return page("Fleet", body, who, attrs)


def filter_form(query: FleetQuery) -> str:
    selector = ",".join(f"{k}={v}" for k, v in query.selector)
    options = ['<option value="">any</option>'] + [
        f'<option value="{v.value}"{" selected" if query.verdict is v else ""}>{v.value}</option>'
        for v in Verdict
    ]
    return (
        '<form data-filter method="get" action="/" role="search">'
        '<label>Labels <input name="selector" placeholder="ring=canary,site=sim" '
        f'value="{esc(selector)}" autocomplete="off"></label> '
        f'<label>Verdict <select name="verdict">{"".join(options)}</select></label> '
        f'<label>Robot id <input name="q" type="search" value="{esc(query.search)}" '
        'autocomplete="off"></label> <button type="submit">Filter</button> '
        '<a href="/">Clear</a></form>'
    )


def summary_box(shown: Visible | None, query: FleetQuery) -> str:
    if shown is None:
        text = "<p>Reading the broker's retained topics…</p>"
    else:
        counts = ", ".join(
            f'<a href="/?{esc(urlencode([*without_verdict(query), ("verdict", v)]))}">{n} {v}</a>'
            for v, n in shown.counts.items()
        )
        text = f"<p>{shown.total} robots in the fleet; these: {counts or 'none'}.</p>"
        if shown.selected > len(shown.rows):
            more = shown.selected - len(shown.rows)
            text += (
                f"<p data-more>Showing the worst {len(shown.rows)} of {shown.selected}: "
                f"{more} more, narrow the filter.</p>"
            )
    return f'<section data-box="summary" aria-live="polite">{text}</section>'


def without_verdict(query: FleetQuery) -> list[tuple[str, str]]:
    return [(k, v) for k, v in query.as_query() if k != "verdict"]


def row_html(row: RobotRow) -> str:
    """One robot's row: `data-robot`, `data-verdict` and `data-rank` (its place worst first,
    for the script to insert it where it belongs); the verdict as text too."""
    rid = esc(row.robot_id)
    labels = ", ".join(f"{k}={v}" for k, v in sorted(row.labels.items())) or "-"
    cells = [
        f'<th scope="row"><a href="/robots/{quote(row.robot_id, safe="")}">{rid}</a></th>',
        f'<td class="verdict"><span class="badge">{row.verdict.value}</span></td>',
        f'<td class="why">{"" if row.verdict is Verdict.IN_SYNC else esc(row.reason, 200)}</td>',
        f"<td>{esc(row.state, 40)}</td>",
        f"<td>{'yes' if row.online else 'no'}</td>",
        f"<td>{esc(labels)}</td>",
        f"<td>{esc(row.wave or '-')}</td>",
        f"<td>{esc(row.scenario or '-')}</td>",
        f"<td>{digest(row.desired)}</td>",
        f"<td>{digest(row.reported)}</td>",
        f"<td>{row.restarts}</td>",
        f"<td>{row.reloads}</td>",
        goals_cell(row),
        f'<td class="drift">{esc(row.drift.summary())}</td>',
    ]
    return (
        f'<tr data-robot="{rid}" data-verdict="{row.verdict.value}" '
        f'data-rank="{esc(rank(row))}">{"".join(cells)}</tr>'
    )


def banner_box(snap: Snapshot) -> str:
    """What makes the page's view doubtful: the broker lost, the reconciler silent."""
    lines = []
    if not snap.connected:
        why = f": {esc(snap.broker_error)}" if snap.broker_error else ""
        lines.append(
            f'<p data-banner="broker">Broker disconnected ({esc(snap.broker)}){why}. '
            "Showing the last state read; it reconnects by itself.</p>"
        )
    fleet = snap.fleet
    if fleet is not None:
        health = reconciler_health(fleet.reconciler, snap.at)
        said = {
            Health.STALE: "Reconciler heartbeat stale: is the reconciler still running?",
            Health.OFFLINE: "Reconciler offline: it stopped, or lost the broker.",
            Health.MISSING: "No reconciler status on the broker: no reconciler runs here.",
        }.get(health)
        if said is not None:
            lines.append(f'<p data-banner="reconciler">{said}</p>')
        if fleet.lost:
            lines.append(f'<p data-banner="lost">{esc(fleet.lost)}</p>')
    hidden = "" if lines else " hidden"
    return f'<div data-box="banner" role="status" aria-live="polite"{hidden}>{"".join(lines)}</div>'


def reconciler_box(snap: Snapshot) -> str:
    """The reconciler's state, revisions and heartbeat, and a refused commit's diagnostics: one
    line while it is at work with nothing to say, the whole of it open when it is not."""
    fleet = snap.fleet
    status = fleet.reconciler if fleet is not None else None
    if status is None:
        state = "Missing" if fleet is not None else "Unknown"
        inner = "<p>No reconciler status on the broker.</p>" if fleet is not None else ""
        return (
            f'<section data-box="reconciler" data-reconciler-state="{state}">'
            f"<h2>Reconciler: {state}</h2>{inner}</section>"
        )
    health = reconciler_health(status, snap.at)
    facts = [
        ("Reason", esc(status.reason or "-")),
        ("Branch", esc(status.branch or "-")),
        ("Applied", revision_link(status.last_applied_revision, status)),
        ("Attempted", revision_link(status.last_attempted_revision, status)),
        ("Failed", revision_link(status.failed_revision, status)),
        ("Robots", str(status.robots)),
        ("Heartbeat", age(status.heartbeat)),
        ("Health", health.value),
    ]
    message = f"<p>{esc(status.message)}</p>" if status.message else ""
    state = esc(status.state, 20)
    line = (
        f"<h2>Reconciler: {state}</h2> "
        f'<span class="line">applied {revision_link(status.last_applied_revision, status)}'
        f" · heartbeat {age(status.heartbeat, short=True)}</span>"
    )
    details = (
        f"{definitions(facts)}{message}{diagnostics(status.diagnostics, status.more_diagnostics)}"
    )
    return (
        f'<section data-box="reconciler" data-reconciler-state="{state}" '
        f'data-health="{health.value}">{fold(line, details, reconciler_trouble(status, health))}'
        "</section>"
    )


def reconciler_trouble(status: ReconcilerStatus, health: Health) -> bool:
    """Something to read in the reconciler's box: not at work (Stalled, Offline), silent, a
    refused commit, robots held back, or reads of the broker that miss messages."""
    return (
        status.state not in ("Ready", "Progressing")
        or health is not Health.OK
        or bool(status.diagnostics or status.held or status.broker_dropped)
    )


def diagnostics(found: Iterable[object], more: int) -> str:
    """One `<li>` per diagnostic, `file:line:col CODE message`."""
    items = []
    listed = list(found)
    for d in listed[:DIAGNOSTICS]:
        path = getattr(d, "path", None)
        where = (
            ":".join(
                [
                    str(path),
                    *(
                        str(n)
                        for n in (getattr(d, "line", None), getattr(d, "column", None))
                        if n is not None
                    ),
                ]
            )
            if path
            else ""
        )
        code = getattr(d, "code", "")
        items.append(
            f'<li><code class="where">{esc(where)}</code> <strong>{esc(code, 60)}</strong> '
            f"{esc(getattr(d, 'message', ''))}</li>"
            if where
            else f"<li><strong>{esc(code, 60)}</strong> {esc(getattr(d, 'message', ''))}</li>"
        )
    if not items:
        return ""
    left = len(listed) - min(len(listed), DIAGNOSTICS) + more
    tail = f"<p>… {left} more (robotconf validate)</p>" if left > 0 else ""
    return (
        '<div class="diagnostics"><h3>Why the commit was refused</h3>'
        f"<ul data-diagnostics>{''.join(items)}</ul>{tail}</div>"
    )


def stages_html(rollout: RolloutStatus, status: ReconcilerStatus | None = None) -> str:
    """The promotion ladder: each stage's standing (`data-stage`, its state as the value) and
    the revision verified for its robots (with its commit's subject, from `status`)."""
    items = "".join(
        f'<li data-stage="{esc(stage.state, 20)}">{esc(stage.name, 64)}: {esc(stage.state, 20)} '
        f"(verified here: {revision_link(stage.verified_revision, status)})</li>"
        for stage in rollout.stages
    )
    return f'<ol class="stages">{items}</ol>'


def rollout_box(snap: Snapshot) -> str:
    """The rollout wave by wave: its robots by how they fare, and what a rollback restored; one
    line while it goes well or is done, the whole of it open when it does not."""
    fleet = snap.fleet
    reconciler = fleet.reconciler if fleet else None
    rollout = reconciler.rollout if reconciler else None
    if rollout is None:
        return '<section data-box="rollout" hidden></section>'
    deferred = [
        r.robot_id
        for r in (fleet.rows if fleet else [])
        if r.wave == rollout.wave_name and r.state == "deferred"
    ]
    counts = rollout.counts
    groups = [
        ("Healthy", rollout.healthy, counts.get("healthy", len(rollout.healthy))),
        ("Failed", rollout.failed, counts.get("failed", len(rollout.failed))),
        ("Pending", rollout.pending, counts.get("pending", len(rollout.pending))),
        ("Deferred", deferred, len(deferred)),
        ("Offline", rollout.offline, counts.get("offline", len(rollout.offline))),
    ]
    facts = [
        ("Revision", revision_link(rollout.revision, reconciler)),
        ("Wave", f"{rollout.wave + 1} of {rollout.waves} ({esc(rollout.wave_name, 80)})"),
        ("Wave since", age(rollout.wave_started_at)),
        ("Stable", revision_link(rollout.stable_revision, reconciler)),
    ]
    if rollout.stages:
        facts.append(("Stages", stages_html(rollout, reconciler)))
    lists = "".join(
        f'<div class="group" data-group="{name.lower()}"><h3>{name}: {n}</h3>'
        f"{id_list(ids, n)}</div>"
        for name, ids, n in groups
    )
    message = f"<p>{esc(rollout.message)}</p>" if rollout.message else ""
    evidence = (
        evidence_html(rollout.verification, paused_for_evidence(rollout))
        if rollout.verification is not None
        else ""
    )
    details = (
        f"{definitions(facts)}{rolled_back(rollout, reconciler)}{message}{evidence}"
        f'<div class="groups">{lists}</div>'
    )
    line = rollout_line(rollout, reconciler, groups)
    return (
        f'<section data-box="rollout" data-rollout-state="{esc(rollout.state, 20)}">'
        f"{fold(line, details, rollout_trouble(rollout))}</section>"
    )


def rollout_line(
    rollout: RolloutStatus,
    status: ReconcilerStatus | None,
    groups: list[tuple[str, list[str], int]],
) -> str:
    """The rollout in one line: its state, revision, wave and how the wave's robots fare."""
    fare = ", ".join(f"{n} {name.lower()}" for name, _, n in groups if n or name == "Failed")
    return (
        f"<h2>Rollout: {esc(rollout.state, 20)}</h2> "
        f'<span class="line">{revision_link(rollout.revision, status)} · wave '
        f"{rollout.wave + 1} of {rollout.waves} ({esc(rollout.wave_name, 80)}) · {fare}</span>"
    )


def rollout_trouble(rollout: RolloutStatus) -> bool:
    """Something to read in the rollout's box: it stopped, went back, or waits for someone
    (Paused, Halted, RolledBack), a robot of its wave failed, or its evidence failed."""
    failed = rollout.counts.get("failed", len(rollout.failed))
    verdict = rollout.verification.verdict if rollout.verification is not None else None
    return (
        rollout.state in ("Paused", "Halted", "RolledBack")
        or failed > 0
        or verdict in ("Failed", "Inconclusive")
        or paused_for_evidence(rollout)
    )


def rolled_back(rollout: RolloutStatus, status: ReconcilerStatus | None) -> str:
    """What a rollback restored."""
    if rollout.state != "RolledBack":
        return ""
    if rollout.stages:
        return (
            "<p data-rolled-back>Rolled back: each stage's robots run the revision verified "
            "for them (Stages).</p>"
        )
    return (
        "<p data-rolled-back>Rolled back: the moved robots run "
        f"{revision_link(rollout.stable_revision, status)} again, the last revision "
        "that fully rolled out.</p>"
    )


def evidence_html(found: WaveVerification, paused: bool) -> str:
    """The wave's evidence against `rollout.verify`: the goals gathered against those needed,
    the rate against its threshold and the stable robots', the verdict, and, `paused` on it,
    the commands an operator decides it with."""
    verdict = found.verdict or "Gathering"
    facts = [
        ("Verdict", f'<span class="verdict">{esc(verdict, 20)}</span>'),
        ("Goals", _goals_text(found)),
    ]
    if found.rate is not None or found.success_rate is not None:
        facts.append(("Success rate", _rate_text(found)))
    if found.max_drop is not None:  # compare: stable
        facts.append(("Stable revision", _stable_text(found)))
    if found.critical:
        facts.append(("Critical codes", esc(", ".join(found.critical))))
    if found.verdict is None and found.deadline is not None:
        facts.append(("Judged by", esc(when(found.deadline))))
    if found.decided_by is not None:
        how = "Aborted by" if found.verdict == "Failed" else "Resumed by"
        facts.append((how, esc(found.decided_by, 80)))
    # A dry run's verdict is shown, never acted on: said before anyone reads it as a gate.
    shadow = (
        "<p>Dry run: judged and shown, not gating; the wave goes on by its "
        "robots' health alone.</p>"
        if found.dry_run
        else ""
    )
    commands = (
        f"<p data-verify-commands>Inconclusive: an operator decides. <code>{RESUME_COMMAND}"
        f"</code> passes the wave; <code>{ABORT_COMMAND}</code> fails it (rolled back, or halted "
        "with on_failure: halt). Here, operators: "
        '<a data-action="rollout-resume" href="/rollout/resume">resume</a> or '
        '<a data-action="rollout-abort" href="/rollout/abort">abort</a>.</p>'
        if paused
        else ""
    )
    dry = " data-dry-run" if found.dry_run else ""
    return (
        f'<div class="evidence" data-evidence="{esc(verdict, 20)}"{dry}>'
        f"<h3>Evidence: {esc(verdict, 20)}</h3>{shadow}{definitions(facts)}{commands}</div>"
    )


def _goals_text(found: WaveVerification) -> str:
    """'14 of at least 20 (13 succeeded, 1 failed, 0 canceled) from 3 robots'."""
    return (
        f"{found.goals} of at least {found.min_goals} ({found.succeeded} succeeded, "
        f"{found.failed} failed, {found.canceled} canceled) from {found.robots} "
        f"robot{'' if found.robots == 1 else 's'}"
    )


def _rate_text(found: WaveVerification) -> str:
    if found.success_rate is None:
        return percent(found.rate)
    return f"{percent(found.rate)} (at least {percent(found.success_rate)})"


def _stable_text(found: WaveVerification) -> str:
    drop = f"at most {percent(found.max_drop)} below it"
    if found.stable_rate is None:
        return f"no rate to compare with yet ({drop})"
    return f"{percent(found.stable_rate)} over {found.stable_goals} goals ({drop})"


def id_list(ids: list[str], count: int) -> str:
    if not ids:
        return ""
    items = "".join(
        f'<li><a href="/robots/{quote(i, safe="")}">{esc(i, 80)}</a></li>' for i in ids[:50]
    )
    more = f"<li>… {count - min(len(ids), 50)} more</li>" if count > min(len(ids), 50) else ""
    return f"<ul>{items}{more}</ul>"
