"""A revision's page, pure: what it achieved beside the revision before it, per scenario and task
and per robot, from the outcome ledger; and what the robots running it report now, from their
retained goals summaries. Every string from a robot or the ledger goes through `esc`."""

from __future__ import annotations

from urllib.parse import quote

from robotconf.readmodel.outcomes import History, RevisionReport, Tally
from robotconf.readmodel.verdicts import short_rev
from robotconf.workstation.ui.auth import Identity
from robotconf.workstation.ui.goals_html import duration, rate_row, revision_link
from robotconf.workstation.ui.model import Snapshot
from robotconf.workstation.ui.pages import banner_box, page
from robotconf.workstation.ui.revisions import live_rates, rate_change
from robotconf.workstation.ui.text import age, esc

MAX_ROWS = 300  # task or robot rows listed; the rest counted
NO_TALLY = Tally()


def revision_page(
    snap: Snapshot,
    revision: str,
    who: Identity,
    kept: History | None,
    why: str | None = None,
    commit: str = "",
) -> str:
    """`kept`: the ledger's answer (None: it holds nothing of this revision, or `why` it could
    not be asked); `commit`: the commit's section (`commit_facts.commit_section`)."""
    short = esc(short_rev(revision))
    body = (
        f'<div data-revision-page="{esc(revision, 64)}"><h1>Revision <code>{short}</code></h1>'
        + banner_box(snap)
        + commit
        + ledger_section(revision, kept, why)
        + live_section(snap, revision)
        + "</div>"
    )
    return page(f"Revision {short_rev(revision)}", body, who)


def live_section(snap: Snapshot, revision: str) -> str:
    fleet = snap.fleet
    rates = live_rates(fleet.rows, revision) if fleet is not None else []
    if not rates:
        inner = "<p>No robot reports goals counted under this revision now.</p>"
    else:
        inner = (
            '<div class="scroll"><table data-rates><thead><tr><th scope="col">Scenario</th>'
            '<th scope="col">Revision</th><th scope="col">Robots</th>'
            '<th scope="col">Success rate</th><th scope="col">Succeeded</th>'
            '<th scope="col">Failed</th><th scope="col">Canceled</th><th scope="col">Stale</th>'
            '<th scope="col">Underway</th></tr></thead>'
            f"<tbody>{''.join(rate_row(r) for r in rates)}</tbody></table></div>"
        )
    return (
        "<section data-live-goals><h2>Now: its robots' goals since their current request</h2>"
        f"{inner}</section>"
    )


def ledger_section(revision: str, kept: History | None, why: str | None) -> str:
    if why is not None:
        return (
            '<section data-ledger="unavailable"><h2>Kept in the outcome ledger</h2>'
            f"<p>{esc(why)}</p></section>"
        )
    if kept is None:
        return (
            '<section data-ledger="empty"><h2>Kept in the outcome ledger</h2><p>The ledger '
            f"holds no goal outcome of <code>{esc(short_rev(revision))}</code>.</p></section>"
        )
    now, before = kept.report, kept.before
    against = (
        f"beside the revision before it, {revision_link(before.revision)}"
        if before is not None
        else "(the ledger holds no revision before it)"
    )
    return (
        '<section data-ledger="kept"><h2>Kept in the outcome ledger</h2>'
        f"<p>Outcomes recorded from {age(now.first_seen)} to {age(now.last_seen)}, {against}.</p>"
        + totals(now, before)
        + task_table(now, before)
        + robot_table(now)
        + "</section>"
    )


def _rate(tally: Tally | None) -> str:
    rate = tally.success_rate if tally is not None else None
    return "-" if rate is None else f"{100 * rate:.0f}%"


def _tally_cells(tally: Tally) -> str:
    return (
        f"<td><strong>{_rate(tally)}</strong></td><td>{tally.succeeded}</td><td>{tally.failed}"
        f"</td><td>{tally.canceled}</td><td>{tally.stale}</td>"
    )


def totals(now: RevisionReport, before: RevisionReport | None) -> str:
    mine = now.tally
    change = rate_change(mine.success_rate, before.tally.success_rate if before else None)
    rate = _rate(mine)
    codes = ", ".join(f"{esc(code, 64)} ×{n}" for code, n in list(now.codes.items())[:5])
    said = f"<p data-failure-codes>Failure codes, the most frequent first: {codes}.</p>"
    return (
        f'<p data-total-rate="{rate}" data-rate-change="{change}">All its goals: '
        f"<strong>{rate}</strong> succeeded of succeeded and failed ({mine.succeeded} "
        f"succeeded, {mine.failed} failed, {mine.canceled} canceled, {mine.stale} stale); "
        f"{change} against the revision before.</p>" + (said if codes else "")
    )


def _tasks(report: RevisionReport | None) -> dict[tuple[str, str], Tally]:
    if report is None:
        return {}
    return {
        (scenario, task): tally
        for scenario, found in report.scenarios.items()
        for task, tally in found.tasks.items()
    }


def task_table(now: RevisionReport, before: RevisionReport | None) -> str:
    mine_all, theirs_all = _tasks(now), _tasks(before)
    keys = sorted(set(mine_all) | set(theirs_all))
    rows = []
    for scenario, task in keys[:MAX_ROWS]:
        mine = mine_all.get((scenario, task), NO_TALLY)
        theirs = theirs_all.get((scenario, task))
        change = rate_change(mine.success_rate, theirs.success_rate if theirs else None)
        rows.append(
            f'<tr data-scenario="{esc(scenario or "-", 128)}" data-task="{esc(task, 128)}" '
            f'data-rate-change="{change}"><th scope="row">{esc(scenario or "-", 128)}</th>'
            f"<td>{esc(task, 128)}</td>{_tally_cells(mine)}<td>{duration(mine.mean_duration)}"
            f"</td><td>{'-' if before is None else _rate(theirs)}</td><td>{change}</td></tr>"
        )
    more = f"<p>… {len(keys) - MAX_ROWS} more tasks.</p>" if len(keys) > MAX_ROWS else ""
    return (
        '<h3>Per scenario and task</h3><div class="scroll"><table data-revision-tasks><thead><tr>'
        '<th scope="col">Scenario</th><th scope="col">Task</th><th scope="col">Success rate</th>'
        '<th scope="col">Succeeded</th><th scope="col">Failed</th><th scope="col">Canceled</th>'
        '<th scope="col">Stale</th><th scope="col">Mean duration</th>'
        '<th scope="col">Rate before</th>'
        f'<th scope="col">Change</th></tr></thead><tbody>{"".join(rows)}</tbody></table></div>'
        f"{more}"
    )


def robot_table(now: RevisionReport) -> str:
    ordered = now.worst_robots()  # the lowest success rate first, then the most failures
    if not ordered:
        return ""
    rows = "".join(
        f'<tr data-robot-result="{esc(robot_id, 64)}"><th scope="row">'
        f'<a href="/robots/{quote(robot_id, safe="")}">{esc(robot_id, 64)}</a></th>'
        f"{_tally_cells(tally)}</tr>"
        for robot_id, tally in ordered[:MAX_ROWS]
    )
    more = f"<p>… {len(ordered) - MAX_ROWS} more robots.</p>" if len(ordered) > MAX_ROWS else ""
    return (
        '<h3>Per robot, the worst first</h3><div class="scroll"><table data-revision-robots>'
        '<thead><tr><th scope="col">Robot</th><th scope="col">Success rate</th>'
        '<th scope="col">Succeeded</th><th scope="col">Failed</th><th scope="col">Canceled</th>'
        f'<th scope="col">Stale</th></tr></thead><tbody>{rows}</tbody></table></div>{more}'
    )
